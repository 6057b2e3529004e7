"""ROC analysis and report of the self-recognition benchmark: AUC, ROC curve, best threshold, decision time, tables,
plots.

"Is this me?" is `score ≤ threshold` (a low free-energy score S: the visual stream is explained by my own body), so
the positives are the self episodes and scikit-learn's metrics see −S: TPR = P(self S ≤ th), FPR = P(other S ≤ th),
AUC = P(other S > self S) + ½ P(tie) (the Mann–Whitney U over n_self · n_other; Hanley & McNeil 1982). The best
threshold maximises Youden's J = TPR − FPR; its balanced accuracy is (1 + J)/2, and the time to a 95 % decision is
the viewing time from which that accuracy stays ≥ 0.95 (the threshold re-chosen at each viewing time).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from bodyschema.aif.perception_config import resolve
from bodyschema.evaluation.core.tables import markdown_table, write_csv
from bodyschema.evaluation.self_recognition.streams import SELF

TABLE_COLUMNS = ("delay_s", "others", "auc", "threshold", "tpr", "fpr", "t95_s", "t_auc95_s", "median_self",
                 "median_other", "failed")
SCORE_NAMES = {"contingency": "F(one body) − F(two bodies)", "visual": "visual free energy",
               "total": "free energy of all modalities"}
_START_NOTE = {"reading": "the joint readings", "previous": "the previous frame's belief"}
DECISION = 0.95                        # balanced accuracy of a "95 % decision"; also the AUC level of t_auc95_s


def _labelled(self_scores, other_scores) -> tuple[np.ndarray, np.ndarray]:
    """(y, −S): self episodes are the positives, a lower score says "me"."""
    s, o = np.asarray(self_scores, float), np.asarray(other_scores, float)
    return np.concatenate([np.ones(s.size), np.zeros(o.size)]), -np.concatenate([s, o])


def auc(self_scores: np.ndarray, other_scores: np.ndarray) -> float:
    """P(other > self) + ½ P(other = self): separating low self scores from high other scores → 1; NaN when a
    side is empty."""
    if np.size(self_scores) == 0 or np.size(other_scores) == 0:
        return float("nan")
    from sklearn.metrics import roc_auc_score  # seconds to import: only when scoring
    return float(roc_auc_score(*_labelled(self_scores, other_scores)))


def roc_curve(self_scores: np.ndarray, other_scores: np.ndarray) -> dict[str, np.ndarray]:
    """FPR, TPR of `score ≤ threshold` at every distinct score (and −inf: nothing is me). Each (K,)."""
    if np.size(self_scores) == 0 or np.size(other_scores) == 0:
        nan = np.array([np.nan])
        return {"threshold": nan, "tpr": nan, "fpr": nan}
    from sklearn import metrics
    fpr, tpr, minus = metrics.roc_curve(*_labelled(self_scores, other_scores), drop_intermediate=False)
    return {"threshold": -minus, "tpr": tpr, "fpr": fpr}       # −F ≥ th  ⇔  F ≤ −th


def best_threshold(roc: Mapping[str, np.ndarray]) -> dict[str, float]:
    """The threshold maximising Youden's J = TPR − FPR, with its TPR and FPR (NaN on an empty curve)."""
    j = roc["tpr"] - roc["fpr"]
    if not np.isfinite(j).any():
        return {"threshold": float("nan"), "tpr": float("nan"), "fpr": float("nan")}
    i = int(np.nanargmax(j))
    return {"threshold": float(roc["threshold"][i]), "tpr": float(roc["tpr"][i]), "fpr": float(roc["fpr"][i])}


def balanced_accuracy(self_scores: np.ndarray, other_scores: np.ndarray) -> float:
    """(TPR + 1 − FPR)/2 at the best threshold = (1 + J)/2."""
    best = best_threshold(roc_curve(self_scores, other_scores))
    return (1.0 + best["tpr"] - best["fpr"]) / 2.0


