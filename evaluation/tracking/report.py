"""The tracking benchmark's scores, tables and plot: per rate × condition × method the joint and hand errors, lost
track (the hand more than lost_mm off) and its recovery, the method's own restarts, evaluations and time per frame.

Wall-clock columns start with `wall_s` (core.tables: they differ between two runs of one seed): wall_s_frame_median
and _p95 are s per stream and frame, wall_s_network_share the part of it spent inside the models and the encoder,
wall_s_frame_cpu_median and _p95 the process's CPU time per stream and frame (a frame's cost without the load of a
shared machine; named wall_s_ as every timing column that differs between runs).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from bodyschema.evaluation.core.tables import markdown_table, write_csv

COLUMNS = ("joint_err_deg", "joint_err_median_deg", "ee_err_mm", "off_track_pct", "lost_events", "recovered_share",
           "restarts", "evaluations_per_frame", "ms_median", "ms_p95", "cpu_ms_median", "cpu_ms_p95", "network_share")


def errors(robot, q: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mean |joint error| deg, hand error mm) per stream and frame (N, T) of beliefs mu against poses q (N, T, Dq)."""
    joint = np.rad2deg(np.abs(mu - q)).mean(axis=-1)
    hand = 1e3 * np.linalg.norm(_hand(robot, mu) - _hand(robot, q), axis=1).reshape(q.shape[:2])
    return joint, hand


def _hand(robot, q: np.ndarray) -> np.ndarray:
    """Forward kinematics of poses (..., Dq) inside the joint limits → (M, 3) m."""
    lim = robot.joint_limits
    return robot.fk(np.clip(q.reshape(-1, q.shape[-1]), lim[:, 0], lim[:, 1]))


def lost_runs(off: np.ndarray) -> list[tuple[int, int, bool]]:
    """(stream, frames off track, back on track before the end) per run of consecutive off frames in off (N, T)."""
    runs = []
    for i, row in enumerate(off):
        padded = np.concatenate([[False], row, [False]]).astype(np.int8)
        edges = np.flatnonzero(np.diff(padded))                               # starts, then ends, alternating
        for begin, end in zip(edges[::2], edges[1::2]):
            runs.append((i, int(end - begin), bool(end < len(row))))
    return runs


def score(robot, streams, done, lost_mm: float, recovery_frames: int) -> tuple[dict, list[dict]]:
    """(table row, per-frame curve rows) of one method on the streams; frame 0 (the start) is not scored."""
    joint, hand = (e[:, 1:] for e in errors(robot, streams.q, done.mu))
    off = hand > lost_mm
    runs = lost_runs(off)
    back = [length <= recovery_frames and ended for _, length, ended in runs]
    row = {"frames": int(joint.size), "joint_err_deg": float(joint.mean()),
           "joint_err_median_deg": float(np.median(joint)), "joint_err_p95_deg": float(np.quantile(joint, 0.95)),
           "ee_err_mm": float(hand.mean()), "ee_err_median_mm": float(np.median(hand)),
           "off_track_pct": float(100 * off.mean()), "lost_events": len(runs),
           "recovered_share": float(np.mean(back)) if runs else 1.0,
           "recovery_frames_max": max((length for _, length, _ in runs), default=0),
           "restarts": int(done.restarted[:, 1:].sum()), "evaluations_per_frame": float(done.evaluations.mean()),
           "wall_s_frame_median": float(np.median(done.ms)) / 1e3,
           "wall_s_frame_p95": float(np.quantile(done.ms, 0.95)) / 1e3,
           "wall_s_frame_cpu_median": float(np.median(done.cpu_ms)) / 1e3,
           "wall_s_frame_cpu_p95": float(np.quantile(done.cpu_ms, 0.95)) / 1e3,
           "wall_s_network_share": float(done.network_ms.sum() / max(done.ms.sum(), 1e-12))}
    onsets = np.zeros_like(off)
    onsets[:, 0] = off[:, 0]
    onsets[:, 1:] = off[:, 1:] & ~off[:, :-1]
    curve = [{"t_s": (k + 1) * streams.period, "joint_err_deg": float(joint[:, k].mean()),
              "ee_err_mm": float(hand[:, k].mean()), "lost_onsets": int(onsets[:, k].sum()),
              "restarts": int(done.restarted[:, k + 1].sum())} for k in range(joint.shape[1])]
    return row, curve


def display(rows: Sequence[Mapping]) -> list[dict]:
    """The rows with their timing in ms and the network's share in %, for the Markdown table."""
    out = []
    for r in rows:
        d = {**r, "ms_median": 1e3 * r["wall_s_frame_median"], "ms_p95": 1e3 * r["wall_s_frame_p95"],
             "cpu_ms_median": 1e3 * r["wall_s_frame_cpu_median"], "cpu_ms_p95": 1e3 * r["wall_s_frame_cpu_p95"],
             "network_share": 100 * r["wall_s_network_share"],
             "case": f"{r['rate_hz']:g} Hz · {r['condition']} · {r['method']}"}
        out.append(d)
    return out


