"""Training plots (PNG, logged to MLflow): loss curves, predicted-vs-target scatter, image target/prediction grid.

Each plot is built by a `*_figure` function (a matplotlib Figure a test can inspect: titles, axis labels, legends)
and written by its namesake, which saves and closes it. Titles say what was trained: `run_title(kind, modality,
robot)`; axes carry units; scatter panels are named after the modality's components (x/y/z, u/v, joint names).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")   # files only, no display; set before pyplot is imported
import matplotlib.pyplot as plt  # noqa: E402 — pyplot after matplotlib.use, so no display backend is tried
import numpy as np  # noqa: E402 — in the same block as pyplot

from bodyschema.base import modalities  # noqa: E402 — the component names and units of each modality

# What each logged history metric is (a multimodal member's metrics carry its modality as a "m/" prefix).
OBJECTIVES = {
    "train_neg_mll": "−log marginal likelihood",      # gpr: per training point, summed over outputs (nats)
    "train_neg_lml": "−log marginal likelihood",      # sklearn-gpr: of the whole hyper-parameter subset (nats)
    "train_loss": "training loss",
    "val_loss": "validation loss",
}
HELD_OUT = {"val_rmse": "RMSE over output elements", "val_mean_error": "mean Euclidean error per sample"}
OBJECTIVE_UNITS = {"train_neg_mll": "nats per training point", "train_neg_lml": "nats"}
OUTLIER_SPAN = 1.0    # an objective value beyond the bulk's 5–95 % range by more than this many ranges is clipped


def run_title(kind: str, modality: str | Sequence[str], robot: str) -> str:
    """"gpr on ee_xyz, robot planar2": what a training plot shows, in its title (a run hash says nothing)."""
    names = modality if isinstance(modality, str) else "+".join(modality)
    return f"{kind} on {names}, robot {robot}"


def component_names(modality: str, n: int, joint_names: Sequence[str] = ()) -> tuple[str, ...]:
    """The names of a modality's `n` output components: x/y/z, u/v, the robot's joints; "output i" otherwise."""
    if modality in ("joints", "q"):                 # the table says only "joint": the body names them
        names = tuple(joint_names)
    else:
        row = modalities.find(modality)
        names = row.names if row is not None else ()
    return names if len(names) == n else tuple(f"output {i}" for i in range(n))


# ---- loss curves ------------------------------------------------------------------------------------------
def loss_curves(history: dict[int, dict[str, float]], path: Path, title: str, unit: str = "output units"
                ) -> Path | None:
    """The training objective and the held-out error (in `unit`) in separate panels; None when nothing to plot."""
    fig = loss_figure(history, title, unit)
    return None if fig is None else save_figure(fig, path)


def loss_figure(history: dict[int, dict[str, float]], title: str, unit: str = "output units"):
    """Left: the objective per step (GP: −log marginal likelihood per evaluation; networks: loss per epoch).
    Right: held-out errors in `unit` (one panel per unit when a multimodal run mixes units). None if empty."""
    lines = curves(history)
    objective = {k: pts for k, pts in lines.items() if _metric(k) in OBJECTIVES}
    errors = {k: pts for k, pts in lines.items() if _metric(k) in HELD_OUT}
    by_unit: dict[str, dict] = {}
    for key, pts in errors.items():
        by_unit.setdefault(_unit_of(key, unit), {})[key] = pts
    panels = ([objective] if objective else []) + list(by_unit.values())
    if not panels:
        return None
    widths = ([3] if objective else []) + [2] * len(by_unit)          # the curve wants the room
    fig, axes = plt.subplots(1, len(panels), figsize=(1.9 * sum(widths), 4), dpi=100, squeeze=False,
                             gridspec_kw={"width_ratios": widths})
    axes = list(axes.flat)
    if objective:
        _draw_objective(axes.pop(0), objective)
    for ax, (u, group) in zip(axes, by_unit.items()):
        _draw_held_out(ax, group, u)
    fig.suptitle(f"Training {title}")
    return fig


def curves(history: dict[int, dict[str, float]]) -> dict[str, list[tuple[int, float]]]:
    """{metric: [(step, finite value)]} of the metrics worth a curve: the objectives (`OBJECTIVES`: losses, a GP's
    −log marginal likelihood at every evaluation) and the held-out errors (`HELD_OUT`)."""
    keys = sorted({k for m in history.values() for k in m if _metric(k) in OBJECTIVES or _metric(k) in HELD_OUT})
    out = {key: [(e, history[e][key]) for e in sorted(history) if key in history[e] and np.isfinite(history[e][key])]
           for key in keys}
    return {key: pts for key, pts in out.items() if pts}


def _draw_objective(ax, lines: dict[str, list[tuple[int, float]]]) -> None:
    gp = any(_metric(k).startswith("train_neg_") for k in lines)
    values = np.array([v for pts in lines.values() for _, v in pts])
    for key, pts in lines.items():
        ax.plot(*zip(*pts), label=_label(key, OBJECTIVES), marker="." if len(pts) < 30 else None)
    if values.min() > 0 and values.max() > 10 * values.min():
        ax.set_yscale("log")                                   # network losses span decades
    else:
        _clip_outliers(ax, values)                             # a −MLL may be < 0: linear, line-search probes cut
    unit = next((OBJECTIVE_UNITS[_metric(k)] for k in lines if _metric(k) in OBJECTIVE_UNITS), "per sample")
    ax.set(xlabel="marginal-likelihood evaluation" if gp else "epoch",
           ylabel=f"{'−log marginal likelihood' if gp else 'loss'} ({unit})",
           title="GP hyper-parameter fit (lower is better)" if gp else "Training objective (lower is better)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def _clip_outliers(ax, values: np.ndarray) -> None:
    """Linear y limits around the bulk of the curve, so one L-BFGS line-search probe (say 1e6) does not flatten
    the rest; what is cut is said on the plot."""
    lo, q95 = np.percentile(values, [0, 95])
    top = q95 + OUTLIER_SPAN * max(q95 - lo, 1e-12)
    above = values > top
    if above.any():
        pad = 0.05 * (top - lo)
        ax.set_ylim(lo - pad, top + pad)
        ax.annotate(f"{above.sum()} value(s) above the axis (max {values.max():.3g})", (0.98, 0.97),
                    xycoords="axes fraction", ha="right", va="top", fontsize=8, color="0.3")


def _draw_held_out(ax, lines: dict[str, list[tuple[int, float]]], unit: str) -> None:
    """Errors logged once (a GP scores after its fit) are bars with their values; errors per epoch are curves."""
    if all(len(pts) == 1 for pts in lines.values()):
        labels, values = [_label(k, HELD_OUT) for k in lines], [pts[0][1] for pts in lines.values()]
        bars = ax.barh(labels, values, color=[f"C{i + 1}" for i in range(len(values))])
        ax.bar_label(bars, labels=[f"{v:.3g} {unit}" for v in values], padding=3, fontsize=8)
        ax.set_xlim(0, 1.35 * max(values) if max(values) > 0 else 1)
        ax.set(xlabel=f"error ({unit})", title="Held-out error after the fit")
        ax.tick_params(axis="y", labelsize=8)
        return
    for key, pts in lines.items():
        ax.plot(*zip(*pts), marker=".", label=_label(key, HELD_OUT))
    ax.set(xlabel="epoch", ylabel=f"error ({unit})", title="Held-out error", yscale="log")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def _metric(key: str) -> str:
    return key.split("/")[-1]


def _label(key: str, table: dict[str, str]) -> str:
    member = key.rsplit("/", 1)[0] + ": " if "/" in key else ""
    return member + table[_metric(key)]


def _unit_of(key: str, default: str) -> str:
    """A multimodal member's errors are in its modality's unit; a single model's in the caller's."""
    return modalities.unit(key.rsplit("/", 1)[0], default) if "/" in key else default


# ---- predictions ------------------------------------------------------------------------------------------
def prediction_scatter(target: np.ndarray, pred: np.ndarray, path: Path, unit: str, title: str,
                       names: Sequence[str] = ()) -> Path:
    """Held-out predictions against targets, one panel per output component (perfect: the diagonal)."""
    return save_figure(scatter_figure(target, pred, unit, title, names), path)


def scatter_figure(target: np.ndarray, pred: np.ndarray, unit: str, title: str, names: Sequence[str] = ()):
    """One panel per output component, titled by `names` (default "output i") with the component's RMSE."""
    target, pred = target.reshape(len(target), -1), pred.reshape(len(pred), -1)   # (N, O)
    n_out = target.shape[1]
    names = tuple(names) if len(names) == n_out else tuple(f"output {i}" for i in range(n_out))
    cols = min(n_out, 4)
    rows = -(-n_out // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.2 * rows), dpi=100, squeeze=False)
    for i, ax in enumerate(axes.flat):
        if i >= n_out:
            ax.axis("off")
            continue
        t, p = target[:, i], pred[:, i]                                                # (N,), (N,)
        ax.scatter(t, p, s=3, alpha=0.5)
        lo, hi = float(min(t.min(), p.min())), float(max(t.max(), p.max()))
        ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
        rmse = float(np.sqrt(np.mean((p - t) ** 2)))
        constant = " (constant target)" if np.ptp(t) == 0 else ""
        ax.set(xlabel=f"target {names[i]} ({unit})", ylabel=f"predicted {names[i]} ({unit})",
               title=f"{names[i]}: RMSE {rmse:.3g} {unit}{constant}")
        ax.title.set_fontsize(9)
    fig.suptitle(title)
    return fig


def image_grid(target: np.ndarray, pred: np.ndarray, path: Path, title: str, n: int = 8) -> Path:
    """Rows: target, prediction, |error| for the first `n` validation images (values in [0, 1])."""
    n = min(n, len(target))
    fig, axes = plt.subplots(3, n, figsize=(1.6 * n, 5), dpi=100, squeeze=False)
    for j in range(n):
        for row, (label, img) in enumerate((("target", target[j]), ("predicted", pred[j]),
                                            ("|error|", np.abs(pred[j] - target[j])))):
            ax = axes[row, j]
            ax.imshow(np.clip(img, 0, 1), cmap="gray" if img.ndim == 2 else None, vmin=0, vmax=1)
            ax.set_xticks([]), ax.set_yticks([])
            if j == 0:
                ax.set_ylabel(label)
    fig.suptitle(title)
    return save_figure(fig, path)


def save_figure(fig, path: Path, dpi: float | str = "figure") -> Path:
    """Lay out, write the PNG (creating its folder) and free the figure."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    # a tight bounding box: legends placed beside or below the panels (so they cover no curve) are never cut off
    fig.savefig(path, dpi=dpi, bbox_inches="tight", pad_inches=0.1)
    plt.close(fig)
    return path
