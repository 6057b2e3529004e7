"""Training plots (PNG, logged to MLflow): loss curves, predicted-vs-target scatter, image target/prediction grid."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")   # files only, no display; set before pyplot is imported
import matplotlib.pyplot as plt  # noqa: E402 — pyplot after matplotlib.use, so no display backend is tried
import numpy as np  # noqa: E402 — in the same block as pyplot


def loss_curves(history: dict[int, dict[str, float]], path: Path, title: str) -> Path | None:
    """One curve per loss metric over epochs (GP: marginal-likelihood evaluations), log scale when all positive.
    None when nothing to plot."""
    lines = curves(history)
    if not lines:
        return None
    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    positive = True
    for key, pts in lines.items():
        ax.plot(*zip(*pts), label=key, marker="." if len(pts) < 30 else None)
        positive &= all(v > 0 for _, v in pts)
    # log: losses span decades; symlog where some are ≤ 0 (a GP's −MLL), which also keeps an L-BFGS line-search
    # probe of 1e6 from flattening the rest of the curve
    ax.set_yscale("log") if positive else ax.set_yscale("symlog", linthresh=1.0)
    gp = any("mll" in key for key in lines)
    ax.set(xlabel="marginal-likelihood evaluation" if gp else "epoch", ylabel="loss / metric", title=title)
    ax.grid(alpha=0.3)
    ax.legend()
    return save_figure(fig, path)


def curves(history: dict[int, dict[str, float]]) -> dict[str, list[tuple[int, float]]]:
    """{metric: [(epoch, finite value)]} of the metrics worth a curve: losses (NN), the negative marginal
    log-likelihood (GP: `train_neg_mll`, one value per evaluation) and validation scores."""
    keys = sorted({k for m in history.values() for k in m if "loss" in k or "mll" in k or k.startswith("val_")})
    out = {key: [(e, history[e][key]) for e in sorted(history) if key in history[e] and np.isfinite(history[e][key])]
           for key in keys}
    return {key: pts for key, pts in out.items() if pts}


def prediction_scatter(target: np.ndarray, pred: np.ndarray, path: Path, unit: str, title: str) -> Path:
    """Validation predictions against targets, one panel per output dimension (perfect: the diagonal)."""
    target, pred = target.reshape(len(target), -1), pred.reshape(len(pred), -1)   # (N, O)
    n_out = target.shape[1]
    cols = min(n_out, 4)
    rows = -(-n_out // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3 * cols, 3 * rows), dpi=100, squeeze=False)
    for i, ax in enumerate(axes.flat):
        if i >= n_out:
            ax.axis("off")
            continue
        ax.scatter(target[:, i], pred[:, i], s=3, alpha=0.5)
        lo, hi = float(min(target[:, i].min(), pred[:, i].min())), float(max(target[:, i].max(), pred[:, i].max()))
        ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
        ax.set(xlabel=f"target [{unit}]", ylabel=f"predicted [{unit}]", title=f"output {i}")
    fig.suptitle(title)
    return save_figure(fig, path)


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
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
