"""How many intra-op threads torch gets for the project's small networks: measured, overridable, said in --verbose.

Why: a training step of the demo's pixel decoder (batch 16, 56×80) or a levels batch is a few milliseconds of
small convolutions. Several OpenMP threads then mostly synchronise, and each waiting thread spins on its core; on a
machine whose cores are busy (a laptop with other work, a shared server) they spin against the other jobs and
against each other. Issue 36: a decoder epoch on a loaded 2-core machine took 43 s at 2 threads, 3.9 s at 1; the
demo 30 min instead of ~4. `bench/busy.py` measures it here, idle vs beside a CPU hog, 1 vs N threads.

The rule (`choose`; the first that applies wins):
  1. `BODYSCHEMA_THREADS=N` (the CLI's `--threads N` sets it, so its child processes inherit it): N.
     `auto` (or empty) means this rule does not apply.
  2. The user chose already: `OMP_NUM_THREADS` or `MKL_NUM_THREADS` in the environment, or torch's count changed
     since this module was imported (`torch.set_num_threads` in the host script) → left as it is.
  3. torch has one thread anyway: 1.
  4. Measured: training steps of a small decoder (the demo's lean pixel decoder at batch 16) at 1 and at N threads
     (torch's count), in rounds of STEPS_PER_ROUND steps at each count; N only when it is `FASTER_BY` faster in most
     rounds: one thread loses at most N× on an idle machine and only on these small ops, N threads lost 10× and more
     beside other work.
The measurement is made once per process and kept (on 2 cores, torch's import included: ~1 s idle, 2.1–2.7 s beside a
spinning process per core, where the N-thread block gives up after twice the 1-thread block's time). Load that starts
after it is not seen.

Who applies it: the CLI, around the commands that run networks (`applied_for`); a library call keeps the host's
torch threads unless it calls `apply()` (as a library call prints nothing unless asked, bodyschema/log.py). Code
that needs one thread whatever the policy (per-tick tensors of a simulation loop) uses `pinned(1)`.

Float rounding: a convolution or matrix product sums in an order that depends on the thread split, so the thread
count changes the last digits of a training run (the README's reproductions pin `OMP_NUM_THREADS=1` or
`BODYSCHEMA_THREADS=1`); the --verbose line names the count a run used.

It imports nothing of ours but `bodyschema.errors` (any stage may import it, as `bodyschema.log`), and torch only
when a choice is made: the CLI's start-up stays light.
"""

from __future__ import annotations

import contextlib
import logging
import os
import statistics
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

from bodyschema.errors import must_be

ENV = "BODYSCHEMA_THREADS"
USER_ENV = ("OMP_NUM_THREADS", "MKL_NUM_THREADS")   # what torch itself reads at start
FASTER_BY = 1.25          # N threads must make a step this much faster than 1 to be chosen (asymmetric risk, above)
ROUNDS = 3                # measured rounds per thread count, after a warm-up step each (pool start, oneDNN primitives)
STEPS_PER_ROUND = 16      # steps a round times at each count: ~80 ms, several of the scheduler's slices. Rounds of one
# step let a hog's contention slip between slices: beside a spinning process per core, 2 threads won in 3 of 6 fresh
# processes, and `make demo` took 544 s instead of ~100 (its levels and tracking 16–47× slower); 16 steps: 0 of 6
# The commands that run networks or GPs in their own process (`reproduce` runs its steps in-process).
NETWORK_COMMANDS = ("train", "sweep", "evaluate", "demo", "reproduce")
_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Choice:
    threads: int
    reason: str               # why, in words: the --verbose line's tail
    seconds: dict | None = None   # measured: threads → median seconds per probe step, "won" of "rounds"


_measurements: dict[int, dict] = {}           # N → measure_probe(N), once per process
_import_threads: int | None = None            # torch's count when first asked (a later change is the host's)
_applied: int | None = None                   # the count `apply` set (not the host's own choice)
_before_apply: int | None = None              # torch's count before `apply` set it (`reset` restores it)


