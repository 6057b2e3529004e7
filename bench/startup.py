"""Start-up time of the CLI, as a ratio against `python -c pass`, side by side in one run.

    .venv/bin/python bench/startup.py [--repeats 7] [--before COMMIT]

Times (wall clock, median of the repeats, each repeat running every command once in turn, so a varying machine
load hits all of them alike) `python -c pass` (the baseline), `bodyschema --help`, `bodyschema train --help` and
`bodyschema evaluate levels --help`, and prints each command's median and its ratio to the baseline. The target
(issue 15): `bodyschema --help` under 1 s; each subcommand imports only its own stage (`evaluate levels` needs
torch, `--help` and `train --help` do not).

--before COMMIT: the same commands run from that commit's source tree too (unpacked with `git archive` into a
temporary folder and imported from there, the installed dependencies shared), e.g. `--before HEAD~5`.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
COMMANDS = (("--help",), ("train", "--help"), ("evaluate", "levels", "--help"))
ENTRY = "import sys; from bodyschema.cli import main; sys.argv[0] = 'bodyschema'; sys.exit(main())"


def timed(argv: list[str], env: dict[str, str] | None = None) -> float:
    start = time.perf_counter()
    done = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=tempfile.gettempdir())
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({done.returncode}):\n{done.stderr.decode()[-2000:]}")
    return seconds


def source_tree(commit: str, into: Path) -> dict[str, str]:
    """An importable `bodyschema` from `commit` (its pyproject's package-dir mapping as symlinks): the env to run it."""
    archive = subprocess.run(["git", "-C", str(REPO), "archive", commit], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    mapping = tomllib.loads((into / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    root = into / "_importable"
    (root / "bodyschema").mkdir(parents=True)
    for package, folder in mapping.items():
        parts = package.split(".")
        if len(parts) == 1:             # bodyschema itself: its files, beside the subpackage links
            for item in (into / folder).iterdir():
                (root / "bodyschema" / item.name).symlink_to(item)
        else:
            (root / "bodyschema" / parts[1]).symlink_to(into / folder)
    return {**os.environ, "PYTHONPATH": str(root)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--before", default=None, help="a commit to time beside the working tree")
    args = parser.parse_args()

    script = Path(sys.executable).with_name("bodyschema")
    runs = {"python -c pass": ([sys.executable, "-c", "pass"], None)}
    runs |= {"bodyschema " + " ".join(c): ([str(script), *c], None) for c in COMMANDS}
    with tempfile.TemporaryDirectory() as tmp:
        if args.before:
            env = source_tree(args.before, Path(tmp))
            runs |= {f"[{args.before}] bodyschema " + " ".join(c): ([sys.executable, "-c", ENTRY, *c], env)
                     for c in COMMANDS}
        for argv, env in runs.values():            # warm the file cache and the .pyc files first
            timed(argv, env)
        times: dict[str, list[float]] = {name: [] for name in runs}
        for _ in range(args.repeats):
            for name, (argv, env) in runs.items():
                times[name].append(timed(argv, env))
    base = statistics.median(times["python -c pass"])
    print(f"start-up, median of {args.repeats} (wall clock, {os.cpu_count()} CPUs):")
    for name, values in times.items():
        median = statistics.median(values)
        print(f"  {name:<55} {median:7.3f} s   {median / base:6.1f} × python -c pass")


if __name__ == "__main__":
    main()
