"""`bodyschema train <kind>`: one subcommand per model kind whose --help lists every hyper-parameter with its
default, and typed flags that reach the model config."""

import dataclasses
import re

import pytest

from bodyschema.cli import main, parse_command
from bodyschema.models import kinds
from bodyschema.training.config import TrainConfig

TRAINABLE = [k.name for k in kinds.trainable()]


def _shown(value) -> str:
    """A default as tyro prints it: a tuple as its items, else str()."""
    return " ".join(map(str, value)) if isinstance(value, tuple) else str(value)


def _help(words: list[str], capsys, monkeypatch) -> str:
    monkeypatch.setenv("COLUMNS", "200")
    with pytest.raises(SystemExit) as exit_:
        main([*words, "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    return " ".join(re.sub(r"[│╭╮╰╯─]", " ", text).split())          # the box drawn around it, and line wraps


@pytest.mark.parametrize("kind", TRAINABLE)
def test_train_kind_help_lists_every_hyper_parameter_with_its_default(kind, capsys, monkeypatch):
    text = _help(["train", kind], capsys, monkeypatch)
    assert f"usage: bodyschema train {kind}" in text and "--data PATH" in text
    for f in dataclasses.fields(kinds.KINDS[kind].config):
        flag = "--" + f.name.replace("_", "-")
        found = re.search(re.escape(flag) + r"[ ,{\[].*?\(default: (.*?)\)", text)
        assert found, f"{flag} is missing from `bodyschema train {kind} --help`"
        assert found[1] == _shown(f.default), f"{flag}: help shows default {found[1]!r}, the config has {f.default!r}"


def test_train_help_names_every_kind(capsys, monkeypatch):
    text = _help(["train"], capsys, monkeypatch)
    assert all(kind in text for kind in TRAINABLE) and "bodyschema train KIND --help" in text


def test_typed_flags_reach_the_kind_config():
    config = parse_command(["train", "pixel", "--data", "d.zarr", "--epochs", "7", "--channels", "8", "4",
                           "--refine", "True", "--size", "pixel_aif", "--seed", "3"])
    assert isinstance(config, TrainConfig) and config.kind == "pixel" and config.seed == 3
    assert (config.model.epochs, config.model.channels, config.model.refine, config.model.size) == \
        (7, (8, 4), True, "pixel_aif")
    assert config.modality == "image", "the kind's default modality"
    multi = parse_command(["train", "multimodal", "--data", "d.zarr", "--no-joint",
                          "--precisions", "image", "100"])
    assert multi.model.joint is False and multi.model.precisions == {"image": 100.0}
