"""The one table writer: CSV with the union of the rows' columns, Markdown with mean ± std, counts as they are."""

from __future__ import annotations

import csv

from bodyschema.evaluation.core.tables import is_wall_column, markdown_table, write_csv


def test_csv_keeps_every_column_in_first_seen_order(tmp_path):
    rows = [{"level": "1", "err": 0.5}, {"level": "2", "err": 0.25, "extra": 3}]
    with open(write_csv(rows, tmp_path / "t.csv"), newline="") as f:
        read = list(csv.DictReader(f))
    assert list(read[0]) == ["level", "err", "extra"] and read[0]["extra"] == "" and read[1]["extra"] == "3"


def test_markdown_shows_std_counts_and_missing_cells():
    table = [{"level": "1", "err": 0.123456, "err_std": 0.01, "failed": 12000}, {"level": "2", "err": 2.0}]
    lines = markdown_table(table, ("err", "failed"), "level").splitlines()
    assert lines[0] == "| level | err | failed |" and lines[1] == "|---|---|---|"
    assert lines[2] == "| 1 | 0.1235 ± 0.01 | 12000 |" and lines[3] == "| 2 | 2 | – |"


def test_wall_clock_columns_are_the_ones_a_rerun_may_change():
    assert all(map(is_wall_column, ("wall_s", "wall_s_std", "L1/wall_s")))
    assert not any(map(is_wall_column, ("settle_s", "time_to_reach_s", "joint_err_deg")))
