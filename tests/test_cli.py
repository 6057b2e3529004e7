"""The `bodyschema` CLI: every subcommand has help, bad input exits non-zero with the house message, and
`validate` answers with its exit code."""

import subprocess
import sys

import pytest

from bodyschema.cli import main

SUBCOMMANDS = [["datagen"], ["validate"], ["train"], ["registry", "list"], ["registry", "promote"],
               ["evaluate", "levels"], ["evaluate", "robustness"], ["evaluate", "reaching"],
               ["evaluate", "loop-robustness"], ["evaluate", "adaptation", "marker-shift"],
               ["evaluate", "adaptation", "jupiter"], ["evaluate", "self-recognition"], ["report"], ["demo"]]


@pytest.mark.parametrize("words", SUBCOMMANDS, ids=" ".join)
def test_every_subcommand_has_help(words, capsys):
    with pytest.raises(SystemExit) as exit_:
        main([*words, "--help"])
    assert exit_.value.code == 0
    assert "usage: bodyschema" in capsys.readouterr().out


def test_bad_datagen_input_exits_nonzero_with_the_house_message(tmp_path):
    out = tmp_path / "bad.zarr"
    result = subprocess.run([sys.executable, "-m", "bodyschema.cli", "datagen", "--n", "0", "--out", str(out)],
                            capture_output=True, text=True)
    assert result.returncode != 0
    assert "n must be an integer >= 1. Got 0." in result.stdout + result.stderr
    assert not out.exists(), "a refused config must leave nothing behind"


def test_validate_exit_code_reflects_the_store(tmp_path, capsys):
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.generate import generate

    store = generate(DatagenConfig(robot="planar2", n=64, images=False, shard_size=32, out=tmp_path / "ok.zarr"),
                     progress=False)
    assert main(["validate", str(store)]) == 0
    (tmp_path / "empty.zarr").mkdir()
    assert main(["validate", str(tmp_path / "empty.zarr")]) == 1            # a store with problems: the answer
    assert "problem" in capsys.readouterr().out
    assert main(["validate", str(tmp_path / "missing.zarr")]) == 2          # no store at all: bad input
    assert "path must be an existing .zarr store" in capsys.readouterr().err


@pytest.mark.parametrize("words", [["evaluate", "levels"], ["evaluate", "reaching"], ["evaluate", "self-recognition"],
                                   ["evaluate", "adaptation", "jupiter"]], ids=" ".join)
def test_repeated_model_flags_fuse_instead_of_replacing(words):
    from bodyschema.cli import parse_command
    models = ["--model", "analytic:nao_arm:ee_xyz", "--model", "analytic:nao_arm:joints"]
    config = parse_command([*words, *models])
    assert config.models == ("analytic:nao_arm:ee_xyz", "analytic:nao_arm:joints")
