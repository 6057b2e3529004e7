"""Which benchmark a report section is, and where it goes: sections follow the pipeline as the README tells it (data →
models → levels → robustness → tracking → reaching → adaptation → self-recognition → rubber hand → agency), then any
other benchmark A→Z.

A run names its benchmark in its run.json (the config class, looked up in the registry), whatever folder `--out`
chose; a run older than run.json by its folder's name, a variant's folder included (the demo's `levels_gpr`,
`reaching_panda`).
"""

from __future__ import annotations

from bodyschema.evaluation import registry

# Tracking is perception over a stream: it follows the levels (perception of one frame) and their robustness, before
# the loop closes. Closed-loop robustness (`loop_robustness`) is reaching under noise: it follows reaching, which it
# needs a reader to know. `data` and `models`: plain folders holding a summary.md of the first stages, should a user
# add them; `trained`: the models `bodyschema train` fitted (trained.py).
PIPELINE = ("data", "models", "trained", "levels", "robustness", "tracking", "reaching", "loop_robustness",
            "adaptation", "self_recognition", "rubber_hand", "agency")


def registry_key(bench: registry.Benchmark) -> str:
    """A registered benchmark's key, as its default folder under results/ spells it (`adaptation/jupiter`)."""
    return "/".join(bench.words).replace("-", "_")


def benchmark_of(record: dict, name: str) -> str | None:
    """The registry key of the run whose run.json is `record` and whose benchmark folder is `name` (relative to
    results); None: no registered benchmark (a plain folder, a benchmark unknown here)."""
    for bench in registry.BENCHMARKS:
        module = str(record.get("module", ""))
        if record.get("config") == bench.names[0] and (module + ".").startswith(bench.module + "."):
            return registry_key(bench)
    return _stage(name, [registry_key(b) for b in registry.BENCHMARKS])


def order_key(benchmark: str | None, name: str, robot: str | None) -> tuple:
    """Sort key of a section: pipeline stage, then folder (a benchmark's own folder before its variants and cases),
    then robot (a run without one first)."""
    stage = _stage(benchmark or name, PIPELINE)
    rank = PIPELINE.index(stage) if stage else len(PIPELINE)
    return rank, name.split("/")[0], name.count("/"), name, robot or ""


def _stage(name: str, stages) -> str | None:
    """The longest of `stages` that `name` is, or is a variant (`<stage>_…`) or case (`<stage>/…`) of."""
    name = name.replace("-", "_")
    fits = [s for s in stages if name == s or name.startswith((f"{s}_", f"{s}/"))]
    return max(fits, key=len, default=None)
