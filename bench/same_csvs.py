"""Benchmark: does a refactor change behaviour? Every stage's outputs for one seed, before and after, compared.

    MUJOCO_GL=egl .venv/bin/python bench/same_csvs.py run DIR          # writes DIR/ (≈ 6 min on 2 idle cores)
    .venv/bin/python bench/same_csvs.py compare BEFORE AFTER           # exit 1 when anything differs

`run` makes the demo at small sizes (datagen of the three shipped arms, GPR / pixel / encoder training, levels,
tracking, reaching, self-recognition) and the benchmarks on analytic models (robustness, loop-robustness,
adaptation, rubber-hand, agency), all with seed 0 and one torch thread (thread count changes float sums).
`compare` reads every CSV under both folders (by path relative to the run folder, with run ids taken out) and every
dataset's arrays, and says which are identical. Columns that hold a run id, a wall time or a creation time are
left out: they differ by design. Same machine, same library versions: bit-identical is the bar (a value that
differs by 1 ulp is printed with its relative difference, to tell a summation-order change from a real one).
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import os
import re
import subprocess
import sys
from pathlib import Path

DEMO = ["demo", "--n-nao", "600", "--n-small", "100", "--pixel-epochs", "2", "--encoder-epochs", "2",
        "--trials", "5", "--pixel-trials", "3", "--runs", "1", "--streams", "2", "--stream-seconds", "1",
        "--reach-targets", "3", "--episodes", "3", "--workers", "1"]
BENCHMARKS = [["robustness", "--trials", "5", "--runs", "1"], ["loop-robustness", "--trials", "2"],
              ["adaptation", "marker-shift", "--trials", "2"], ["adaptation", "jupiter", "--trials", "2"],
              ["rubber-hand", "--trials", "2"], ["agency", "--trials", "8"]]
VOLATILE = re.compile(r"run_id|wall|fit_s$|time_s$|seconds|created|duration|_s_per|per_s|fps|ms$|^run$", re.I)
RUN_ID = re.compile(r"\b[0-9a-f]{32}\b|\d{8}T\d{6}(\.\d+)?Z-[0-9a-f]+|\d{8}-\d{6}[-\w]*")


def run(folder: Path) -> None:
    env = {**os.environ, "BODYSCHEMA_THREADS": "1", "MLFLOW_TRACKING_URI": f"sqlite:///{folder}/mlflow.db"}
    folder.mkdir(parents=True, exist_ok=False)
    commands = [DEMO + ["--out", str(folder / "demo")]]
    commands += [["evaluate", *b, "--out", str(folder / "bench" / "-".join(w for w in b if w[0] not in "-0123456789")),
                  "--no-progress"] for b in BENCHMARKS]
    for command in commands:
        print("$ bodyschema", " ".join(command), flush=True)
        subprocess.run([sys.executable, "-m", "bodyschema.cli", *command], env=env, check=True,
                       stdout=subprocess.DEVNULL)


def key(path: Path, root: Path) -> str:
    return RUN_ID.sub("<run>", str(path.relative_to(root)))


def csv_rows(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return [{k: v for k, v in row.items() if k and not VOLATILE.search(k)} for row in csv.DictReader(f)]


def arrays_digest(store: Path) -> str:
    digest = hashlib.sha256()
    for chunk in sorted(p for p in store.rglob("*") if p.is_file() and "/c/" in str(p)):
        digest.update(str(chunk.relative_to(store)).encode() + chunk.read_bytes())
    return digest.hexdigest()


def differences(a: list[dict[str, str]], b: list[dict[str, str]]) -> str:
    if len(a) != len(b) or any(x.keys() != y.keys() for x, y in zip(a, b)):
        return f"{len(a)} vs {len(b)} rows or other columns"
    worst = ""
    for x, y in zip(a, b):
        for column in x:
            if x[column] != y[column]:
                try:
                    rel = abs(float(x[column]) - float(y[column])) / max(abs(float(x[column])), 1e-30)
                    worst = worst or f"{column}: {x[column]} vs {y[column]} (relative {rel:.1e})"
                except ValueError:
                    return f"{column}: {x[column]!r} vs {y[column]!r}"
    return worst


def compare(before: Path, after: Path) -> int:
    found = 0
    for kind, pattern, read in (("csv", "*.csv", csv_rows), ("store", "*.zarr", arrays_digest)):
        old = {key(p, before): p for p in before.rglob(pattern) if "mlartifacts" not in str(p)}
        new = {key(p, after): p for p in after.rglob(pattern) if "mlartifacts" not in str(p)}
        for name in sorted(old.keys() | new.keys()):
            if name not in old or name not in new:
                print(f"{kind:5} only in {'after' if name in new else 'before'}: {name}")
                found += 1
                continue
            a, b = read(old[name]), read(new[name])
            why = "" if a == b else (differences(a, b) if kind == "csv" else "arrays differ")
            print(f"{kind:5} {'identical' if not why else 'DIFFERS'}: {name}{'  ' + why if why else ''}")
            found += bool(why)
    print(f"{found} differ" if found else "all identical")
    return 1 if found else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    sub.add_parser("run").add_argument("folder", type=Path)
    both = sub.add_parser("compare")
    both.add_argument("before", type=Path)
    both.add_argument("after", type=Path)
    o = parser.parse_args()
    if o.what == "run":
        run(o.folder)
        return 0
    return compare(o.before, o.after)


if __name__ == "__main__":
    sys.exit(main())
