"""`bodyschema <command> --config FILE [flags]`: a command's config from a file, flags on top.

FILE is TOML (`.toml`), YAML (`.yaml`/`.yml`, read with PyYAML, which MLflow already installs) or JSON (`.json`),
holding the command's config fields by name (the names of its flags: `trials = 50`, `noise_floor = 1e-6`; hyphens
or underscores). A nested config is a table (`[perception]`, or `[model]` for `train KIND`'s hyper-parameters); a key
the CLI takes as a flat flag (`--dt`, `--noise-floor`) may also stay flat, when exactly one nested config has it.
A benchmark's `run.json` is such a file (its `fields`; its config must be the command's): `bodyschema evaluate
levels --config results/levels/latest/run.json` runs that config again. Anything not in the file keeps its default;
a flag given beside `--config` overrides the file (tyro parses the flags with the file's config as defaults).
TOML has no null: leave such a key out (its default) or use YAML's `null`.
"""

from __future__ import annotations

import dataclasses
import json
import typing
from pathlib import Path
from typing import Any

from bodyschema.errors import must_be

FLAG = "--config"
SUFFIXES = (".toml", ".yaml", ".yml", ".json")


def split_flag(argv: list[str]) -> tuple[list[str], Path | None]:
    """argv without `--config FILE` (or `--config=FILE`), and FILE (None: not given)."""
    for i, arg in enumerate(argv):
        if arg == FLAG:
            if i + 1 >= len(argv) or argv[i + 1].startswith("--"):
                raise ValueError(must_be(FLAG, "followed by a file (TOML, YAML or a run.json)", "nothing",
                                         "e.g. `bodyschema evaluate levels --config levels.toml`."))
            return argv[:i] + argv[i + 2:], Path(argv[i + 1])
        if arg.startswith(FLAG + "="):
            return argv[:i] + argv[i + 1:], Path(arg.split("=", 1)[1])
    return argv, None


def command_type(union, words: list[str]):
    """The config type `bodyschema <words>` parses into, found in the CLI's tree of subcommands (`cli.commands`)."""
    node = union
    for word in words:
        found = [t for t in _members(node) if _name(t) == word]
        if not found:
            break
        node = _inner(found[0])
    if typing.get_origin(node) is typing.Union or not _is_config(node):
        raise ValueError(must_be(FLAG, "given after a whole command (e.g. `bodyschema evaluate levels --config "
                                 "FILE`)", " ".join(["bodyschema", *words, FLAG]), "Name the command first."))
    return node


def _members(node) -> tuple:
    node = _inner(node)
    return typing.get_args(node) if typing.get_origin(node) is typing.Union else ()


def _name(annotated) -> str | None:
    return next((getattr(m, "name", None) for m in getattr(annotated, "__metadata__", ())
                 if type(m).__name__ == "_SubcommandConfig"), None)


def _inner(node):
    return typing.get_args(node)[0] if typing.get_origin(node) is typing.Annotated else node


def _is_config(tp) -> bool:
    return dataclasses.is_dataclass(typing.get_origin(tp) or tp)


def read_file(path: Path) -> dict:
    """The mapping a config file holds (TOML, YAML, JSON by suffix)."""
    if path.suffix.lower() not in SUFFIXES or not path.is_file():
        raise ValueError(must_be(f"{FLAG} file", f"an existing {', '.join(SUFFIXES)} file", str(path),
                                 "Write the command's fields there (a run.json of a benchmark run counts)."))
    text = path.read_text(encoding="utf-8")
    try:
        if path.suffix.lower() == ".toml":
            import tomllib
            data = tomllib.loads(text)
        elif path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            import yaml
            data = yaml.safe_load(text)
    except Exception as error:  # noqa: BLE001 — each parser's own error type; all mean "not a readable file"
        raise ValueError(must_be(f"{FLAG} file {str(path)!r}", f"valid {path.suffix.lstrip('.').upper()}",
                                 f"{type(error).__name__}: {error}")) from error
    if not isinstance(data, dict):
        raise ValueError(must_be(f"{FLAG} file {str(path)!r}", "a mapping of field names to values",
                                 type(data).__name__))
    return data


def load_config(path: Path, config_type, command: str):
    """The config of type `config_type` (for `command`, in messages) that `path` describes; a run.json's `fields`,
    once its config class is checked against the command's."""
    data = read_file(path)
    origin = typing.get_origin(config_type) or config_type
    if "fields" in data and "config" in data and isinstance(data["fields"], dict):      # a benchmark's run.json
        if data["config"] != origin.__name__:
            raise ValueError(must_be(f"{FLAG} run.json {str(path)!r}", f"a run of `{command}` ({origin.__name__})",
                                     data["config"], "Give it to the command that wrote it."))
        data = data["fields"]
    return build(config_type, data, str(path))


