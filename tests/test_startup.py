"""Start-up stays light: the CLI module and the help of unrelated commands import no stage (torch, MuJoCo, MLflow);
a command imports only its own stage. Each check runs in a fresh interpreter (sys.modules of this one is full).
Speed itself is measured by bench/startup.py, not asserted here."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

HEAVY = ("torch", "mujoco", "mlflow", "gpytorch", "sklearn", "matplotlib", "zarr")
BENCHMARK_PACKAGES = ("levels", "robustness", "reaching", "adaptation", "self_recognition", "rubber_hand", "agency")


def loaded_after(code: str, tmp_path: Path) -> set[str]:
    """The module names loaded in a fresh interpreter after running `code`."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr
    return set(json.loads(done.stdout.strip().splitlines()[-1]))


def help_of(*words: str) -> str:
    return (f"from bodyschema.cli import main\ntry:\n    main({list(words) + ['--help']!r})\n"
            "except SystemExit as e:\n    assert e.code == 0, e.code")


def test_importing_the_cli_imports_no_stage(tmp_path):
    loaded = loaded_after("import bodyschema.cli", tmp_path)
    assert not {m for m in HEAVY if m in loaded}, "bodyschema.cli must import no heavy library"


@pytest.mark.parametrize("words", [(), ("train",), ("train", "gpr"), ("evaluate",), ("registry", "list"),
                                   ("export", "onnx")], ids=lambda w: " ".join(w) or "top")
def test_help_of_commands_without_a_stage_to_show_imports_none(words, tmp_path):
    loaded = loaded_after(help_of(*words), tmp_path)
    assert not {m for m in HEAVY if m in loaded}, f"`bodyschema {' '.join(words)} --help` imported a stage"


def test_a_benchmark_imports_its_own_package_and_no_other(tmp_path):
    loaded = loaded_after(help_of("evaluate", "rubber-hand"), tmp_path)
    assert "bodyschema.evaluation.rubber_hand" in loaded, "its config is the real one"
    others = {p for p in BENCHMARK_PACKAGES if p != "rubber_hand" and f"bodyschema.evaluation.{p}" in loaded}
    assert not others, f"`evaluate rubber-hand --help` imported other benchmarks: {others}"


def test_help_from_a_bare_shell_is_quiet(tmp_path):
    """`env -i PATH=/usr/bin:/bin HOME=$HOME bodyschema --help`: the help on stdout, nothing on stderr."""
    script = Path(sys.executable).with_name("bodyschema")
    done = subprocess.run([str(script), "--help"], capture_output=True, text=True, cwd=tmp_path, timeout=300,
                          env={"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", str(tmp_path))})
    assert done.returncode == 0 and "evaluate" in done.stdout and "--quiet" in done.stdout
    assert done.stderr == ""
