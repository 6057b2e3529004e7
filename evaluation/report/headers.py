"""Readable table headers: the report turns every snake_case column name of every table on its page (summary.md
tables and the models table alike) into words with their unit: `mean_err_deg` → "mean error (°)",
`joint_err_median_deg` → "median joint error (°)", `joint_err_deg/shoulder` → "joint error, shoulder (°)".

One mapping for every section: `NAMES` for whole names that read wrong word by word, else each word through
`WORDS` and a last word that is a unit through `UNITS`. The CSVs keep their names (scripts read them); only the page
changes. A header cell that is no snake_case name (already words, a symbol) is left as written.
"""

from __future__ import annotations

import re

NAMES = {
    "all_joints_2deg": "all joints within 2°",
    "evaluations_per_trial": "evaluations per trial",
    "evaluations_per_frame": "evaluations per frame",
    "ms_median": "median time per frame (ms)",
    "ms_p95": "p95 time per frame (ms)",
    "network_share": "network share (%)",
    "recovered_share": "share of lost events recovered",
    "fpr_at_tpr95": "FPR at 95 % TPR",
    "t95_s": "time to a 95 % decision (s)",
    "t_auc95_s": "time to AUC 0.95 (s)",
    "t_half_s": "time to half drift (s)",
    "settle_s": "settling time (s)",
    "wall_s": "wall time (s)",
    "success": "success (fraction)",           # the share of trials that succeeded, 0–1 (a mean of booleans)
    "goal_success": "goal success (fraction)",
    "converged": "converged (fraction)",
    "run_id": "source run",
    "sha256": "weights SHA-256",
    "sigma": "σ",
    "joint_peak_after_deg": "peak joint error after (°)",
    "ee_peak_after_mm": "peak ee error after (mm)",
}
WORDS = {"err": "error", "move": "movement", "auc": "AUC", "tpr": "TPR", "fpr": "FPR", "aif": "AIF", "pd": "PD",
         "aic": "AIC", "px": "pixel"}
UNITS = {"deg": "°", "rad": "rad", "mm": "mm", "cm": "cm", "m": "m", "px": "px", "s": "s", "ms": "ms", "hz": "Hz",
         "pct": "%", "mps2": "m/s²"}
QUALIFIERS = ("mean", "median", "max", "min")      # read first: joint_err_median_deg → "median joint error (°)"
SNAKE = re.compile(r"^[a-z][a-z0-9]*(?:_[a-z0-9]+)*(?:/[\w.-]+)?$")
DELIMITER_ROW = re.compile(r"^\s*\|?\s*:?-+:?\s*(?:\|\s*:?-+:?\s*)*\|?\s*$")
CELL_SEPARATOR = re.compile(r"(?<!\\)\|")       # a `|` that is not escaped as `\|`


def readable(column: str) -> str:
    """The header a reader sees for `column`; anything that is no snake_case name comes back unchanged."""
    if column in NAMES:
        return NAMES[column]
    if not SNAKE.match(column):
        return column
    head, _, part = column.partition("/")                        # joint_err_deg/shoulder: one joint's column
    words = head.split("_")
    std = len(words) > 1 and words[-1] == "std"                  # drift_cm_std: the std of drift_cm, in cm
    if std:
        words.pop()
    unit = UNITS[words.pop()] if len(words) > 1 and words[-1] in UNITS else None
    words = [w for w in words if w in QUALIFIERS] + [w for w in words if w not in QUALIFIERS]
    text = " ".join(WORDS.get(w, w) for w in words) + (" std" if std else "") + (f", {part}" if part else "")
    return f"{text} ({unit})" if unit else text


def readable_tables(markdown: str) -> str:
    """`markdown` with the header row of every pipe table made readable (fenced code left alone)."""
    lines, fenced = markdown.split("\n"), False
    for i, line in enumerate(lines):
        if line.lstrip().startswith(("```", "~~~")):
            fenced = not fenced
        if not fenced and _is_table_head(lines, i):
            lines[i] = _readable_row(line)
    return "\n".join(lines)


def _is_table_head(lines: list[str], i: int) -> bool:
    below = lines[i + 1] if i + 1 < len(lines) else ""
    return "|" in lines[i] and "|" in below and DELIMITER_ROW.match(below) is not None


def _readable_row(row: str) -> str:
    cells = CELL_SEPARATOR.split(row)
    return "|".join(cell if not cell.strip() else f" {readable(cell.strip())} " for cell in cells)
