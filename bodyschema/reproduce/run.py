"""`bodyschema reproduce`: run the README's recipes (recipes.py) step by step into `<out>/<run-id>/`, resumably
(state.py), after printing what each pending step will cost (probe.py); then write `tables.md`, each README table
beside its reproduction (readme_tables.py), and print it."""

from __future__ import annotations

import logging
import time
from pathlib import Path

from bodyschema.errors import must_be
from bodyschema.reproduce import execute, probe, readme_tables, state
from bodyschema.reproduce.config import ReproduceConfig
from bodyschema.reproduce.recipes import RECIPES, Recipe, Step

logger = logging.getLogger(__name__)
TABLES = "tables.md"


def reproduce(config: ReproduceConfig) -> Path:
    """Run (or continue) a reproduction; returns its tables.md (its folder on a dry run)."""
    recipes = [RECIPES[name] for name in (config.only or RECIPES)]
    readme = _readme(config)
    _check_device(config.device)
    folder, record = _open_run(config, [r.name for r in recipes])
    values = {"run": str(folder.resolve()), "workers": str(config.workers), "device": config.device,
              "tracking": config.tracking_uri or f"sqlite:///{folder.resolve()}/mlflow.db"}
    steps = _steps(recipes)
    products = {name: done["product"] for name, done in record["steps"].items()}
    full = _full_configs(steps, values, products)                    # every command parsed now: a bad one fails first
    pending = [s for s in steps if s.name not in products]
    _print_plan(folder, steps, products, values)
    if config.estimate and pending:
        print("probing the cost of the pending steps at a small size …")
        costs = probe.estimate(pending, products, values, full)
        print("cost estimate (this machine, now):\n" + "\n".join(map(str, costs)))
        print(f"  {'total':<12} ~{sum(c.cpu_seconds for c in costs) / 3600:6.2f} CPU-h    "
              f"~{sum(c.wall_seconds for c in costs) / 3600:6.2f} h wall")
    if config.dry_run:
        return folder
    for step in pending:
        products[step.name] = _run_step(step, values, products, folder, record, config.progress)
    return _finish(folder, record, recipes, readme)


def _readme(config: ReproduceConfig) -> Path:
    readme = config.readme or Path(__file__).resolve().parents[2] / "README.md"
    if not readme.is_file():
        raise FileNotFoundError(must_be("--readme", "the README.md whose tables are reproduced", str(readme),
                                        "Run from a clone of the repository, or pass --readme PATH."))
    return readme


def _check_device(device: str) -> None:
    if device.startswith("cuda"):
        import torch

        if not torch.cuda.is_available():
            raise ValueError(must_be("--device", "a device this machine has", device,
                                     "torch sees no CUDA GPU here: use --device cpu."))


def _open_run(config: ReproduceConfig, names: list[str]) -> tuple[Path, dict]:
    if config.run_id is not None:
        folder = Path(config.out) / config.run_id
        record = state.load(folder)
        if record["recipes"] != names:
            raise ValueError(must_be(f"--only of run {config.run_id}", " ".join(record["recipes"]) or "(all)",
                                     " ".join(names), "A run continues with the recipes it started with."))
        return folder, record
    folder = None if config.fresh else state.unfinished(config.out, names)
    if folder is not None:
        print(f"continuing {folder} (--fresh starts a new run)")
        return folder, state.load(folder)
    return state.new_run(config, names)


def _steps(recipes: list[Recipe]) -> list[Step]:
    """Every recipe's steps in order, a shared step once."""
    return list({step.name: step for recipe in recipes for step in recipe.steps}.values())


def _full_configs(steps: list[Step], values: dict, products: dict) -> dict:
    """Each step's config; a product not made yet stands in as what it will be (a path) or a registry spec."""
    configs, known = {}, dict(products)
    for step in steps:
        configs[step.name] = execute.parse(step.command.format(**values, **known))
        out = getattr(configs[step.name], "out", None)
        known.setdefault(step.name, str(out) if step.command.startswith("datagen") else
                         f"models:/bodyschema-pending-{step.name}@champion")
    return configs


def _print_plan(folder: Path, steps: list[Step], products: dict, values: dict) -> None:
    print(f"reproduce run: {folder}")
    for step in steps:
        shown = step.command.format(**values, **{**{s.name: f"<{s.name}>" for s in steps}, **products})
        print(f"  {'done ' if step.name in products else 'to do'}  {step.name:<10} bodyschema {shown}")


def _run_step(step: Step, values: dict, products: dict, folder: Path, record: dict, progress: bool) -> str:
    command = step.command.format(**values, **products)
    logger.info("== %s: bodyschema %s", step.name, command)
    started = time.perf_counter()
    done = execute.run(execute.parse(command), progress)
    record["steps"][step.name] = {"command": f"bodyschema {command}", "product": done.product,
                                  "seconds": round(time.perf_counter() - started, 1)}
    state.save(folder, record)
    print(f"{step.name}: {done.product} ({record['steps'][step.name]['seconds'] / 60:.1f} min)")
    return done.product


def _finish(folder: Path, record: dict, recipes: list[Recipe], readme: Path) -> Path:
    sections = [f"# Reproduction {folder.name}\n", f"Compared with {readme}. A cell reads README → reproduced "
                "(difference); ✓/✗ where the README states a ± (its spread: over runs for the levels, over "
                "episodes for the rubber hand).\n"]
    for recipe in recipes:
        products = {name: done["product"] for name, done in record["steps"].items()}
        compared = readme_tables.compare(recipe.table, readme, products)
        sections += [f"## {recipe.name}: {recipe.about}\n", readme_tables.markdown(compared) + "\n",
                     "Commands, and their wall time:\n"]
        sections += [f"- `{record['steps'][s.name]['command']}` ({record['steps'][s.name]['seconds'] / 60:.1f} min)"
                     for s in recipe.steps]
        sections.append("")
    record["finished"] = time.time()
    wall = sum(done["seconds"] for done in record["steps"].values())
    sections.append(f"Wall time of the steps: {wall / 60:.1f} min (summed over sessions when continued).")
    path = folder / TABLES
    path.write_text("\n".join(sections) + "\n")
    state.save(folder, record)
    print(path.read_text())
    return path
