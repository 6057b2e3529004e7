"""Suite-wide guards."""

import os

import pytest
import torch

# The CLI's thread policy (bodyschema/threads.py) measures 1 against N torch threads once per process; on an idle
# machine the two are within its 1.25× margin, so two runs of one command could choose differently and differ in the
# last float digits. The suite's commands and their child processes run at one thread; the policy's own tests unset
# this (tests/test_threads_policy.py, fixture `policy`).
os.environ.setdefault("BODYSCHEMA_THREADS", "1")


@pytest.fixture(autouse=True)
def torch_threads_restored():
    """A test that changes torch's thread count must restore it (tests/threads.one_thread does): a leaked count
    changes the float rounding of every later test in the process, which made the suite depend on its order."""
    threads = torch.get_num_threads()
    yield
    leaked = torch.get_num_threads()
    torch.set_num_threads(threads)
    assert leaked == threads, (f"the test left torch.get_num_threads() at {leaked} (was {threads}): "
                               "use tests.threads.one_thread")


@pytest.fixture
def in_world(world, monkeypatch):
    """The bad-input tests' scratch folder (each module's own `world` fixture) as the working folder: default
    outputs (runs/, results/, mlflow.db) land there, and no tracking URI, debug flag or Ray address of the caller's
    environment leaks in."""
    monkeypatch.chdir(world)
    for name in ("MLFLOW_TRACKING_URI", "BODYSCHEMA_DEBUG", "RAY_ADDRESS"):
        monkeypatch.delenv(name, raising=False)
    return world


@pytest.fixture
def figures():
    """Figures a test built (a plot's *_figure function leaves closing to its caller), closed after it."""
    import matplotlib.pyplot as plt
    made = []
    yield made.append
    for fig in made:
        plt.close(fig)
