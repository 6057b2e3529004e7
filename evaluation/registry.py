"""The registry of benchmarks: the CLI's `bodyschema evaluate` group is built from it, the determinism test runs
every entry. A new benchmark is one folder under evaluation/ and one line here (see the README's recipe).

Each entry: the CLI words under `evaluate`, the config class (a `core.config.BenchmarkConfig`), the runner
(`run(config, models=None)` → the paths it wrote), a one-line help, and `tiny(out)`: a seconds-long config that
writes under `out`, for the tests.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from bodyschema.evaluation.adaptation import JupiterConfig, MarkerShiftConfig, run_jupiter, run_marker_shift
from bodyschema.evaluation.agency import AgencyConfig, run_agency
from bodyschema.evaluation.levels import LevelsConfig, run_levels
from bodyschema.evaluation.reaching import ReachingConfig, run_reaching
from bodyschema.evaluation.robustness import (LoopRobustnessConfig, RobustnessConfig, run_loop_robustness,
                                              run_robustness)
from bodyschema.evaluation.rubber_hand import RubberHandConfig, run_rubber_hand
from bodyschema.evaluation.self_recognition import SelfRecognitionConfig, run_self_recognition


@dataclass(frozen=True)
class Benchmark:
    words: tuple[str, ...]             # `bodyschema evaluate <words>`; two words: a group and its member
    config: type
    run: Callable
    help: str
    tiny: Callable[[Path], object]     # out → a config that runs in seconds (determinism test)


GROUPS = {"adaptation": "Adaptation in the loop."}     # help of the groups the words name
QUIET = {"mlflow": False, "progress": False}

BENCHMARKS = (
    Benchmark(("levels",), LevelsConfig, run_levels, "Estimation levels 1–3: where is my body? (AIF perception)",
              lambda out: LevelsConfig(trials=4, runs=1, multistart=0, plots=False, out=out, **QUIET)),
    Benchmark(("robustness",), RobustnessConfig, run_robustness,
              "Joint error vs observation noise and with a broken sensor.",
              lambda out: RobustnessConfig(trials=4, sigmas=(0.0, 0.01), plots=False, out=out, **QUIET)),
    Benchmark(("reaching",), ReachingConfig, run_reaching,
              "Closed-loop AIF reaching to image / ee-pixel / ee-position goals vs PD.",
              lambda out: ReachingConfig(trials=2, duration=0.1, out=out, **QUIET)),
    Benchmark(("loop-robustness",), LoopRobustnessConfig, run_loop_robustness,
              "Reaching success vs observation noise and with a sensor broken.",
              lambda out: LoopRobustnessConfig(trials=2, duration=0.1, sigmas=(0.0, 0.01), out=out, **QUIET)),
    Benchmark(("adaptation", "marker-shift"), MarkerShiftConfig, run_marker_shift,
              "(a) The visual marker moves on the hand at run time.",
              lambda out: MarkerShiftConfig(trials=1, shifts=("left",), duration=0.2, shift_time=0.1,
                                            visual_precisions=(1.0,), out=out, **QUIET)),
    Benchmark(("adaptation", "jupiter"), JupiterConfig, run_jupiter,
              "(b) Gravity jumps to 24.79 m/s² mid-task: PD vs AIC on the panda.",
              lambda out: JupiterConfig(trials=1, duration=0.2, switch_time=0.1, steady_window=0.05, out=out,
                                        **QUIET)),
    Benchmark(("self-recognition",), SelfRecognitionConfig, run_self_recognition,
              "Is this me? AUC of the free energy vs an imitator's delay and viewing time: own body vs others.",
              lambda out: SelfRecognitionConfig(trials=3, steps=3, delays=(0.0, 0.1), plots=False, out=out,
                                                **QUIET)),
    Benchmark(("rubber-hand",), RubberHandConfig, run_rubber_hand,
              "Rubber-hand drift: the felt hand drifts towards a displaced seen hand (sync vs async stroking).",
              lambda out: RubberHandConfig(trials=2, displacements=(0.1,), visual_sigmas=(0.01,), duration=6.0,
                                           plots=False, out=out, **QUIET)),
    Benchmark(("agency",), AgencyConfig, run_agency,
              "Did I do it? AUC of the free energy of predicted consequences: own vs imposed movements.",
              lambda out: AgencyConfig(trials=4, steps=4, delays=(0.0, 0.05), plots=False, out=out, **QUIET)),
)
