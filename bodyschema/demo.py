"""The end-to-end demo on embedded defaults: babble → dataset → fit → registry → Jacobian → AIF levels → tracking →
reaching → self-recognition → rubber hand → agency → report.

Sized for 2 CPU cores in a few minutes: small datasets for every robot (validated, summarised, a contact sheet
each), GPR + MDN on nao_arm ee_xyz and a pixel decoder and an image encoder on its 56×80 images, all registered in
MLflow; then, with the models loaded back from the registry by URI: the estimation levels 1–3 (the GPR; the pixel
decoder from its own and the encoder's starts, beside its floor: what a seconds-long decoder reaches, and the
README's recipe), a tracking episode (the arm followed frame by frame from the camera at 30 Hz), closed-loop
reaching to end-effector goals (the GPR fused with the joint encoder) against a PD baseline, "is this me?" on its ee
stream, the rubber-hand drift and "did I do it?"; last, one report page (Markdown + HTML) of every table and plot.
Each stage's wall time is printed at the end.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from bodyschema.demo_config import (
    DemoConfig,
    act_configs,
    body_and_agency_configs,
    check_demo,
    datagen_jobs,
    levels_config,
    tracking_config,
    train_jobs,
)
from bodyschema.log import progress_bars, progress_of

logger = logging.getLogger(__name__)   # the section headers (info); tables and paths written are printed
# What the README's levels table was measured with (`make reproduce ONLY=levels`), for the line beside the demo's.
RECIPE = ("the README's recipe (`make reproduce ONLY=levels`: 18 000 images, decoder 60 epochs, encoder 40) "
          "reaches 0.48° at every level with the encoder")


def run_demo(config: DemoConfig) -> None:
    check_demo(config)
    clock = _Stages()
    stores = clock("datagen", _datagen, config)
    trained = clock("train", _train, config, stores["nao_arm"])
    gpr = f"models:/{trained['gpr'].registered_name}@champion"
    clock("levels (GPR)", _evaluate, config, gpr, "gpr")
    decoder = clock("levels (pixel)", _evaluate_pixel, config, trained)
    clock("tracking", _track, config, decoder, _version_uri(trained["encoder"]))
    clock("reaching and self-recognition", _act, config, gpr)
    clock("rubber hand and agency", _body_and_agency, config, gpr)
    clock("registry and report", _report, config)
    print(f"Everything else is under {config.out.resolve()}")
    print(clock.summary())


class _Stages:
    """Runs the demo's stages and keeps their wall times, printed last: where a newcomer's minutes went."""

    def __init__(self):
        self.seconds: dict[str, float] = {}

    def __call__(self, name: str, stage, *args):
        start = time.perf_counter()
        try:
            return stage(*args)
        finally:
            self.seconds[name] = time.perf_counter() - start

    def summary(self) -> str:
        parts = " · ".join(f"{name} {s:.0f}" for name, s in self.seconds.items())
        return f"demo stages (wall s): {parts} · total {sum(self.seconds.values()):.0f}"


def _datagen(config: DemoConfig) -> dict[str, Path]:
    from bodyschema.datagen.generate import generate
    from bodyschema.datagen.store.contact_sheet import write_contact_sheet
    from bodyschema.datagen.store.validate import summarize_store, validate_store

    stores = {}
    for robot, job in datagen_jobs(config).items():
        logger.info(f"== datagen {robot}: {job.n} samples, sampler {job.sampler}")
        stores[robot] = generate(job, progress=progress_bars())    # no progress flag of its own
        problems = validate_store(stores[robot])
        if problems:
            raise RuntimeError(f"demo dataset {stores[robot]} is invalid:\n" + "\n".join(problems))
        print(summarize_store(stores[robot], check=False))
        sheet = write_contact_sheet(stores[robot], config.out / f"contact_sheet_{robot}.png")
        print(f"contact sheet: {sheet}")
    return stores


def _train(config: DemoConfig, nao_store: Path) -> dict:
    """kind → its TrainResult (registered; the champion alias moved only by a better version)."""
    from bodyschema.training.train import train

    results = {}
    for kind, job in train_jobs(config, nao_store).items():
        logger.info(f"== train {kind} on nao_arm {job.modality}")
        result = train(progress_of(job))
        shown = ", ".join(f"{k}={v:.4g}" for k, v in result.metrics.items() if k.startswith("val_"))
        print(f"{result.registered_name} v{result.model_version} {shown}"
              f"{' (new champion)' if result.champion else ''}; plots: {list(map(str, result.plots.values()))}")
        results[kind] = result
    return results


def _version_uri(result) -> str:
    """The registered version this run trained, not the champion: the pixel part describes this decoder (its epochs,
    images and floor), which a better champion from an earlier run would not match."""
    return f"models:/{result.registered_name}/{result.model_version}"


def _evaluate(config: DemoConfig, uri: str, kind: str, models=None, encoder: str | None = None):
    from bodyschema.evaluation.levels import run_levels

    logger.info(f"== AIF perception, levels 1–3, with {uri} loaded from the registry"
                f"{f' (+enc rows: starts from {encoder})' if encoder else ''}")
    summary = run_levels(progress_of(levels_config(config, uri, kind, encoder)), models)
    print(summary.paths["summary_md"].read_text())
    print("plots:", ", ".join(str(p) for k, p in summary.paths.items() if str(p).endswith(".png")))
    return summary


def _evaluate_pixel(config: DemoConfig, trained: dict):
    """The pixel decoder's levels, from the level's starts and from the encoder's guess ("+enc"), then what they are:
    how the decoder was trained, its floor (the levels' floor row: started at the truth) and the README's recipe.
    → the loaded decoder."""
    from bodyschema.evaluation.core.specs import resolve_models

    uri = _version_uri(trained["pixel"])
    decoder = resolve_models((uri,), (), config.tracking_uri)
    summary = _evaluate(config, uri, "pixel", decoder, _version_uri(trained["encoder"]))
    print(_models_section(config, trained, summary.floor["joint_err_deg"]))
    return decoder[0]


def _models_section(config: DemoConfig, trained: dict, floor: float) -> str:
    """The report's "models" section (results/models: summary.md, models.csv): each trained model's samples, epochs,
    fit seconds and held-out error, and what the pixel decoder is. → that note on the pixel decoder."""
    from bodyschema.evaluation.core.tables import markdown_table, write_csv
    from bodyschema.training.registry import use_tracking

    client = use_tracking(config.tracking_uri)
    rows = {kind: {"model": f"{r.registered_name} v{r.model_version}",
                   "train_samples": int(client.get_run(r.run_id).data.params["n_train"]),
                   **({"epochs": len(_history(r))} if kind != "gpr" else {}),      # a GP has no epochs
                   "fit_s": r.metrics["fit_seconds"], "val_rmse": r.metrics["val_rmse"],
                   **({"floor_deg": floor} if kind == "pixel" else {})} for kind, r in trained.items()}
    pixel = rows["pixel"]
    note = (f"The pixel decoder: {pixel['epochs']} epochs on {pixel['train_samples']} images in {pixel['fit_s']:.0f} s "
            f"of fitting. Its floor, perception started at the true pose of its levels' targets: {floor:.2f}° mean "
            f"joint error (where F's own minimum lies: the levels land there at best); the +enc rows start from the "
            f"{rows['encoder']['epochs']}-epoch encoder's guess. More images and epochs lower the floor: {RECIPE}.")
    folder = config.out / "results" / "models"
    folder.mkdir(parents=True, exist_ok=True)
    write_csv(list(rows.values()), folder / "models.csv")
    table = markdown_table(list(rows.values()), ("train_samples", "epochs", "fit_s", "val_rmse", "floor_deg"), "model")
    (folder / "summary.md").write_text(f"# The demo's models\n\n{table}\n{note}\n")
    return note


def _history(result) -> list[str]:
    """The per-epoch lines of a network's fit (its run folder's history.jsonl)."""
    return (result.run_dir / "history.jsonl").read_text().splitlines()


def _track(config: DemoConfig, decoder, encoder_uri: str) -> None:
    from bodyschema.evaluation.tracking import run_tracking

    spec = decoder.provenance["spec"]
    logger.info(f"== tracking: {config.streams} babbling streams of {config.stream_seconds:g} s at 30 Hz, followed "
                f"frame by frame from the camera image ({spec} + {encoder_uri}): the encoder alone, a same-budget "
                "gradient flow and the tracker")
    paths = run_tracking(progress_of(tracking_config(config, spec, encoder_uri)), [decoder])
    print(paths["summary_md"].read_text())
    print(f"plot: {paths.get('error_vs_time', '(none)')}")


def _act(config: DemoConfig, gpr_uri: str) -> None:
    from bodyschema.evaluation.reaching import run_reaching
    from bodyschema.evaluation.self_recognition import run_self_recognition

    reaching, panda, recognition = act_configs(config, gpr_uri)
    logger.info(f"== closed-loop reaching on nao_arm: {config.reach_targets} ee_xyz goals, {gpr_uri} + joint "
                "encoder")
    print(run_reaching(progress_of(reaching))["summary_md"].read_text())
    logger.info("== reaching on the 7-DOF torque panda: 10 ee_xyz goals in 3 s, the velocity controller on the joint "
                "impedance servo vs PD on the true inverse kinematics (analytic models)")
    print(run_reaching(progress_of(panda))["summary_md"].read_text())
    logger.info(f"== self-recognition: {config.episodes} babbling episodes per condition, is the ee stream mine "
                f"or an imitator's? ({gpr_uri})")
    print(run_self_recognition(progress_of(recognition))["summary_md"].read_text())


def _report(config: DemoConfig) -> None:
    from bodyschema.evaluation.report import ReportConfig, write_report
    from bodyschema.training.registry import list_models

    logger.info("== registry")
    for row in list_models(tracking=config.tracking_uri):
        print(f"  {row}")
    report = write_report(ReportConfig(results=config.out / "results", trained=config.out / "runs"))
    print(f"report: {report['html']} (and {report['markdown'].name})")


def _body_and_agency(config: DemoConfig, gpr_uri: str) -> None:
    from bodyschema.evaluation.agency import run_agency
    from bodyschema.evaluation.rubber_hand import run_rubber_hand

    rubber, agency = body_and_agency_configs(config, gpr_uri)
    logger.info(f"== rubber hand: a seen hand 5–10 cm away, stroked in and out of sync; drift of the belief "
                f"({gpr_uri})")
    print(run_rubber_hand(progress_of(rubber))["summary"].read_text())
    logger.info(f"== did I do it? own movements vs the same movements pushed or seen in a moved scene "
                f"({gpr_uri})")
    print(run_agency(progress_of(agency))["summary"].read_text())
