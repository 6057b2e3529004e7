"""The thread policy (bodyschema/threads.py): the measured choice with an injected measurement (no timing here;
bench/busy.py measures), the override, a user's own setting, the CLI flag and the --verbose line."""

from __future__ import annotations

import pytest
import torch

from bodyschema import cli, threads
from bodyschema.threads import ENV, Choice, choose, pinned
from tests.test_cli_logging import restore_logging_and_env  # noqa: F401 — autouse: configure()'s env and level undone


def loaded(n: int) -> dict:
    """A loaded machine: the N-thread step 10× slower than one thread's (issue 36 measured 11×)."""
    return {1: 0.004, n: 0.040, "won": 0, "rounds": 2}


def idle(n: int) -> dict:
    return {1: 0.004, n: 0.002, "won": 2, "rounds": 2}




@pytest.fixture
def policy(monkeypatch):
    """No user setting in the environment, torch at 4 threads as if it had started there, no measurement kept."""
    for name in (ENV, *threads.USER_ENV):
        monkeypatch.setenv(name, "")          # recorded, so whatever the test (or the CLI's --threads) sets is undone
    monkeypatch.setattr(threads, "_import_threads", 4)
    monkeypatch.setattr(threads, "_measurements", {})
    with pinned(4):
        yield
    threads.reset()


def test_one_thread_on_a_loaded_machine(policy):
    calls = []
    choice = choose(lambda n: calls.append(n) or loaded(n))
    assert (choice.threads, calls) == (1, [4])
    assert "1 thread 4 ms, 4 threads 40 ms" in choice.reason and "0 of 2 rounds" in choice.reason
    assert torch.get_num_threads() == 4                     # choose sets nothing


def test_n_threads_where_they_are_faster(policy):
    assert choose(idle).threads == 4


def test_a_tie_is_one_thread(policy):
    assert choose(lambda n: {1: 0.004, n: 0.004, "won": 1, "rounds": 2}).threads == 1


def test_override_wins_without_measuring(policy, monkeypatch):
    monkeypatch.setenv(ENV, "3")
    assert choose(lambda n: pytest.fail("measured despite the override")) == Choice(3, f"{ENV}=3")
    monkeypatch.setenv(ENV, "auto")
    assert choose(loaded).threads == 1


@pytest.mark.parametrize("bad", ["0", "-1", "two", "1.5"])
def test_bad_override_is_the_house_error(policy, monkeypatch, bad):
    monkeypatch.setenv(ENV, bad)
    with pytest.raises(ValueError, match=f"{ENV} must be a positive integer or 'auto'. Got '{bad}'"):
        choose(loaded)


def test_the_users_omp_num_threads_is_kept(policy, monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "4")
    choice = choose(lambda n: pytest.fail("measured despite OMP_NUM_THREADS"))
    assert choice.threads == 4 and "OMP_NUM_THREADS=4 set by you" in choice.reason


def test_the_callers_set_num_threads_is_kept(policy):
    with pinned(3):                                          # the host script's torch.set_num_threads(3)
        choice = choose(lambda n: pytest.fail("measured despite set_num_threads"))
    assert choice.threads == 3 and "set_num_threads" in choice.reason


def test_apply_sets_measures_once_and_reset_restores(policy):
    calls = []

    def counted(n):
        calls.append(n)
        return loaded(n)

    assert threads.apply(counted).threads == 1
    assert torch.get_num_threads() == 1
    threads.reset()
    assert torch.get_num_threads() == 4
    threads._measurements[4] = loaded(4)                     # what a first measurement in this process kept
    assert threads.apply().threads == 1 and calls == [4]     # kept: not measured again
    threads.reset()


def test_applied_for_network_commands_only_and_restored(policy):
    threads._measurements[4] = loaded(4)
    with threads.applied_for("bodyschema train") as choice:
        assert choice.threads == 1 and torch.get_num_threads() == 1
    assert torch.get_num_threads() == 4
    with threads.applied_for("bodyschema registry list") as choice:
        assert choice is None and torch.get_num_threads() == 4


def test_split_flag():
    env = {}
    assert threads.split_flag(["--threads", "2", "demo", "--threads=3", "-v"], env) == ["demo", "-v"]
    assert env == {ENV: "3"}                                  # the last one given
    assert threads.split_flag(["demo", "--threads"], env) == ["demo", "--threads"]   # no value: left to the parser


def test_measure_probe_restores_the_count(policy):
    seconds = threads.measure_probe(2, rounds=1)
    assert seconds["rounds"] == 1 and seconds[1] > 0 and seconds[2] > 0
    assert torch.get_num_threads() == 4


def test_the_first_step_at_each_count_is_a_warm_up_not_a_round(policy, monkeypatch):
    """A step whose first run at a thread count is slow (OpenMP's pool starting, oneDNN's primitives) and whose later
    runs are 3× faster at 2 threads: the probe must choose 2. Timed on the fake step's own sleeps (30 ms start-up
    against 1–3 ms steps: far above a loaded scheduler's jitter on this order)."""
    import time

    started = set()

    def step():
        n = torch.get_num_threads()
        time.sleep(0.030 if n not in started else (0.001 if n == 2 else 0.003))
        started.add(n)

    monkeypatch.setattr(threads, "_probe", lambda: step)
    seconds = threads.measure_probe(2)
    assert seconds["won"] * 2 > seconds["rounds"], seconds
    assert seconds[2] < seconds[1] < 0.030


def test_a_count_far_slower_is_given_up_within_its_first_round(policy, monkeypatch):
    """Beside a hog an N-thread step took ~0.5 s against 5 ms: the probe stops the N-thread block once it has spent
    twice the 1-thread block's time, and the choice is 1 thread after that one round (counted calls, no timing)."""
    import time

    calls = {1: 0, 2: 0}

    def step():
        n = torch.get_num_threads()
        calls[n] += 1
        time.sleep(0.001 if n == 1 else 0.1)

    monkeypatch.setattr(threads, "_probe", lambda: step)
    seconds = threads.measure_probe(2)
    assert (seconds["won"], seconds["rounds"]) == (0, 1)
    assert calls == {1: 1 + threads.STEPS_PER_ROUND, 2: 1 + 1}       # a warm-up each, then one slow step given up


def test_verbose_line_states_the_count_and_why(policy, tmp_path, capsys, monkeypatch):
    """A network command with --verbose says the count and its reason on stderr before it runs (here it then fails
    at its data: nothing is trained)."""
    monkeypatch.chdir(tmp_path)
    threads._measurements[4] = loaded(4)
    code = cli.main(["--verbose", "train", "gpr", "--data", str(tmp_path / "none.zarr"), "--modality", "ee_xyz"])
    err = capsys.readouterr().err
    assert code == 2
    assert "torch intra-op threads: 1 (a small decoder's training step measured: 1 thread 4 ms, 4 threads 40 ms" in err
    assert torch.get_num_threads() == 4                     # restored after the command
    cli.main(["train", "gpr", "--threads", "2", "-v", "--data", str(tmp_path / "none.zarr")])
    assert f"torch intra-op threads: 2 ({ENV}=2)" in capsys.readouterr().err


def test_bad_threads_flag_is_the_house_error(policy, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["--threads", "0", "train", "gpr", "--data", str(tmp_path / "none.zarr")]) == 2
    assert f"{ENV} must be a positive integer or 'auto'. Got '0'" in capsys.readouterr().err