def notes(config, robot, models, wall: float) -> list[str]:
    specs = ", ".join(getattr(m, "provenance", {}).get("spec", type(m).__name__) for m in models)
    t = config.tracker
    sensors = f"; with several sensors, also each joints or ee term alone (slack {t.consistency_slack:g})" \
        if t.consistency else ""
    return [f"Robot {robot.name}; models {specs}; encoder {config.encoder or 'none'}. {config.trials} babbling "
            f"streams of {config.duration:g} s per rate (targets held {config.hold_s[0]:g}–{config.hold_s[1]:g} s), "
            f"every method from the true first pose; noise σ {dict(config.noise)}.",
            f"Tracker: {t.perception.method} update, budget {t.budget} model evaluations per frame"
            f"{f' and {t.budget_ms:g} ms' if t.budget_ms else ''}, motion order {t.order}, lost-track threshold "
            f"{'calibrated' if t.lost_threshold is None else t.lost_threshold} (F at the truth of "
            f"{config.calibration_frames} frames: quantile {t.lost_quantile} + {t.lost_slack} × its distance to the "
            f"median){sensors}"
            f", restarts: {t.restart}. flow: Euler steps, same budget, Δt = 1/λ_max(H) (column euler_dt). "
            "tracker+command: moved by the joint velocity of the previous frame.",
            f"Off track: the hand > {config.lost_mm:g} mm from the truth; recovered_share: lost events back within "
            f"{config.recovery_frames} frames; restarts: the method's own lost-track detections. ms per stream and "
            f"frame ({'batched: the batch time / streams' if config.batched else 'one stream at a time'}; cpu_ms: the "
            f"process's CPU time, the cost without other processes' load), "
            f"network_share in % of it. Run wall time {wall:.0f} s."]


def title(robot, models, encoder) -> str:
    """What the plot shows, for a reader who sees only the picture: robot, models (kind and size), encoder."""
    def name(m):
        size = getattr(m, "size", None)
        return f"{m.kind} {m.modality}" + (f" ({size})" if size else "")
    seen = " + ".join(name(m) for m in models)
    return f"{robot.name}: {seen}" + (" + image encoder" if encoder is not None else "")


def write_all(folder: Path, rows: Sequence[Mapping], curves: Sequence[Mapping], lines: Sequence[str],
              plots: bool = True, heading: str = "") -> dict[str, Path]:
    """summary.csv, curves.csv, summary.md and (plots) error_vs_time.png, titled `heading`, in folder."""
    paths = {"summary_csv": write_csv(rows, folder / "summary.csv"),
             "curves_csv": write_csv(curves, folder / "curves.csv"), "summary_md": folder / "summary.md"}
    table = markdown_table(display(rows), COLUMNS, "case", digits=3)
    paths["summary_md"].write_text("# Tracking\n\n" + table + "\n" + "\n\n".join(lines) + "\n")
    if plots:
        paths["error_vs_time"] = plot_error_vs_time(curves, folder / "error_vs_time.png", heading)
    return paths


def plot_error_vs_time(curves: Sequence[Mapping], path: Path, heading: str = "") -> Path:
    """Mean joint error vs time per method, one panel per rate × condition (frame rate in its title); the tracker's
    lost-track restarts (▼) and the frames where some stream went off track (×, any method's colour) marked."""
    from bodyschema.evaluation.core.plots import plt, save_figure
    rates = sorted({c["rate_hz"] for c in curves})
    conds = list(dict.fromkeys(c["condition"] for c in curves))
    methods = list(dict.fromkeys(c["method"] for c in curves))
    fig, axes = plt.subplots(len(conds), len(rates), figsize=(4.2 * len(rates), 2.8 * len(conds)), squeeze=False,
                             sharey=True)
    colours = {m: f"C{i}" for i, m in enumerate(methods)}
    for (i, cond), (j, rate) in ((a, b) for a in enumerate(conds) for b in enumerate(rates)):
        ax = axes[i][j]
        for method in methods:
            pts = [c for c in curves if (c["rate_hz"], c["condition"], c["method"]) == (rate, cond, method)]
            t = np.array([c["t_s"] for c in pts])
            err = np.array([c["joint_err_deg"] for c in pts])
            ax.plot(t, err, lw=0.9, color=colours[method], label=method)
            lost = np.array([c["lost_onsets"] > 0 for c in pts], bool)
            ax.plot(t[lost], err[lost], "x", ms=5, color=colours[method])
            if method.startswith("tracker"):
                restart = np.array([c["restarts"] > 0 for c in pts], bool)
                ax.plot(t[restart], np.full(restart.sum(), 0.05), "v", ms=5, color=colours[method])
        ax.set_yscale("log")
        ax.set_title(f"{rate:g} Hz camera · {cond}", fontsize=9)
        ax.set_xlabel("time (s)")
        if j == 0:
            ax.set_ylabel("mean |joint error| (deg)")
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"{heading + chr(10) if heading else ''}Joint error vs time (mean over streams); × a stream lost "
                 "track (hand > lost_mm off), ▼ the tracker restarted", fontsize=9)
    return save_figure(fig, path, dpi=110)