# ---- the table ------------------------------------------------------------------------------------------
def roc_table(kinds: np.ndarray, conditions: np.ndarray, delays: np.ndarray, per_frame: np.ndarray,
              failed: np.ndarray, period: float) -> tuple[list, dict, dict]:
    """Self vs others (pooled, then each condition) over the episodes that did not fail, scored by the time-average
    of per_frame (N, T). Returns (one row per comparison, ROC curves, AUC and balanced accuracy over viewing time)
    by comparison name."""
    ok = ~failed
    scores = np.full(len(kinds), np.nan)
    scores[ok] = per_frame[ok].mean(axis=1)
    s = scores[ok & (kinds == SELF)]
    names = [c for c in dict.fromkeys(conditions) if c != SELF]
    every = {"pooled": kinds != SELF, **{c: conditions == c for c in names}}
    groups = {name: ok & mask for name, mask in every.items()}
    over_time = decision_over_time(kinds, per_frame, failed, groups)
    rows, curves = [], {}
    for name, mask in groups.items():
        o = scores[mask]
        curves[name] = roc_curve(s, o)
        delay = np.unique(delays[every[name]]) if name != "pooled" else np.array([np.nan])
        rows.append({"comparison": name, "delay_s": float(delay[0]) if delay.size == 1 else float("nan"),
                     "self": int(s.size), "others": int(o.size), "auc": auc(s, o), **best_threshold(curves[name]),
                     "t95_s": time_to(over_time[name]["accuracy"], period),
                     "t_auc95_s": time_to(over_time[name]["auc"], period),
                     "median_self": float(np.median(s)) if s.size else float("nan"),
                     "median_other": float(np.median(o)) if o.size else float("nan"),
                     "failed": int((failed & every[name]).sum())})
    return rows, curves, over_time


def decision_over_time(kinds: np.ndarray, per_frame: np.ndarray, failed: np.ndarray,
                       groups: Mapping[str, np.ndarray]) -> dict[str, dict[str, np.ndarray]]:
    """AUC and best balanced accuracy of the running mean of F after each frame (how long must the robot watch?),
    per group mask (N,) of others. Each (T,)."""
    running = np.cumsum(per_frame, axis=1) / np.arange(1, per_frame.shape[1] + 1)    # (N, T)
    s = running[~failed & (kinds == SELF)]
    frames = range(running.shape[1])
    return {name: {"auc": np.array([auc(s[:, j], running[mask, j]) for j in frames]),
                   "accuracy": np.array([balanced_accuracy(s[:, j], running[mask, j]) for j in frames])}
            for name, mask in groups.items()}


def time_to(curve: np.ndarray, period: float, level: float = DECISION) -> float:
    """Viewing time (s) from which the curve stays ≥ level; NaN when it does not end there."""
    below = np.flatnonzero(~(curve >= level))
    if curve.size == 0 or (below.size and below[-1] == curve.size - 1):
        return float("nan")
    return float((below[-1] + 2 if below.size else 1) * period)


def viewing_rows(over_time: Mapping[str, Mapping[str, np.ndarray]], period: float) -> list[dict]:
    """One row per comparison and viewing time (s): AUC and best balanced accuracy of the running mean."""
    return [{"comparison": name, "viewing_s": round((j + 1) * period, 6), "auc": float(curve["auc"][j]),
             "accuracy": float(curve["accuracy"][j])}
            for name, curve in over_time.items() for j in range(curve["auc"].size)]


def markdown(rows: Sequence[Mapping], notes: Sequence[str]) -> str:
    """The summary table (self vs each condition of other) and a few lines of what was measured."""
    return markdown_table(rows, TABLE_COLUMNS, "comparison") + "\n" + "\n".join(notes) + "\n"


def summary_notes(config, robot: str, visual: Sequence[str], period: float, rows: Sequence[Mapping], scores,
                  wall: float) -> list[str]:
    """The lines under the summary table: what was measured, the decision rule, failures and time."""
    pooled = rows[0]
    failures = sorted({r for r in scores.reason if r})
    failed = f"{int(scores.failed.sum())}" + (f" ({'; '.join(failures[:5])})" if failures else "")
    return [f"Self-recognition on {robot} seen through {', '.join(visual)}: {config.trials} babbling episodes of "
            f"{config.steps} frames every {period:g} s per condition: the robot's own body, and "
            f"{', '.join(config.sources)} (imitator: gain {config.imitation_gain:g}, motor noise "
            f"{config.imitation_noise:.4g} rad, delays {', '.join(f'{d:g}' for d in config.delays)} s); noise σ: "
            f"joints {config.proprio_noise:.4g} rad, visual {({m: s for m, s in config.visual_noise if m in visual})}.",
            f"Score: time-averaged {SCORE_NAMES[config.score]} after {_updates(config, visual)} per frame (one body "
            f"from {_START_NOTE[config.start]}); "
            f"'is this me?' = score ≤ threshold (Youden's J per comparison; pooled: "
            f"{pooled['threshold']:.4g}, TPR {pooled['tpr']:.3f} at FPR {pooled['fpr']:.3f}, AUC {pooled['auc']:.4f}). "
            f"t95_s: viewing time from which the best balanced accuracy stays ≥ {DECISION:g} (a 95 % decision); "
            f"t_auc95_s: from which the AUC stays ≥ {DECISION:g}; NaN: not within the episode.",
            f"Failed episodes: {failed}; wall time {wall:.1f} s."]


