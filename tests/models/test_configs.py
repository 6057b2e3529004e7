"""The typed hyper-parameter configs (models/configs.py) cannot drift from the model constructors they feed.

For every trainable kind: the config's fields are exactly the constructor's keyword parameters (after body,
modality and shape) minus the ones it leaves out on purpose (`not_on_cli`), with equal defaults and a help
comment each; a Literal field lists exactly the words the model accepts. A constructor that gains a parameter,
loses one or changes a default fails here, naming it.
"""

import dataclasses
import inspect
import typing

import pytest

from bodyschema.models import kinds
from bodyschema.models.configs import ModelConfig

POSITIONAL = {"self", "body", "modality", "output_shape", "output_shapes", "image_shape"}
SET_BY_MODEL = {"multimodal": {"precision"}}    # a member's `precision` comes from the model's `precisions`
TRAINABLE = [k.name for k in kinds.trainable() if k.module.startswith("bodyschema.models.")]


def constructor_keywords(kind: kinds.Kind) -> dict[str, object]:
    """name → default of the hyper-parameters the kind's constructor takes. A constructor that forwards
    **kwargs to the saved class (multimodal → its members) takes the saved class's keywords too, except the ones
    it sets itself (a member's `precision` comes from the model's `precisions`)."""
    built, saved = kinds.model_class(kind.name), kinds.saved_class(kind.name)
    params = inspect.signature(built).parameters
    keywords = {n: p.default for n, p in params.items()
                if n not in POSITIONAL and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)}
    if any(p.kind is p.VAR_KEYWORD for p in params.values()) and saved is not built:
        forwarded = constructor_keywords_of(saved)
        keywords.update({n: d for n, d in forwarded.items() if n not in SET_BY_MODEL.get(kind.name, ())})
    return keywords


def constructor_keywords_of(cls: type) -> dict[str, object]:
    return {n: p.default for n, p in inspect.signature(cls).parameters.items() if n not in POSITIONAL}


@pytest.mark.parametrize("name", TRAINABLE)
def test_config_fields_are_the_constructors_hyper_parameters_with_its_defaults(name):
    kind = kinds.KINDS[name]
    expected = constructor_keywords(kind)
    for skipped in kind.config_class.not_on_cli:
        assert skipped in expected, f"{kind.config_class.__name__}.not_on_cli names {skipped!r}, not a parameter"
        del expected[skipped]
    fields = {f.name: f.default for f in dataclasses.fields(kind.config_class)}
    assert sorted(fields) == sorted(expected), (
        f"{kind.config_class.__name__} fields vs {kind.trains}'s keywords: "
        f"missing {sorted(set(expected) - set(fields))}, "
        f"extra {sorted(set(fields) - set(expected))}")
    differ = {n: (fields[n], expected[n]) for n in fields if fields[n] != expected[n]}
    assert not differ, f"{kind.config_class.__name__} defaults (config, model) differ: {differ}"


@pytest.mark.parametrize("name", TRAINABLE)
def test_every_field_has_a_help_line_and_the_defaults_pass_the_checks(name):
    config = kinds.KINDS[name].config_class
    source = inspect.getsource(config)
    for f in dataclasses.fields(config):
        line = next(line for line in source.splitlines() if line.strip().startswith(f"{f.name}:"))
        assert "  # " in line, f"{config.__name__}.{f.name} has no help comment (tyro shows it in --help)"
    assert isinstance(config(), ModelConfig)                 # the defaults are valid values


def test_literal_choices_are_the_words_the_models_accept():
    from bodyschema.models import mdn, multimodal, pixel
    from bodyschema.models.configs import MDNConfig, MultimodalConfig, PixelConfig

    def choices(config, name):
        return set(typing.get_args(typing.get_type_hints(config)[name]))

    assert choices(MDNConfig, "mode") == set(mdn.MODES)
    assert choices(PixelConfig, "size") == set(pixel.SIZES)
    assert choices(MultimodalConfig, "decoder") == set(multimodal.DECODERS)
