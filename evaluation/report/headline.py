"""The report's headline: one line per section with the benchmark's key figure, read from the CSVs of the run the
section shows (only those the section accepted: never a stale or outside file).

models (a plain folder, the demo's): the floor of each model that has one; levels: mean joint error per level, the
floor (started at the truth) and the joints it finds not observable;
robustness: joint error at the largest noise and with the worst broken sensor;
tracking: per frame rate and sensing condition, the tracker's mean joint error beside the other methods', its time
per frame and lost-track events; reaching: AIF vs PD success; loop robustness: success at the largest noise and with
the worst broken sensor; adaptation: error after the gravity switch per controller (Jupiter), the fraction of the
marker shift corrected (marker shift); self-recognition: the pooled AUC; rubber hand: drift after synchronous vs
asynchronous stroking; agency: the pooled AUC of own vs imposed movements at each delay. A benchmark without a rule
here, or a run whose CSV lacks a column, gets a line that says so: the headline never hides a section.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from pathlib import Path

from bodyschema.evaluation.core.runs import read_run_record
from bodyschema.evaluation.core.tables import escape_markdown
from bodyschema.evaluation.report.sections import Section
from bodyschema.evaluation.report.trained import held_out


class NoFigure(Exception):
    """The run's CSVs do not hold the key figure (an older or a partial run)."""


def headline(section: Section) -> str:
    """The section's key figure as one line of Markdown (escaped)."""
    rule = RULES.get(section.benchmark or section.folder_name)       # a plain folder by its name (`models`)
    if rule is None:
        return "no key figure defined for this benchmark: see its section"
    try:
        return rule(section)
    except NoFigure as e:
        return f"key figure unavailable ({escape_markdown(e)})"


# ---- reading a run's CSVs -----------------------------------------------------------------------------------
def rows(section: Section, name: str) -> list[dict[str, str]]:
    """The rows of the run's CSV `name`, one the section accepted."""
    path = next((p for p in section.tables if p.relative_to(section.folder) == Path(name)), None)
    if path is None:
        raise NoFigure(f"no {name}")
    try:
        with open(path, newline="", encoding="utf-8") as f:
            table = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise NoFigure(f"{name} unreadable ({type(e).__name__})") from None
    if not table:
        raise NoFigure(f"{name} is empty")
    return table


def number(row: dict[str, str], column: str) -> float:
    try:
        return float(row[column])
    except (KeyError, TypeError, ValueError):
        raise NoFigure(f"no number in column {column}") from None


def cell(row: dict[str, str], column: str) -> str:
    """A name from the row (a controller, a case), escaped for the page."""
    if row.get(column) is None:
        raise NoFigure(f"no column {column}")
    return escape_markdown(row[column])


def setting(section: Section, field: str):
    """A field of the run's config (run.json); None for a run older than run.json."""
    fields = read_run_record(section.folder).get("fields")
    return fields.get(field) if isinstance(fields, dict) else None


def fmt(value: float, unit: str = "") -> str:
    """3 significant digits and the unit (° unspaced, others after a space); NaN (not reached, not measured): n/a."""
    if math.isnan(value):
        return "n/a"
    return f"{value:.3g}{unit if unit in ('°', '') else ' ' + unit}"


def _mean_of(n: int, what: str) -> str:
    return f", mean of {n} {what}s" if n > 1 else ""


def percent(fraction: float) -> str:
    return "n/a" if math.isnan(fraction) else f"{100 * fraction:.0f} %"


# ---- one rule per benchmark -----------------------------------------------------------------------------------
def models(section: Section) -> str:
    floors = [r for r in rows(section, "models.csv") if r.get("floor_deg")]
    if not floors:
        raise NoFigure("models.csv has no floor_deg")
    return " · ".join(f"{cell(r, 'model')} ({int(number(r, 'epochs'))} epochs on {int(number(r, 'train_samples'))} "
                      f"samples): floor {fmt(number(r, 'floor_deg'), '°')} mean joint error, started at the truth"
                      for r in floors)


def levels(section: Section) -> str:
    table = rows(section, "summary.csv")
    floor = next((r for r in table if r.get("level") == "floor"), None)   # a run before the floor row: none
    per_level = " · ".join(f"L{cell(r, 'level')} {fmt(number(r, 'joint_err_deg'), '°')}" for r in table
                           if r is not floor)
    if floor is None:
        return f"mean joint error {per_level}"
    threshold = setting(section, "unobservable_deg")
    unseen = [] if threshold is None else [
        f"{escape_markdown(k.removeprefix('joint_err_deg/'))} {fmt(number(floor, k), '°')}" for k in floor
        if k.startswith("joint_err_deg/") and number(floor, k) > threshold]
    return (f"mean joint error {per_level}; floor {fmt(number(floor, 'joint_err_deg'), '°')} (started at the truth)"
            + (f"; not observable by this model/camera: {', '.join(unseen)}" if unseen else ""))


def robustness(section: Section) -> str:
    noise = rows(section, "noise_sweep.csv")
    worst = max(rows(section, "broken_sensor.csv"), key=lambda r: number(r, "joint_err_deg"))
    clean, noisiest = min(noise, key=lambda r: number(r, "sigma")), max(noise, key=lambda r: number(r, "sigma"))
    return (f"joint error {fmt(number(clean, 'joint_err_deg'), '°')} at σ {fmt(number(clean, 'sigma'))} → "
            f"{fmt(number(noisiest, 'joint_err_deg'), '°')} at σ {fmt(number(noisiest, 'sigma'))} "
            f"({cell(noisiest, 'modality')}); worst broken sensor ({cell(worst, 'broken')}) "
            f"{fmt(number(worst, 'joint_err_deg'), '°')}")