def choose(measure: Callable[[int], dict] | None = None, env: Mapping[str, str] | None = None) -> Choice:
    """The thread count by the rule above (not cached, nothing set). `measure(n)` → {1: s, n: s} per probe step
    and "won" of "rounds" (default `measure_probe`); `env` defaults to os.environ. A bad BODYSCHEMA_THREADS raises
    the house error."""
    import torch

    _remember_start()
    env = os.environ if env is None else env
    forced = _forced(env.get(ENV, ""))
    if forced is not None:
        return Choice(forced, f"{ENV}={forced}")
    current = torch.get_num_threads()
    user = [f"{name}={env[name]}" for name in USER_ENV if env.get(name, "")]
    if user:
        return Choice(current, f"{', '.join(user)} set by you")
    if _import_threads is not None and current not in (_import_threads, _applied):
        return Choice(current, "torch.set_num_threads set by the caller")
    if current == 1:
        return Choice(1, "torch has one thread (one core)")
    seconds = (measure or measure_probe)(current)
    won, rounds = seconds["won"], seconds["rounds"]
    threads = current if won * 2 > rounds else 1
    return Choice(threads, f"a small decoder's training step measured: 1 thread {seconds[1] * 1e3:.0f} ms, "
                           f"{current} threads {seconds[current] * 1e3:.0f} ms (median), {current} threads "
                           f"{FASTER_BY:g}× faster in {won} of {rounds} rounds; {ENV}=N or --threads N to choose",
                  seconds)


def apply(measure: Callable[[int], dict] | None = None) -> Choice:
    """`choose` (its measurement made once per process and count, `_measured`), set torch's intra-op count to it,
    and log the --verbose line."""
    global _applied, _before_apply
    import torch

    choice = choose(measure or _measured)
    _log.debug(line(choice))
    if _before_apply is None:
        _before_apply = torch.get_num_threads()
    torch.set_num_threads(choice.threads)
    _applied = choice.threads
    return choice


def _measured(threads: int) -> dict:
    if threads not in _measurements:
        _measurements[threads] = measure_probe(threads)
    return _measurements[threads]


@contextlib.contextmanager
def applied_for(command: str) -> Iterator[Choice | None]:
    """`apply()` for the `with` body when `command` ("bodyschema <words>") runs networks (NETWORK_COMMANDS), torch's
    count restored after (an in-process caller, a test, keeps its own); yields the choice, None for other commands."""
    global _applied, _before_apply
    words = command.split()[1:2]
    if not (words and words[0] in NETWORK_COMMANDS):
        yield None
        return
    import torch

    before = torch.get_num_threads()
    try:
        yield apply()
    finally:
        torch.set_num_threads(before)
        _applied = _before_apply = None


def split_flag(argv: list[str], environ: dict | None = None) -> list[str]:
    """argv without the global `--threads N` / `--threads=N` (before or after the subcommand), N put in
    BODYSCHEMA_THREADS of `environ` (os.environ) so that child processes see it.
    N is checked when the choice is made (`choose`: the house error); a `--threads` without a value stays in argv
    (the parser names it)."""
    environ = os.environ if environ is None else environ
    rest, i = [], 0
    while i < len(argv):
        if argv[i] == "--threads" and i + 1 < len(argv):
            environ[ENV] = argv[i + 1]
            i += 2
            continue
        if argv[i].startswith("--threads="):
            environ[ENV] = argv[i].split("=", 1)[1]
        else:
            rest.append(argv[i])
        i += 1
    return rest


def line(choice: Choice) -> str:
    """The --verbose line: the count and why."""
    return f"torch intra-op threads: {choice.threads} ({choice.reason})"


def reset() -> None:
    """Forget the measurement and give torch back the count `apply` found (tests; a host whose load changed)."""
    global _applied, _before_apply
    if _before_apply is not None:
        import torch

        torch.set_num_threads(_before_apply)
    _measurements.clear()
    _applied = _before_apply = None


