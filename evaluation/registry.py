"""The registry of benchmarks: the CLI's `bodyschema evaluate` group is built from it, the determinism test runs
every entry. A new benchmark is one folder under evaluation/ and one line here (see the README's recipe).

Each entry: the CLI words under `evaluate`, the package and the names of its config class (a
`core.config.BenchmarkConfig`) and runner (`run(config, models=None)` → the paths it wrote), a one-line help, and
the keywords of a seconds-long config that writes under `out` (`tiny(out)`), for the tests. Names, not objects:
the package (torch, MuJoCo) is imported only when its benchmark is run or its `--help` shown.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Benchmark:
    words: tuple[str, ...]             # `bodyschema evaluate <words>`; two words: a group and its member
    package: str                       # bodyschema.evaluation.<package>, imported only when used: `bodyschema
                                       # --help` and the other commands never pull in torch or MuJoCo through here
    names: tuple[str, str]             # (config class, runner) exported by the package
    help: str
    tiny_args: Callable[[Path], dict]  # out → keywords of a config that runs in seconds (determinism test)

    def __post_init__(self) -> None:
        names = self.names if isinstance(self.names, tuple) else ()
        if not (isinstance(self.package, str) and len(names) == 2 and all(isinstance(n, str) for n in names)):
            raise TypeError(f"Benchmark {self.words} must name its package and (config class, runner) as strings, "
                            f'e.g. Benchmark(("levels",), "levels", ("LevelsConfig", "run_levels"), help, tiny). '
                            f"Got {self.package!r}, {self.names!r}.")

    @property
    def module(self) -> str:
        return f"bodyschema.evaluation.{self.package}"

    @property
    def config(self) -> type:
        return getattr(importlib.import_module(self.module), self.names[0])

    @property
    def run(self) -> Callable:
        """The runner, timed (`core.runs.clocked`): its MLflow run starts when the benchmark does, not when it logs."""
        from bodyschema.evaluation.core.runs import clocked
        return clocked(getattr(importlib.import_module(self.module), self.names[1]))

    def tiny(self, out: Path):
        return self.config(**self.tiny_args(out))


GROUPS = {"adaptation": "Adaptation in the loop."}     # help of the groups the words name
QUIET = {"mlflow": False, "progress": False}

BENCHMARKS = (   # (words, package, (config class, runner), help, tiny keywords)
    Benchmark(("levels",), "levels", ("LevelsConfig", "run_levels"),
              "Estimation levels 1–3: where is my body? (AIF perception)",
              lambda out: dict(trials=4, runs=1, multistart=0, plots=False, out=out, **QUIET)),
    Benchmark(("robustness",), "robustness", ("RobustnessConfig", "run_robustness"),
              "Joint error vs observation noise and with a broken sensor.",
              lambda out: dict(trials=4, sigmas=(0.0, 0.01), plots=False, out=out, **QUIET)),
    Benchmark(("reaching",), "reaching", ("ReachingConfig", "run_reaching"),
              "Closed-loop AIF reaching to image / ee-pixel / ee-position goals vs PD.",
              lambda out: dict(trials=2, duration=0.1, out=out, **QUIET)),
    Benchmark(("loop-robustness",), "robustness", ("LoopRobustnessConfig", "run_loop_robustness"),
              "Reaching success vs observation noise and with a sensor broken.",
              lambda out: dict(trials=2, duration=0.1, sigmas=(0.0, 0.01), out=out, **QUIET)),
    Benchmark(("adaptation", "marker-shift"), "adaptation", ("MarkerShiftConfig", "run_marker_shift"),
              "(a) The visual marker moves on the hand at run time.",
              lambda out: dict(trials=1, shifts=("left",), duration=0.2, shift_time=0.1, visual_precisions=(1.0,),
                               out=out, **QUIET)),
    Benchmark(("adaptation", "jupiter"), "adaptation", ("JupiterConfig", "run_jupiter"),
              "(b) Gravity jumps to 24.79 m/s² mid-task: PD vs AIC on the panda.",
              lambda out: dict(trials=1, duration=0.2, switch_time=0.1, steady_window=0.05, out=out, **QUIET)),
    Benchmark(("self-recognition",), "self_recognition", ("SelfRecognitionConfig", "run_self_recognition"),
              "Is this me? AUC of the free energy vs an imitator's delay and viewing time: own body vs others.",
              lambda out: dict(trials=3, steps=3, delays=(0.0, 0.1), plots=False, out=out, **QUIET)),
    Benchmark(("rubber-hand",), "rubber_hand", ("RubberHandConfig", "run_rubber_hand"),
              "Rubber-hand drift: the felt hand drifts towards a displaced seen hand (sync vs async stroking).",
              lambda out: dict(trials=2, displacements=(0.1,), visual_sigmas=(0.01,), duration=6.0, plots=False,
                               out=out, **QUIET)),
    Benchmark(("agency",), "agency", ("AgencyConfig", "run_agency"),
              "Did I do it? AUC of the free energy of predicted consequences: own vs imposed movements.",
              lambda out: dict(trials=4, steps=4, delays=(0.0, 0.05), plots=False, out=out, **QUIET)),
    Benchmark(("tracking",), "tracking", ("TrackingConfig", "run_tracking"),
              "Where is my arm now? Babbling streams at 10–60 Hz followed frame by frame: encoder, flow, tracker.",
              lambda out: dict(trials=2, duration=0.5, rates=(10.0,), calibration_frames=10, plots=False, out=out,
                               **QUIET)),
)
