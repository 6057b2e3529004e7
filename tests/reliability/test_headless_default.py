"""Headless rendering is set in one place, the package's __init__: any module of ours imported first (here the reach,
which imports mujoco itself) gets mujoco's EGL backend without MUJOCO_GL in the environment; a value set wins."""

from __future__ import annotations

import os
import subprocess
import sys


def run_python(code: str, **env: str) -> str:
    clean = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    result = subprocess.run([sys.executable, "-c", code], env={**clean, **env}, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_the_package_sets_egl_before_mujoco_is_imported():
    out = run_python("import bodyschema.datagen.body.reach, mujoco, os\n"
                     "print(os.environ['MUJOCO_GL'], os.environ['PYOPENGL_PLATFORM'], mujoco.GLContext.__module__)")
    assert out.split() == ["egl", "egl", "mujoco.egl"]


def test_a_backend_the_user_set_wins():
    out = run_python("import bodyschema, os; print(os.environ['MUJOCO_GL'], 'PYOPENGL_PLATFORM' in os.environ)",
                     MUJOCO_GL="glfw")
    assert out.split() == ["glfw", "False"]
