"""ROC/AUC (scikit-learn), tables and the summary of the agency benchmark; its figures are in plots.py."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
from sklearn import metrics

from bodyschema.evaluation.agency.streams import ALL, SELF
from bodyschema.evaluation.core.tables import markdown_table, write_csv

CLAIMED = 0.95            # fpr_at_tpr95: the false "I did it" rate once 95 % of own movements are claimed


def agency_score(energy: Mapping[str, np.ndarray], senses: str) -> np.ndarray:
    """(N,) −F averaged over frames: on every sense (`ALL`) or one modality."""
    f = sum(energy.values()) if senses == ALL else energy[senses]              # (N, T)
    return -f.mean(axis=1)


def roc_rows(config, kinds: np.ndarray, failed: np.ndarray, energies: Mapping[float, Mapping[str, np.ndarray]]
             ) -> tuple[list[dict], dict[str, dict[str, np.ndarray]]]:
    """One row per delay × senses × comparison (each source against self, and all sources pooled): AUC, the
    false-alarm rate at 95 % own movements claimed; ROC curves of the pooled comparison per delay and senses."""
    rows, curves = [], {}
    ok = ~failed
    for (delay, known), energy in energies.items():
        for senses in (ALL, *energy):
            score = agency_score(energy, senses)
            for source in (*config.sources, "pooled"):
                other = (kinds != SELF) if source == "pooled" else (kinds == source)
                sel = ok & ((kinds == SELF) | other)
                y = (kinds[sel] == SELF).astype(int)
                fpr, tpr, _ = metrics.roc_curve(y, score[sel])
                label = f"delay={delay * 1000:g}ms{' known' if known else ''} {source} [{senses}]"
                rows.append({"comparison": label, "delay_s": float(delay), "known_delay": known, "source": source,
                             "senses": senses,
                             "auc": float(metrics.roc_auc_score(y, score[sel])),
                             "fpr_at_tpr95": float(fpr[np.argmax(tpr >= CLAIMED)]),
                             "self": int(y.sum()), "others": int((1 - y).sum()),
                             "failed": int((failed & ((kinds == SELF) | other)).sum())})
                if source == "pooled":
                    curves[label] = {"fpr": fpr, "tpr": tpr}
    return rows, curves


def write_report(out: Path, config, robot: str, senses, episodes, energies, rows, curves, wall: float
                 ) -> dict[str, Path]:
    paths = {"roc_csv": write_csv(rows, out / "roc.csv")}
    per_episode = [{"episode": i, "kind": k, "failed": bool(f),
                    **{f"score_{d * 1000:g}ms{'_known' if known else ''}": float(agency_score(e, ALL)[i])
                       for (d, known), e in energies.items()}}
                   for i, (k, f) in enumerate(zip(episodes.kind, episodes.failed))]
    paths["episodes_csv"] = write_csv(per_episode, out / "episodes.csv")
    main = [r for r in rows if r["senses"] == ALL]
    per_sense = [r for r in rows if r["senses"] != ALL and r["source"] == "pooled"]
    lines = [f"# Agency: did I do it? ({robot}, models: {', '.join(senses)})", "",
             f"{config.trials} episodes of {config.steps} frames × {config.period:g} s, half the robot's own "
             f"movements, half the same movements imposed from outside ({', '.join(config.sources)}); score = −F of "
             "the observations against the consequences the robot's own command predicts (forward model), averaged "
             "over the episode; AUC of own vs imposed; fpr_at_tpr95 = imposed movements claimed as own once 95 % "
             "of the own ones are. Sensory delay: every stream arrives that late; the forward model predicts for now, "
             "or "
             "(known) knows the delay and predicts what arrives then.", "",
             markdown_table(main, ("auc", "fpr_at_tpr95", "self", "others", "failed"), "comparison"), "",
             "Per sense (pooled sources): which sense carries the evidence.", "",
             markdown_table(per_sense, ("auc", "fpr_at_tpr95"), "comparison"), "", f"Wall time {wall:.1f} s."]
    paths["summary"] = out / "summary.md"
    paths["summary"].write_text("\n".join(lines) + "\n", encoding="utf-8")
    if config.plots:
        from bodyschema.evaluation.agency.plots import write_plots  # matplotlib only when plotting
        paths.update(write_plots(out, config, robot, rows, curves, episodes, energies))
    return paths
