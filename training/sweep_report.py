"""After the trials of `bodyschema sweep`: each trial's row, the children's final status, the parent's table of trials,
and the registration of the best finished trial (`register_version`: `@champion` moves only if it is better)."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mlflow

from bodyschema.errors import must_be
from bodyschema.training.champion import register_version
from bodyschema.training.digest import DIGEST_TAG
from bodyschema.training.registry import METRIC, registered_name
from bodyschema.training.sweep_trial import EPOCH, FINAL
from bodyschema.training.train import Registered

STATUS_TAG = "bodyschema.sweep.status"
_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrialRow:
    hyper: dict[str, Any]            # the swept values of this trial
    status: str                      # finished | stopped early (ASHA) | failed: <error>
    epochs: int | None               # epochs reported (networks)
    val_rmse: float | None           # held-out RMSE in output units; None unless finished
    child_run_id: str | None
    metrics: dict[str, Any]          # the trial's last report (model_uri, digest, dataset digests …)


@dataclass(frozen=True)
class SweepResult:
    parent_run_id: str
    trials: tuple[TrialRow, ...]
    registered: Registered | None    # the best trial's version (None with --no-register)
    sweep_dir: Path
    cost: Any                        # the estimate printed before the start (sweep_probe.Cost)

    def __str__(self) -> str:
        lines = [f"MLflow parent run {self.parent_run_id} (sweep folder {self.sweep_dir})", markdown(self.trials)]
        r = self.registered
        if r is not None:
            lines.append(f"registered models:/{r.name}/{r.version}" + ("  → now @champion" if r.champion else
                                                                        "  (champion unchanged: not better)"))
        return "\n".join(lines)


def trial_rows(client, results, space) -> list[TrialRow]:
    """One row per Tune result; a child run left RUNNING by an early stop or a failure is ended with its status."""
    rows = []
    for result in results:
        metrics = dict(result.metrics or {})
        child = metrics.get("child_run_id")
        if result.error is not None:
            status = f"failed: {type(result.error).__name__}"
        elif FINAL in metrics:
            status = "finished"
        else:
            status = "stopped early (ASHA)"
        if child:
            _end_child(client, child, status)
        hyper = {d.name: (result.config or {}).get(d.name) for d in space.dimensions}
        rows.append(TrialRow(hyper, status, metrics.get(EPOCH), metrics.get(FINAL), child, metrics))
    return sorted(rows, key=lambda r: (r.val_rmse is None, r.val_rmse or 0.0))


def _end_child(client, child: str, status: str) -> None:
    """The child's MLflow status from the trial's fate (a stopped trial's process was ended by Tune mid-run)."""
    wanted = "FINISHED" if status == "finished" else "FAILED" if status.startswith("failed") else "KILLED"
    if client.get_run(child).info.status != wanted:
        client.set_terminated(child, wanted)
    client.set_tag(child, STATUS_TAG, status)


def log_table(rows: list[TrialRow]) -> None:
    """The parent's table of trials (MLflow's table artifact, and Markdown), and its best val_rmse."""
    columns = [*rows[0].hyper, "status", "epochs", METRIC, "child_run_id"] if rows else []
    table = {c: [_cell(r, c) for r in rows] for c in columns}
    mlflow.log_table(table, artifact_file="trials.json")
    mlflow.log_text(markdown(rows), "trials.md")
    finished = [r.val_rmse for r in rows if r.val_rmse is not None]
    mlflow.log_metrics({"trials_finished": len(finished), "trials": len(rows),
                        **({"best_val_rmse": min(finished)} if finished else {})})


def register_best(client, rows: list[TrialRow], kind: str, modality: str) -> Registered:
    """Register the finished trial with the lowest val_rmse; `@champion` moves only if it beats the current one."""
    finished = [r for r in rows if r.val_rmse is not None and math.isfinite(r.val_rmse)]
    if not finished:
        raise ValueError(must_be("the sweep", "at least one trial run to its end with a finite val_rmse",
                                 sorted({r.status for r in rows}), "Nothing was registered; see the child runs."))
    best = finished[0]
    m = best.metrics
    name = registered_name(m["robot"], modality, kind)
    tags = {DIGEST_TAG: m["digest"], METRIC: repr(best.val_rmse), "robot": m["robot"], "modality": modality,
            "kind": kind, "joint_names": m["joint_names"], "dataset_sha256": m["dataset_sha256"],
            "mjcf_sha256": m["mjcf_sha256"], **{k: m[k] for k in ("val_sha256", "dataset") if k in m}}
    version, champion = register_version(client, name, m["model_uri"], tags, best.val_rmse)
    client.set_tag(best.child_run_id, "bodyschema.champion", name if champion else "none")
    mlflow.set_tags({"best_child_run_id": best.child_run_id, "registered": f"{name}/{version}",
                     "bodyschema.champion": name if champion else "none"})
    _log.debug("registered %s v%s (%s=%.4g): %s", name, version, METRIC, best.val_rmse,
               "now @champion" if champion else "champion unchanged")
    return Registered(modality, name, version, champion, m["digest"])


def markdown(rows) -> str:
    if not rows:
        return "(no trials)"
    columns = [*rows[0].hyper, "status", "epochs", METRIC]
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(str(_cell(r, c)) for c in columns) + " |" for r in rows]
    return "\n".join(lines)


def _cell(row: TrialRow, column: str):
    if column in row.hyper:
        value = row.hyper[column]
        return "x".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value)
    if column == METRIC:
        return "" if row.val_rmse is None else f"{row.val_rmse:.4g}"
    return {"status": row.status, "epochs": "" if row.epochs is None else row.epochs,
            "child_run_id": row.child_run_id or ""}[column]
