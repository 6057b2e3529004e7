"""ROC analysis and report of the self-recognition benchmark: rank AUC, ROC curve, best threshold, tables, plots.

"Is this me?" is `score ≤ threshold` (a low free energy: the visual stream is explained by my own body), so the
positives are the self episodes: TPR = P(self score ≤ th), FPR = P(other score ≤ th). The AUC is
P(other score > self score) + ½ P(tie), the Mann–Whitney U statistic over n_self · n_other (Hanley & McNeil
1982), computed from average ranks (no scikit-learn needed).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from bodyschema.evaluation.core.tables import markdown_table, write_csv
from bodyschema.evaluation.self_recognition.streams import SELF

TABLE_COLUMNS = ("others", "auc", "threshold", "tpr", "fpr", "fpr_at_pooled", "t_auc99_s", "median_self",
                 "median_other", "failed")


def average_ranks(values: np.ndarray) -> np.ndarray:
    """1-based ranks, ties sharing their average rank (as scipy.stats.rankdata). (N,) → (N,)"""
    unique, inverse, counts = np.unique(values, return_inverse=True, return_counts=True)
    first = np.cumsum(counts) - counts                                     # rank − 1 of each value's first copy
    return (first + (counts + 1) / 2.0)[inverse]


def auc(self_scores: np.ndarray, other_scores: np.ndarray) -> float:
    """P(other > self) + ½ P(other = self) from ranks: separating low self scores from high other scores → 1."""
    s, o = np.asarray(self_scores, float), np.asarray(other_scores, float)
    if s.size == 0 or o.size == 0:
        return float("nan")
    ranks = average_ranks(np.concatenate([s, o]))
    u_other = ranks[s.size:].sum() - o.size * (o.size + 1) / 2.0           # pairs (self, other) with other > self
    return float(u_other / (s.size * o.size))


def roc_curve(self_scores: np.ndarray, other_scores: np.ndarray) -> dict[str, np.ndarray]:
    """FPR, TPR of `score ≤ threshold` at every distinct score (and −inf: nothing is me). Each (K,)."""
    s, o = np.sort(np.asarray(self_scores, float)), np.sort(np.asarray(other_scores, float))
    thresholds = np.concatenate([[-np.inf], np.unique(np.concatenate([s, o]))])
    tpr = np.searchsorted(s, thresholds, side="right") / max(s.size, 1)
    fpr = np.searchsorted(o, thresholds, side="right") / max(o.size, 1)
    return {"threshold": thresholds, "tpr": tpr, "fpr": fpr}


def best_threshold(roc: Mapping[str, np.ndarray]) -> dict[str, float]:
    """The threshold maximising Youden's J = TPR − FPR, with its TPR and FPR."""
    i = int(np.argmax(roc["tpr"] - roc["fpr"]))
    return {"threshold": float(roc["threshold"][i]), "tpr": float(roc["tpr"][i]), "fpr": float(roc["fpr"][i])}


def roc_table(kinds: np.ndarray, per_frame: np.ndarray, failed: np.ndarray, sources: Sequence[str],
              period: float) -> tuple[list, dict, dict]:
    """Self vs others (pooled, then each source) over the episodes that did not fail, scored by the time-average of
    per_frame (N, T). Returns (one row per comparison, ROC curves, AUC over viewing time) by comparison name."""
    ok = ~failed
    scores = np.full(len(kinds), np.nan)
    scores[ok] = per_frame[ok].mean(axis=1)
    s = scores[ok & (kinds == SELF)]
    groups = {"pooled": ok & (kinds != SELF), **{k: ok & (kinds == k) for k in sources}}
    over_time = auc_over_time(kinds, per_frame, failed, groups)
    rows, curves, pooled_threshold = [], {}, None
    for name, mask in groups.items():
        o = scores[mask]
        roc = curves[name] = roc_curve(s, o)
        best = best_threshold(roc)
        pooled_threshold = best["threshold"] if pooled_threshold is None else pooled_threshold
        every = (kinds != SELF) if name == "pooled" else (kinds == name)
        rows.append({"comparison": name, "self": int(s.size), "others": int(o.size), "auc": auc(s, o), **best,
                     "fpr_at_pooled": float((o <= pooled_threshold).mean()) if o.size else float("nan"),
                     "t_auc99_s": time_to_auc(over_time[name], period),
                     "median_self": float(np.median(s)) if s.size else float("nan"),
                     "median_other": float(np.median(o)) if o.size else float("nan"),
                     "failed": int((failed & every).sum())})
    return rows, curves, over_time