def _updates(config, visual: Sequence[str]) -> str:
    """The perception updates of one hypothesis per frame, e.g. "≤ 10 + 10 adam+lm updates"."""
    perception = resolve(config.perception, visual)
    steps = perception.max_steps
    return f"≤ {steps} + {steps} adam+lm updates" if perception.method == "adam+lm" else \
        f"≤ {steps} {perception.method} updates"


# ---- plots ---------------------------------------------------------------------------------------------
def plot_roc(curves: Mapping[str, Mapping[str, np.ndarray]], rows: Sequence[Mapping], path: Path) -> Path:
    from bodyschema.evaluation.core.plots import plt, save_figure  # matplotlib only when plotting
    fig, ax = plt.subplots(figsize=(4.8, 4.6))
    aucs = {r["comparison"]: r["auc"] for r in rows}
    for name, roc in curves.items():
        ax.step(roc["fpr"], roc["tpr"], where="post", lw=2.2 if name == "pooled" else 1.2,
                label=f"{name} (AUC {aucs[name]:.3f})")
    ax.plot([0, 1], [0, 1], color="grey", ls=":", lw=0.8)
    ax.set_xlabel("FPR: others taken for me")
    ax.set_ylabel("TPR: me recognised")
    ax.set_title("is this me? score ≤ threshold")
    ax.legend(loc="lower right", fontsize=7)
    return save_figure(fig, path, dpi=120)


def plot_over_viewing_time(over_time: Mapping[str, Mapping[str, np.ndarray]], period: float, path: Path) -> Path:
    """AUC and best balanced accuracy vs viewing time, one line per comparison."""
    from bodyschema.evaluation.core.plots import plt, save_figure
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharex=True)
    for (name, curve), c in zip(over_time.items(), range(len(over_time))):
        t = (np.arange(curve["auc"].size) + 1) * period
        for ax, key in zip(axes, ("auc", "accuracy")):
            ax.plot(t, curve[key], color=f"C{c}", lw=2.2 if name == "pooled" else 1.2, label=name)
    for ax, label in zip(axes, ("AUC of the running mean of F", "balanced accuracy at the best threshold")):
        ax.axhline(DECISION, color="grey", ls=":", lw=0.8)
        ax.set_xlabel("viewing time (s)")
        ax.set_ylabel(label)
    axes[0].legend(loc="lower right", fontsize=7)
    return save_figure(fig, path, dpi=120)