def build(config_type, data: dict, where: str, base=None):
    """`config_type` from a mapping of its field names (nested mappings: nested configs), over `base` (an instance:
    its values are the defaults) or the type's own defaults."""
    origin = typing.get_origin(config_type) or config_type
    hints = _hints(config_type)
    fields = {f.name: f for f in dataclasses.fields(origin) if f.init}
    nested = [n for n in fields if _is_config(_strip(hints[n]))]
    values: dict[str, Any] = {}
    for key, value in data.items():
        name = str(key).replace("-", "_")
        if name in fields:
            values[name] = _value(hints[name], value, f"{where}: {name}", _current(base, fields[name]))
            continue
        owners = [n for n in nested if name in {f.name for f in dataclasses.fields(_origin(hints[n]))}]
        if len(owners) != 1:
            raise ValueError(must_be(f"key {key!r} in {where}", f"a field of {origin.__name__}",
                                     key, f"Its fields: {', '.join(sorted(fields))}."))
        values.setdefault(owners[0], {})
        if not isinstance(values[owners[0]], dict):
            raise ValueError(must_be(f"key {key!r} in {where}", f"in the [{owners[0]}] table, or flat, not both", key))
        values[owners[0]][name] = value                          # a flat key of a nested config (its flat flag)
    for name in nested:
        if isinstance(values.get(name), dict):
            values[name] = build(_strip(hints[name]), values[name], f"{where}: {name}", _current(base, fields[name]))
        elif name not in values and base is None and _required(fields[name]):
            values[name] = build(_strip(hints[name]), {}, f"{where}: {name}")       # a required config: defaults
    if base is not None:
        return dataclasses.replace(base, **values)
    missing = [n for n, f in fields.items() if n not in values and _required(f)]
    if not missing:
        return config_type(**values)                             # its own checks (`__post_init__`) run on the file
    # Required fields left to the command line: tyro asks for them (tyro.MISSING), then builds and checks the config.
    import tyro
    partial = origin.__new__(origin)
    for name, field in fields.items():
        object.__setattr__(partial, name, values[name] if name in values else
                           tyro.MISSING if name in missing else _current(None, field))
    return partial


def _required(field: dataclasses.Field) -> bool:
    return field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING


def _current(base, field: dataclasses.Field):
    if base is not None:
        return getattr(base, field.name)
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    return None


def _hints(config_type) -> dict:
    """Field → type, a generic config's parameters bound (`TrainConfig[GPRConfig]`: model → GPRConfig)."""
    origin = typing.get_origin(config_type) or config_type
    hints = typing.get_type_hints(origin, include_extras=True)
    bound = dict(zip(getattr(origin, "__parameters__", ()), typing.get_args(config_type)))
    return {k: _bind(v, bound) for k, v in hints.items()}


def _bind(hint, bound: dict):
    if hint in bound:
        return bound[hint]
    if typing.get_origin(hint) is typing.Annotated and typing.get_args(hint)[0] in bound:
        return bound[typing.get_args(hint)[0]]
    return hint


def _strip(hint):
    """A hint without Annotated and Optional (`X | None` → X when X is the only other arm)."""
    hint = _inner(hint)
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    if _is_union(hint) and len(args) == 1:
        return _inner(args[0])
    return hint


def _origin(hint):
    hint = _strip(hint)
    return typing.get_origin(hint) or hint


def _is_union(hint) -> bool:
    import types
    return typing.get_origin(hint) in (typing.Union, types.UnionType)


def _value(hint, value, where: str, base=None):
    """`value` from a file as the field's type: tables → configs, lists → tuples, strings → paths, ints → floats."""
    hint = _inner(hint)
    if value is None:
        return None
    if _is_union(hint):
        arms = [a for a in typing.get_args(hint) if a is not type(None)]
        arm = next((a for a in arms if _is_config(_inner(a)) == isinstance(value, dict)), arms[0])
        return _value(arm, value, where, base)
    if _is_config(hint):
        if not isinstance(value, dict):
            raise ValueError(must_be(where, "a table of its fields", value))
        return build(hint, value, where, base if dataclasses.is_dataclass(base) else None)
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (tuple, list):
        items = value if isinstance(value, (list, tuple)) else [value]
        if origin is tuple and args and args[-1] is not Ellipsis:
            kinds = list(args)
        else:
            kinds = [args[0] if args else Any] * len(items)
        converted = [_value(k, v, where) for k, v in zip(kinds, items)]
        return tuple(converted) if origin is tuple else converted
    if hint is Path and isinstance(value, str):
        return Path(value)
    if hint is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value
