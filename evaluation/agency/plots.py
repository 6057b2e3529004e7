"""The agency benchmark's figures: ROC per sensory delay, AUC vs delay per senses, free energy over time.

Curves that coincide (an exact model gives AUC 1 at several delays) must all stay visible: one panel per delay or
per senses (small multiples), and within a panel each line its own colour, dash and marker, drawn wide-to-narrow so
a line on top of another leaves it showing; every legend entry carries its AUC. Each `*_figure` returns a Figure a
test can inspect; `write_plots` saves them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from bodyschema.evaluation.agency.streams import ALL, SELF
from bodyschema.evaluation.core.plots import plt, save_figure

# (dash, marker, marker size, line width): the first drawn widest, so a later one on top leaves it visible
STYLES = (("-", "o", 7, 2.6), ("--", "s", 5, 1.8), (":", "^", 4, 1.6), ("-.", "D", 3, 1.2), ((0, (1, 1)), "v", 3, 1))
F_UNIT = "nats"     # F = Σ ½ εᵀΠε, natural-log units, constants dropped (benchmark.py's formula)


def write_plots(out: Path, config, robot: str, rows: Sequence[Mapping], curves: Mapping, episodes,
                energies: Mapping) -> dict[str, Path]:
    return {"roc_png": save_figure(roc_figure(rows, curves, robot), out / "roc.png"),
            "auc_vs_delay_png": save_figure(auc_vs_delay_figure(rows, config.sources, robot), out / "auc_vs_delay.png"),
            "free_energy_png": save_figure(free_energy_figure(config, episodes, energies, robot),
                                           out / "free_energy.png")}


def roc_figure(rows: Sequence[Mapping], curves: Mapping[str, Mapping[str, np.ndarray]], robot: str):
    """One panel per sensory delay: the pooled ROC on all senses, predicted for now and (delay > 0) with the delay
    known, each labelled with its AUC."""
    pooled = [r for r in rows if r["source"] == "pooled" and r["senses"] == ALL]
    delays = sorted({r["delay_s"] for r in pooled})
    fig, axes = plt.subplots(1, len(delays), figsize=(3.6 * len(delays) + 0.4, 4.8), sharey=True, squeeze=False)
    for ax, delay in zip(axes.flat, delays):
        for k, row in enumerate(sorted((r for r in pooled if r["delay_s"] == delay), key=lambda r: r["known_delay"])):
            dash, marker, size, width = STYLES[k % len(STYLES)]
            roc = curves[row["comparison"]]
            ax.plot(roc["fpr"], roc["tpr"], ls=dash, lw=width, marker=marker, ms=size, color=f"C{k}",
                    alpha=0.8, mfc="none" if k else f"C{k}",
                    label=f"{'delay known' if row['known_delay'] else 'predicted for now'} (AUC {row['auc']:.3f})")
        ax.plot([0, 1], [0, 1], ":", color="grey", lw=0.8)                             # chance
        ax.set(xlabel="imposed movements claimed (FPR)", title=f"sensory delay {delay * 1000:g} ms",
               xlim=(-0.03, 1.03), ylim=(-0.03, 1.03))
        ax.set_box_aspect(1)
        ax.set_anchor("N")                   # square panels at the top of their slots: the legends below fit
        ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16))    # below: covers no curve
    axes[0, 0].set_ylabel("own movements claimed (TPR)")
    fig.suptitle(f"Did I do it? ROC of own vs imposed movements (all senses, sources pooled), {robot}")
    return fig


def auc_vs_delay_figure(rows: Sequence[Mapping], sources: Sequence[str], robot: str):
    """One panel per senses (all, then each modality): AUC vs delay per source, predicted for now; the pooled
    sources with the delay known beside them."""
    senses_all = [ALL, *sorted({r["senses"] for r in rows} - {ALL})]
    lines = [(source, False) for source in (*sources, "pooled")] + [("pooled", True)]
    fig, axes = plt.subplots(1, len(senses_all), figsize=(3.6 * len(senses_all) + 0.4, 3.8), sharey=True,
                             squeeze=False)
    for ax, senses in zip(axes.flat, senses_all):
        for k, (source, known) in enumerate(lines):
            sel = sorted((r for r in rows if (r["senses"], r["source"]) == (senses, source)
                          and (r["known_delay"] == known or (known and r["delay_s"] == 0))),   # 0: nothing to know
                         key=lambda r: r["delay_s"])
            dash, marker, size, width = STYLES[k % len(STYLES)]
            ax.plot([r["delay_s"] * 1000 for r in sel], [r["auc"] for r in sel], ls=dash, lw=width, marker=marker,
                    ms=size, color=f"C{k}", alpha=0.85, mfc="none" if known else f"C{k}",
                    label=f"{source}, delay known" if known else f"{source}, predicted for now")
        ax.axhline(0.5, color="grey", ls=":", lw=0.8)
        ax.set(xlabel="sensory delay (ms)", title=senses, ylim=(-0.03, 1.03))
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("AUC of own vs imposed (0.5: chance)")
    axes[0, -1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1))   # beside the panels, hiding none
    fig.suptitle(f"Agency AUC vs sensory delay, per senses, {robot}")
    return fig


def free_energy_figure(config, episodes, energies: Mapping, robot: str):
    """Median (IQR band) over episodes of F(t) on all senses, per kind of movement, at the shortest delay."""
    delay = min(config.delays)
    total = sum(energies[(delay, False)].values())                               # (N, T)
    t = (np.arange(total.shape[1]) + 1) * config.period
    fig, ax = plt.subplots(figsize=(6.4, 4))
    for k, kind in enumerate((SELF, *config.sources)):
        sel = (episodes.kind == kind) & ~episodes.failed
        if sel.any():
            q25, q50, q75 = np.percentile(total[sel], [25, 50, 75], axis=0)     # (T,) each
            ax.plot(t, q50, ls=STYLES[k][0], marker=STYLES[k][1], ms=4, color=f"C{k}", label=kind)
            ax.fill_between(t, q25, q75, color=f"C{k}", alpha=0.15)
    ax.set_yscale("symlog", linthresh=1.0)           # F ≥ 0 spans decades between own and imposed movements
    ax.set(xlabel="time (s)", ylabel=f"F ({F_UNIT}): median and IQR over episodes",
           title=f"Free energy of the predicted consequences, {robot}\n(all senses, delay {delay * 1000:g} ms)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig
