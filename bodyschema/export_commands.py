"""The `bodyschema export dataset|onnx` and `bodyschema show` commands: their configs and what each runs.

    bodyschema show data/nao.zarr                                     summary + data/nao_contact_sheet.png
    bodyschema export dataset --to hdf5 data/nao.zarr data/nao.h5
    bodyschema export dataset --to lerobot data/nao.zarr data/nao_lerobot
    bodyschema export onnx models:/bodyschema-nao_arm-ee_xyz-gpr@champion gpr.onnx
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from bodyschema.cli_marks import Positional


@dataclass(frozen=True)
class ShowArgs:
    """Summarize a dataset store and draw a contact sheet of its images (PNG) with the stored ee_pixel on each."""

    path: Annotated[Path, Positional("STORE")]   # the .zarr store
    out: Path | None = None            # the PNG; None: <store name>_contact_sheet.png beside the store
    n: int = 16                        # images on the sheet, evenly spread over the store


@dataclass(frozen=True)
class ExportDatasetArgs:
    """Write a dataset store as HDF5 (one file) or in LeRobot's v3.0 dataset layout (a directory)."""

    to: Literal["hdf5", "lerobot"]     # the format
    store: Annotated[Path, Positional("STORE")]   # the .zarr store (it must validate)
    out: Annotated[Path, Positional("OUT")]   # .h5 file (hdf5), a directory (lerobot)
    overwrite: bool = False            # replace OUT if it is a previous export in this format (never anything else)


@dataclass(frozen=True)
class ExportOnnxArgs:
    """Export a fitted model to ONNX: joint angles in rad in, its prediction out (scaling inside), checked with
    onnxruntime against the model before it is written."""

    model: Annotated[str, Positional("MODEL_SPEC")]
    """models:/<name>@<alias>, a `bodyschema train` run or model directory, or trusted:<dir>"""
    out: Annotated[Path, Positional("OUT")]   # the .onnx file
    opset: int = 18                    # ONNX opset, in the installed exporter's range (the file's is in its metadata)
    tracking_uri: str | None = None    # None: $MLFLOW_TRACKING_URI, else sqlite:///<cwd>/mlflow.db
    overwrite: bool = False            # replace OUT if it is a previous ONNX export (never anything else)


def run_show(args: ShowArgs) -> int:
    from bodyschema.datagen.store.show import show_store

    shown = show_store(args.path, args.out, args.n)
    print(shown.summary)
    if shown.sheet is not None:
        print(f"contact sheet: {shown.sheet}")
    else:
        logging.getLogger(__name__).warning(shown.note)
    return 0


def run_export_dataset(args: ExportDatasetArgs) -> int:
    from bodyschema.datagen.exchange.export import export_dataset

    print(f"{args.to}: {export_dataset(args.store, args.out, args.to, overwrite=args.overwrite)}")
    return 0


def run_export_onnx(args: ExportOnnxArgs) -> int:
    from bodyschema.base.outputs import check_out
    from bodyschema.models.onnx_export import FORMAT, check_opset, export_onnx, read_metadata

    check_opset(args.opset)                            # both before loading the model: a bad flag fails at once
    check_out(args.out, FORMAT, args.overwrite)
    path = export_onnx(_load(args.model, args.tracking_uri), args.out, opset=args.opset, overwrite=args.overwrite)
    meta = read_metadata(path)
    print(f"onnx: {path} (opset {meta['opset']}, {meta['bodyschema.dtype']})\n"
          f"  in:  {meta['bodyschema.input']}\n  out: {meta['bodyschema.output']}\n  {meta['bodyschema.check']}")
    return 0


def _load(spec: str, tracking_uri: str | None):
    """The model a spec names (the evaluation core's resolution: registry, logged directory or trusted:<dir>); a
    `bodyschema train` run directory stands for the model directory it saved."""
    from bodyschema.evaluation.core.specs import resolve_model

    spec = model_dir_of_run(spec)
    if spec.startswith("models:/") or (not spec.startswith(("trusted:", "analytic:")) and Path(spec).is_dir()):
        from bodyschema.training.registry import check_tracking, tracking_uri as resolve_uri

        uri = resolve_uri(tracking_uri)      # the registry or the digests of logged directories live there
        from bodyschema.log import tracking_line

        tracking_line(uri)
        check_tracking(uri, timeout_s=5)
    return resolve_model(spec, tracking_uri)


def model_dir_of_run(spec: str) -> str:
    """runs/<kind>-<modality>-<hash> → its model/ (model-<modality>/ for a multimodal run: named, one per export)."""
    prefix = "trusted:" if spec.startswith("trusted:") else ""
    folder = Path(spec.removeprefix(prefix))
    if not folder.is_dir() or (folder / "meta.json").is_file() or spec.startswith(("models:/", "analytic:")):
        return spec
    saved = sorted(p.parent for p in folder.glob("model*/meta.json"))
    if len(saved) == 1:
        return prefix + str(saved[0])
    if len(saved) > 1:
        from bodyschema.errors import must_be

        raise ValueError(must_be("MODEL", "one model", f"run directory {str(folder)!r} with {len(saved)} models",
                                 "Name one: " + ", ".join(prefix + str(p) for p in saved) + "."))
    return spec