def tracking(section: Section) -> str:
    table = rows(section, "summary.csv")
    cases = {}
    for r in table:
        cases.setdefault((cell(r, "rate_hz"), cell(r, "condition")), []).append(r)
    return " · ".join(_tracked(rate, condition, mine) for (rate, condition), mine in cases.items())


def _tracked(rate: str, condition: str, mine: list[dict[str, str]]) -> str:
    """One rate and condition: the tracker's error, time per frame and lost track, the other methods' errors."""
    tracker = next((r for r in mine if r.get("method") == "tracker"), None)
    if tracker is None:
        raise NoFigure(f"summary.csv lacks the tracker row at {rate} Hz, {condition}")
    others = ", ".join(f"{cell(r, 'method')} {fmt(number(r, 'joint_err_deg'), '°')}" for r in mine if r is not tracker)
    # CPU ms beside the wall ms where the run has them: a shared machine's load inflates only the wall
    cpu = (f", {fmt(1e3 * number(tracker, 'wall_s_frame_cpu_median'), 'ms')} of CPU"
           if tracker.get("wall_s_frame_cpu_median") else "")
    return (f"{rate} Hz, {condition}: tracker {fmt(number(tracker, 'joint_err_deg'), '°')} mean joint error"
            f"{f' ({others})' if others else ''}, {fmt(1e3 * number(tracker, 'wall_s_frame_median'), 'ms')} per frame "
            f"(median{cpu}), {int(number(tracker, 'lost_events'))} lost-track events")


def reaching(section: Section) -> str:
    by_controller = {r.get("controller", "").lower(): r for r in rows(section, "summary.csv")}
    if not {"aif", "pd"} <= by_controller.keys():
        raise NoFigure("summary.csv lacks the aif or pd row")
    aif, pd = by_controller["aif"], by_controller["pd"]
    tolerance = setting(section, "success_mm")
    within = f" (final ee error < {fmt(float(tolerance), 'mm')})" if isinstance(tolerance, (int, float)) else ""
    return (f"success{within} AIF {percent(number(aif, 'success'))} vs PD {percent(number(pd, 'success'))} over "
            f"{cell(aif, 'episodes')} episodes")


def loop_robustness(section: Section) -> str:
    noise = rows(section, "noise_sweep.csv")
    broken = [r for r in rows(section, "broken_sensor.csv") if r.get("case") != "none"]
    if not broken:
        raise NoFigure("broken_sensor.csv has no broken sensor")
    noisiest = max(noise, key=lambda r: number(r, "sigma"))
    worst = min(broken, key=lambda r: (number(r, "success"), -number(r, "ee_err_mm")))
    return (f"reaching success {percent(number(noisiest, 'success'))} at σ {fmt(number(noisiest, 'sigma'))} "
            f"({cell(noisiest, 'modality')}); worst broken sensor ({cell(worst, 'case')}) "
            f"{percent(number(worst, 'success'))}")


def jupiter(section: Section) -> str:
    table = rows(section, "summary.csv")
    after = " · ".join(f"{cell(r, 'controller')} {fmt(number(r, 'joint_err_after_deg'), '°')}" for r in table)
    return f"joint error after the gravity switch: {after}"


def marker_shift(section: Section) -> str:
    table = rows(section, "summary.csv")
    done = sum(number(r, "correction") for r in table) / len(table)
    theory = sum(number(r, "predicted_correction") for r in table) / len(table)
    return f"{fmt(done)} of the seen marker shift corrected (linear theory {fmt(theory)}){_mean_of(len(table), 'case')}"


def self_recognition(section: Section) -> str:
    pooled = next((r for r in rows(section, "summary.csv") if r.get("comparison") == "pooled"), None)
    if pooled is None:
        raise NoFigure("summary.csv lacks the pooled row")
    return (f"AUC own body vs others {fmt(number(pooled, 'auc'))} (pooled; TPR {fmt(number(pooled, 'tpr'))} at "
            f"FPR {fmt(number(pooled, 'fpr'))})")


def rubber_hand(section: Section) -> str:
    table = rows(section, "conditions.csv")
    drift = {mode: [number(r, "drift_cm") for r in table if r.get("mode") == mode]
             for mode in ("synchronous", "asynchronous")}
    if not all(drift.values()):
        raise NoFigure("conditions.csv lacks a synchronous or asynchronous condition")
    mean = {mode: sum(d) / len(d) for mode, d in drift.items()}
    return (f"drift towards the seen hand {fmt(mean['synchronous'], 'cm')} synchronous vs "
            f"{fmt(mean['asynchronous'], 'cm')} asynchronous{_mean_of(len(drift['synchronous']), 'condition')}")


def agency(section: Section) -> str:
    pooled = [r for r in rows(section, "roc.csv") if r.get("source") == "pooled" and r.get("senses") == "all senses"]
    if not pooled:
        raise NoFigure("roc.csv lacks the pooled rows of all senses")
    cases = " · ".join(f"{fmt(number(r, 'auc'))} at {fmt(1000 * number(r, 'delay_s'), 'ms')}"
                       f"{' (delay known)' if r.get('known_delay') == 'True' else ''}" for r in pooled)
    return f"AUC own vs imposed movements (all senses, pooled): {cases}"


RULES: dict[str, Callable[[Section], str]] = {
    "models": models, "trained": held_out, "levels": levels, "robustness": robustness, "tracking": tracking,
    "reaching": reaching,
    "loop_robustness": loop_robustness,
    "adaptation/jupiter": jupiter, "adaptation/marker_shift": marker_shift, "self_recognition": self_recognition,
    "rubber_hand": rubber_hand, "agency": agency}