@contextlib.contextmanager
def pinned(threads: int) -> Iterator[None]:
    """torch at `threads` intra-op threads for the `with` body, restored after (also on an exception)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def measure_probe(threads: int, rounds: int = ROUNDS) -> dict:
    """Seconds per training step of a small decoder at 1 and at `threads` intra-op threads, in rounds of
    STEPS_PER_ROUND steps at each count (load from other processes hits both alike), after a warm-up step at each
    count: oneDNN's primitives, and at `threads` the OpenMP pool's start (alone 2–7× a 1-thread step).
    It stops once a majority of `rounds` is decided either way (a round is won by `threads` when its steps are
    FASTER_BY faster than the round's 1-thread steps), or at once when `threads` are more than 2× slower (the loaded
    machine: its N-thread steps are the expensive ones, ~0.5 s each on 2 cores beside a hog; the block gives up
    there). torch's count is restored.
    → {1: s per step, threads: s per step (medians over rounds), "won": rounds won by `threads`, "rounds": run}"""
    step = _probe()
    times: dict[int, list[float]] = {1: [], threads: []}
    won = lost = 0
    with pinned(1):
        for n in times:
            _set(n)
            step()
        while max(won, lost) <= rounds // 2:
            _set(1)
            times[1].append(_block(step, STEPS_PER_ROUND))
            _set(threads)
            times[threads].append(_block(step, STEPS_PER_ROUND, give_up=2 * STEPS_PER_ROUND * times[1][-1]))
            if times[threads][-1] * FASTER_BY <= times[1][-1]:
                won += 1
            else:
                lost += 1 if times[threads][-1] <= 2 * times[1][-1] else rounds    # far slower: decided
    return {1: statistics.median(times[1]), threads: statistics.median(times[threads]), "won": won,
            "rounds": len(times[1])}


def _block(step: Callable[[], None], steps: int, give_up: float = float("inf")) -> float:
    """Seconds per step over `steps` steps, stopping early (after at least one) once `give_up` seconds have passed."""
    start, done = time.perf_counter(), 0
    while done < steps and (done == 0 or time.perf_counter() - start <= give_up):
        step()
        done += 1
    return (time.perf_counter() - start) / done


def _probe() -> Callable[[], None]:
    """One SGD step of the demo's lean pixel decoder (models/pixel.py: 5 joints → 56×80) at batch 16, written with
    functional ops on tensors drawn from its own generator: no global RNG draw, no module or optimiser set-up cost."""
    import torch
    import torch.nn.functional as F

    gen = torch.Generator().manual_seed(0)

    def weights(*shape):
        return (torch.randn(*shape, generator=gen) * 0.05).requires_grad_()

    w1, b1, w2, b2 = weights(64, 5), weights(64), weights(32 * 7 * 10, 64), weights(32 * 7 * 10)
    convs = [(weights(a, b, 4, 4), weights(b)) for a, b in ((32, 16), (16, 8), (8, 1))]   # ConvTranspose2d(a, b)
    params = [w1, b1, w2, b2, *(t for pair in convs for t in pair)]
    u = torch.rand(16, 5, generator=gen) * 2 - 1                                   # (16, 5) in [-1, 1]
    target = torch.rand(16, 1, 56, 80, generator=gen)                              # (16, 1, 56, 80)

    def step() -> None:
        y = F.elu(F.linear(F.elu(F.linear(u, w1, b1)), w2, b2)).reshape(16, 32, 7, 10)   # (16, 32, 7, 10)
        for i, (w, b) in enumerate(convs):
            y = F.conv_transpose2d(y, w, b, stride=2, padding=1)                  # ×2: … → (16, 1, 56, 80)
            y = F.elu(y) if i < len(convs) - 1 else y.sigmoid()
        loss = (y - target).pow(2).mean()
        grads = torch.autograd.grad(loss, params)
        with torch.no_grad():
            for p, g in zip(params, grads):
                p -= 1e-3 * g

    return step


def _set(threads: int) -> None:
    import torch

    torch.set_num_threads(threads)


def _forced(text: str) -> int | None:
    text = text.strip()
    if text.lower() in ("", "auto"):
        return None
    if not text.isdigit() or int(text) < 1:
        raise ValueError(must_be(ENV, "a positive integer or 'auto'", text,
                                 "Unset it (or --threads auto) to let bodyschema measure."))
    return int(text)


def _remember_start() -> None:
    """torch's count before anything of ours changed it; called on first use (torch imported by then)."""
    global _import_threads
    if _import_threads is None:
        import sys

        if "torch" in sys.modules:
            _import_threads = sys.modules["torch"].get_num_threads()


_remember_start()