def plot_vs_delay(rows: Sequence[Mapping], over_time: Mapping[str, Mapping[str, np.ndarray]], period: float,
                  path: Path) -> Path:
    """AUC (after a quarter, half and all of the viewing window) and time to a 95 % decision vs the imitator's
    delay; the other sources as horizontal lines."""
    from bodyschema.evaluation.core.plots import plt, save_figure
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6))
    imitator = [r for r in rows if np.isfinite(r["delay_s"])]
    others = [r for r in rows if not np.isfinite(r["delay_s"]) and r["comparison"] != "pooled"]
    delays = [r["delay_s"] for r in imitator]
    frames = next(iter(over_time.values()))["auc"].size
    for k, frame in enumerate(dict.fromkeys((max(frames // 4, 1), max(frames // 2, 1), frames))):
        axes[0].plot(delays, [over_time[r["comparison"]]["auc"][frame - 1] for r in imitator], "o-", color="C0",
                     alpha=(k + 1) / 3, label=f"imitator, {frame * period:g} s viewed")
    axes[1].plot(delays, [r["t95_s"] for r in imitator], "o-", color="C0", label="imitator")
    for ax, key in zip(axes, ("auc", "t95_s")):
        for c, r in enumerate(others, start=1):
            ax.axhline(r[key], color=f"C{c}", ls="--", lw=1, label=f"{r['comparison']} ({key})")
        ax.set_xlabel("imitator delay (s)")
    axes[0].set_ylabel("AUC")
    axes[1].set_ylabel("time to a 95 % decision (s)")
    axes[0].axhline(0.5, color="grey", ls=":", lw=0.8)
    axes[0].legend(fontsize=7)
    return save_figure(fig, path, dpi=120)


def plot_histogram(conditions: np.ndarray, scores: np.ndarray, failed: np.ndarray, path: Path) -> Path:
    """Score histograms per condition on a symmetric log axis (scores span decades; a difference of free
    energies may be negative)."""
    from bodyschema.evaluation.core.plots import plt, save_figure
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    ok = ~failed & np.isfinite(scores)
    if ok.any():
        low, high = np.arcsinh(scores[ok].min()), np.arcsinh(scores[ok].max())
        bins = np.sinh(np.linspace(low, max(high, low + 1e-6), 40))             # even steps of asinh: log-like
        for name in dict.fromkeys(conditions):
            values = scores[ok & (conditions == name)]
            ax.hist(values, bins=bins, histtype="step", lw=2 if name == SELF else 1, label=f"{name} ({values.size})")
        ax.set_xscale("symlog", linthresh=1.0)
    ax.set_xlabel("time-averaged score (nats: a free energy or a difference of two)")
    ax.set_ylabel("episodes")
    ax.legend(fontsize=7)
    return save_figure(fig, path, dpi=120)


def plot_over_time(conditions: np.ndarray, per_frame: np.ndarray, period: float, path: Path,
                   per_condition: int = 2) -> Path:
    """F(t) of the first `per_condition` episodes of each condition. per_frame (N, T), NaN where one failed."""
    from bodyschema.evaluation.core.plots import plt, save_figure
    fig, ax = plt.subplots(figsize=(6.4, 4))
    t = np.arange(per_frame.shape[1]) * period
    for c, name in enumerate(dict.fromkeys(conditions)):
        for j, i in enumerate(np.flatnonzero(conditions == name)[:per_condition]):
            ax.plot(t, per_frame[i], color=f"C{c}", lw=1, alpha=0.8,
                    label=name if j == 0 else None)
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("score per frame (nats)")
    ax.set_title(f"Free-energy score of the first {per_condition} episodes per condition", fontsize=10)
    ax.legend(fontsize=7)
    return save_figure(fig, path, dpi=120)


def write_report(out: Path, episodes_rows: Sequence[Mapping], rows: Sequence[Mapping], curves, over_time,
                 notes: Sequence[str], conditions: np.ndarray, failed: np.ndarray, per_frame: np.ndarray,
                 period: float, plots: bool = True) -> dict[str, Path]:
    """summary.md, summary.csv, viewing_time.csv, episodes.csv and (with `plots`) roc.png, viewing_time.png,
    delay.png, scores.png and free_energy.png in `out`."""
    out.mkdir(parents=True, exist_ok=True)
    paths = {"summary_csv": write_csv(rows, out / "summary.csv"),
             "viewing_time_csv": write_csv(viewing_rows(over_time, period), out / "viewing_time.csv"),
             "episodes_csv": write_csv(episodes_rows, out / "episodes.csv"),
             "summary_md": out / "summary.md"}
    paths["summary_md"].write_text(markdown(rows, notes))
    if plots:
        paths["roc"] = plot_roc(curves, rows, out / "roc.png")
        paths["viewing_time"] = plot_over_viewing_time(over_time, period, out / "viewing_time.png")
        if any(np.isfinite(r["delay_s"]) for r in rows):
            paths["delay"] = plot_vs_delay(rows, over_time, period, out / "delay.png")
        scores = np.where(failed, np.nan, per_frame.mean(axis=1))
        paths["scores"] = plot_histogram(conditions, scores, failed, out / "scores.png")
        paths["free_energy"] = plot_over_time(conditions, per_frame, period, out / "free_energy.png")
    return paths