def auc_over_time(kinds: np.ndarray, per_frame: np.ndarray, failed: np.ndarray,
                  groups: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """AUC of the running mean of F after each frame (how long must the robot watch?), per group mask (N,) of
    others. Each (T,)."""
    running = np.cumsum(per_frame, axis=1) / np.arange(1, per_frame.shape[1] + 1)    # (N, T)
    s = running[~failed & (kinds == SELF)]
    return {name: np.array([auc(s[:, j], running[mask, j]) for j in range(running.shape[1])])
            for name, mask in groups.items()}


def time_to_auc(curve: np.ndarray, period: float, level: float = 0.99) -> float:
    """Viewing time (s) from which the AUC stays ≥ level; NaN when it does not end there."""
    below = np.flatnonzero(~(curve >= level))
    if curve.size == 0 or (below.size and below[-1] == curve.size - 1):
        return float("nan")
    return float((below[-1] + 2 if below.size else 1) * period)


def markdown(rows: Sequence[Mapping], notes: Sequence[str]) -> str:
    """The summary table (self vs each kind of other) and a few lines of what was measured."""
    return markdown_table(rows, TABLE_COLUMNS, "comparison") + "\n" + "\n".join(notes) + "\n"


def summary_notes(config, robot: str, visual: Sequence[str], period: float, rows: Sequence[Mapping], scores,
                  wall: float) -> list[str]:
    """The lines under the summary table: what was measured, the decision rule, failures and time."""
    pooled = rows[0]
    failures = sorted({r for r in scores.reason if r})
    failed = f"{int(scores.failed.sum())}" + (f" ({'; '.join(failures[:5])})" if failures else "")
    return [f"Self-recognition on {robot} seen through {', '.join(visual)}: {config.trials} babbling episodes of "
            f"{config.steps} frames every {period:g} s, half from the robot's own body, half from "
            f"{', '.join(config.sources)} (delay {config.delay:g} s); noise σ: joints {config.proprio_noise:.4g} rad, "
            f"visual {({m: s for m, s in config.visual_noise if m in visual})}.",
            f"Score: time-averaged {config.score} free energy after ≤ {config.perception.max_steps} perception "
            f"updates per frame; 'is this me?' = score ≤ {pooled['threshold']:.4g} (best pooled threshold, Youden's "
            f"J): TPR {pooled['tpr']:.3f} at FPR {pooled['fpr']:.3f}, pooled AUC {pooled['auc']:.4f}; t_auc99_s: "
            "viewing time from which the AUC stays ≥ 0.99.",
            f"Failed episodes: {failed}; wall time {wall:.1f} s."]


# ---- plots ---------------------------------------------------------------------------------------------
def plot_roc(curves: Mapping[str, Mapping[str, np.ndarray]], rows: Sequence[Mapping], path: Path) -> Path:
    from bodyschema.evaluation.core.plots import plt, save_figure   # matplotlib only when plotting
    fig, ax = plt.subplots(figsize=(4.6, 4.4))
    aucs = {r["comparison"]: r["auc"] for r in rows}
    for name, roc in curves.items():
        ax.step(roc["fpr"], roc["tpr"], where="post", lw=2.2 if name == "pooled" else 1.2,
                label=f"{name} (AUC {aucs[name]:.3f})")
    ax.plot([0, 1], [0, 1], color="grey", ls=":", lw=0.8)
    ax.set_xlabel("FPR: others taken for me")
    ax.set_ylabel("TPR: me recognised")
    ax.set_title("is this me? score ≤ threshold")
    ax.legend(loc="lower right", fontsize=8)
    return save_figure(fig, path, dpi=120)


def plot_auc_over_time(over_time: Mapping[str, np.ndarray], period: float, path: Path) -> Path:
    from bodyschema.evaluation.core.plots import plt, save_figure
    fig, ax = plt.subplots(figsize=(5.4, 3.8))
    for name, curve in over_time.items():
        ax.plot((np.arange(curve.size) + 1) * period, curve, lw=2.2 if name == "pooled" else 1.2, label=name)
    ax.axhline(0.99, color="grey", ls=":", lw=0.8)
    ax.set_xlabel("viewing time (s)")
    ax.set_ylabel("AUC of the running mean of F")
    ax.legend(loc="lower right", fontsize=8)
    return save_figure(fig, path, dpi=120)


def plot_histogram(kinds: np.ndarray, scores: np.ndarray, failed: np.ndarray, threshold: float, path: Path) -> Path:
    """Score histograms per kind on a log axis (free energies span decades), with the pooled best threshold."""
    from bodyschema.evaluation.core.plots import plt, save_figure
    fig, ax = plt.subplots(figsize=(6, 3.8))
    ok = ~failed & np.isfinite(scores)
    positive = np.maximum(scores[ok], 1e-12)
    if positive.size:
        bins = np.geomspace(positive.min(), max(positive.max(), positive.min() * 1.01), 40)
        for kind in dict.fromkeys(kinds):
            values = np.maximum(scores[ok & (kinds == kind)], 1e-12)
            ax.hist(values, bins=bins, alpha=0.5, label=f"{kind} ({values.size})")
        ax.set_xscale("log")
    if np.isfinite(threshold):
        ax.axvline(threshold, color="k", ls="--", lw=1, label="best pooled threshold")
    ax.set_xlabel("score: time-averaged free energy")
    ax.set_ylabel("episodes")
    ax.legend(fontsize=8)
    return save_figure(fig, path, dpi=120)


def plot_over_time(kinds: np.ndarray, per_frame: np.ndarray, period: float, path: Path, per_kind: int = 3) -> Path:
    """F(t) of the first `per_kind` episodes of each kind. per_frame (N, T), NaN where an episode failed."""
    from bodyschema.evaluation.core.plots import plt, save_figure
    fig, ax = plt.subplots(figsize=(6.4, 4))
    t = np.arange(per_frame.shape[1]) * period
    for c, kind in enumerate(dict.fromkeys(kinds)):
        for j, i in enumerate(np.flatnonzero(kinds == kind)[:per_kind]):
            ax.plot(t, np.maximum(per_frame[i], 1e-12), color=f"C{c}", lw=1, alpha=0.8,
                    label=kind if j == 0 else None)
    ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("free energy per frame")
    ax.legend(fontsize=8)
    return save_figure(fig, path, dpi=120)


def write_report(out: Path, episodes_rows: Sequence[Mapping], rows: Sequence[Mapping], curves, over_time,
                 notes: Sequence[str], kinds: np.ndarray, failed: np.ndarray, per_frame: np.ndarray, period: float,
                 plots: bool = True) -> dict[str, Path]:
    """summary.md, summary.csv, episodes.csv and (with `plots`) roc.png, auc_over_time.png, scores.png and
    free_energy.png in `out`."""
    out.mkdir(parents=True, exist_ok=True)
    paths = {"summary_csv": write_csv(rows, out / "summary.csv"),
             "episodes_csv": write_csv(episodes_rows, out / "episodes.csv"),
             "summary_md": out / "summary.md"}
    paths["summary_md"].write_text(markdown(rows, notes))
    if plots:
        paths["roc"] = plot_roc(curves, rows, out / "roc.png")
        paths["auc_over_time"] = plot_auc_over_time(over_time, period, out / "auc_over_time.png")
        scores = np.where(failed, np.nan, per_frame.mean(axis=1))
        paths["scores"] = plot_histogram(kinds, scores, failed, rows[0]["threshold"], out / "scores.png")
        paths["free_energy"] = plot_over_time(kinds, per_frame, period, out / "free_energy.png")
    return paths
