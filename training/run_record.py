"""What a training run records in MLflow besides its model and scores: its inputs (params: the run identity; tags:
robot, MJCF, library versions; the dataset as an MLflow input), the per-epoch history (`history.jsonl` in the run
directory, so a resumed run's curves include the epochs before a kill), and the files logged beside the plots
(`dataset_summary.txt`, `loss_curves.csv`).
"""

from __future__ import annotations

import importlib.metadata
import json
import platform
import warnings
from pathlib import Path

import mlflow
from mlflow.data.dataset_source_registry import resolve_dataset_source
from mlflow.data.meta_dataset import MetaDataset

from bodyschema.training.config import NON_IDENTITY_FIELDS, TrainConfig
from bodyschema.training.data import Dataset

LIBRARIES = ("bodyschema", "torch", "numpy", "mlflow", "zarr", "gpytorch", "scikit-learn", "mujoco")


def log_run_files(data: Dataset, history: "History", run_dir: Path) -> None:
    """The dataset summary (`dataset_summary.txt`, as `bodyschema show` prints it) and the loss curves' numbers
    (`loss_curves.csv`: one row per epoch, beside plots/loss_curves.png) as artifacts of the run."""
    from bodyschema.datagen.store.validate import summarize_store

    mlflow.log_text(summarize_store(data.path, check=False) + "\n", "dataset_summary.txt")
    if history.epochs:
        keys = sorted({k for row in history.epochs.values() for k in row})
        rows = [",".join(["epoch", *keys])]
        for epoch in sorted(history.epochs):
            row = history.epochs[epoch]
            rows.append(",".join([str(epoch), *(repr(row[k]) if k in row else "" for k in keys)]))
        mlflow.log_text("\n".join(rows) + "\n", "loss_curves.csv")


def log_inputs(config: TrainConfig, data: Dataset, run_name: str) -> dict:
    """Params (the run identity), tags (robot, MJCF, versions), and the dataset as an MLflow input. → the params"""
    identity = config.identity(data.sha256)
    params = {k: v for k, v in identity.items() if k not in ("hyper", "dataset_sha256")}
    params.update({f"hyper.{k}": v for k, v in identity["hyper"].items()})
    params.update(data=str(Path(data.path).resolve()), n_train=len(data.train), n_val=len(data.val),
                  split_by=data.split_by, output_shape={m: list(data.output_shape(m)) for m in data.modalities},
                  joint_names=",".join(data.body.joint_names))
    mlflow.log_params({k: str(v) for k, v in params.items()})
    tags = {"robot": data.body.robot, "mjcf_sha256": str(data.attrs.get("mjcf_sha256", "")),
            "dataset_sha256": data.sha256, "modality": config.modality, "kind": config.kind,
            "config_hash": run_name.rsplit("-", 1)[-1], "python": platform.python_version(),
            **{f"config.{k}": str(getattr(config, k)) for k in NON_IDENTITY_FIELDS}}
    for lib in LIBRARIES:
        try:
            tags[f"version.{lib}"] = importlib.metadata.version(lib)
        except importlib.metadata.PackageNotFoundError:
            pass
    mlflow.set_tags(tags)
    with warnings.catch_warnings():   # "can be interpreted in multiple ways": both are the local-file source
        warnings.filterwarnings("ignore", message=".*interpreted in multiple ways.*", category=UserWarning)
        source = resolve_dataset_source(str(Path(data.path).resolve()))
    dataset = MetaDataset(source, name=Path(data.path).name, digest=data.sha256[:32])
    mlflow.log_input(dataset, context="training", tags={"robot": tags["robot"], "mjcf_sha256": tags["mjcf_sha256"],
                                                         "modality": config.modality})
    return params


class History:
    """Per-epoch metrics, appended to a JSONL file so a resumed run's curves include the epochs before the kill."""

    def __init__(self, path: Path):
        self.path, self.epochs = path, {}
        if path.is_file():
            for line in path.read_text().splitlines():
                row = json.loads(line)
                self.epochs[int(row["epoch"])] = row["metrics"]

    def add(self, epoch: int, metrics: dict[str, float]) -> None:
        self.epochs[int(epoch)] = {k: float(v) for k, v in metrics.items()}
        with self.path.open("a") as f:
            f.write(json.dumps({"epoch": int(epoch), "metrics": self.epochs[int(epoch)]}) + "\n")

    def last(self) -> dict[str, float]:
        return self.epochs[max(self.epochs)] if self.epochs else {}
