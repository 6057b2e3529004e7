"""Fuzz-style: bad inputs to every subcommand end as a clear error, never as a traceback or a half-written output.

Each case runs `bodyschema.cli.main(argv)` in-process (a few also as a real process) in a scratch folder that holds
a valid store, damaged stores and crafted model directories. For each: exit code 2 (1 for `validate` answering
"this store has problems"), a house message (" must be ") or tyro's parse message on stderr, no traceback, and
not one file of the folder added, removed or changed. Adding a case is one line in CASES.
"""

from __future__ import annotations

import json
import os
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bodyschema.cli import main

# (id, argv; {W} is the scratch folder). Stores: good (kinematics), img (images), trunc (an image chunk cut in
# half), holed (an image chunk deleted), badjson (zarr.json not JSON). Models: pickle_model (state.pt is a pickle
# whose payload runs a shell command), badmeta_model (meta.json without "kind"), garbage_model (state.pt noise);
# a bare directory is refused unless its digest is registered, `trusted:<dir>` skips that check to reach the reader.
CASES = [
    ("datagen-n-abc", "datagen --n abc --out {W}/new.zarr"),
    ("datagen-n-0", "datagen --n 0 --out {W}/new.zarr"),
    ("datagen-n-negative", "datagen --n -5 --out {W}/new.zarr"),
    ("datagen-n-huge", "datagen --n 1000000000000 --out {W}/new.zarr"),
    ("datagen-robot-unknown", "datagen --robot mars --out {W}/new.zarr"),
    ("datagen-sampler-unknown", "datagen --sampler nope --out {W}/new.zarr"),
    ("datagen-image-size-0", "datagen --image-size 0 0 --n 4 --out {W}/new.zarr"),
    ("datagen-gravity-nan", "datagen --gravity nan --n 4 --out {W}/new.zarr"),
    ("datagen-gravity-inf", "datagen --gravity inf --n 4 --out {W}/new.zarr"),
    ("datagen-ranges-reversed", "datagen --ranges 1 0 0 1 --n 4 --out {W}/new.zarr"),
    ("datagen-workers-0", "datagen --workers 0 --n 4 --out {W}/new.zarr"),
    ("datagen-record-hz-0", "datagen --sampler babble --record-hz 0 --n 4 --out {W}/new.zarr"),
    ("datagen-hold-reversed", "datagen --sampler babble --hold-s 1 0 --n 4 --out {W}/new.zarr"),
    ("datagen-other-config", "datagen --robot planar2 --n 32 --no-images --out {W}/good.zarr"),
    ("validate-no-path", "validate"),
    ("validate-missing", "validate {W}/missing.zarr"),
    ("validate-not-a-store", "validate {W}/notastore"),
    ("validate-truncated-chunk", "validate {W}/trunc.zarr"),
    ("validate-deleted-chunk", "validate {W}/holed.zarr"),
    ("validate-bad-json", "validate {W}/badjson.zarr"),
    ("train-kind-unknown", "train nope --data {W}/good.zarr"),
    ("train-data-missing", "train gpr --data {W}/missing.zarr"),
    ("train-data-not-a-store", "train gpr --data {W}/notastore"),
    ("train-data-bad-json", "train gpr --data {W}/badjson.zarr"),
    ("train-modality-unknown", "train gpr --data {W}/good.zarr --modality smell"),
    ("train-hyper-epochs-abc", "train mdn --data {W}/good.zarr --epochs abc"),
    ("train-hyper-lr-nan", "train mdn --data {W}/good.zarr --lr nan"),
    ("train-hyper-lr-inf", "train gpr --data {W}/good.zarr --lr 1e999"),
    ("train-hyper-epochs-negative", "train mdn --data {W}/good.zarr --epochs -3"),
    ("train-hyper-epochs-0", "train mdn --data {W}/good.zarr --epochs 0"),
    ("train-hyper-hidden-word", "train mdn --data {W}/good.zarr --hidden wide"),
    ("train-hyper-mode-unknown", "train mdn --data {W}/good.zarr --mode median"),
    ("train-hyper-unknown", "train gpr --data {W}/good.zarr --bogus 1"),
    ("train-hyper-of-another-kind", "train gpr --data {W}/good.zarr --epochs 5"),
    ("train-old-model-flag", "train --model gpr --data {W}/good.zarr"),
    ("train-old-hyper-flag", "train mdn --data {W}/good.zarr --hyper epochs 5"),
    ("train-tracking-bad-scheme", "train gpr --data {W}/good.zarr --tracking-uri notascheme://x"),
    ("train-tracking-unreachable", "train gpr --data {W}/good.zarr --tracking-uri http://127.0.0.1:9"),
    ("train-val-fraction", "train gpr --data {W}/good.zarr --val-fraction 1.5"),
    ("train-seed-negative", "train gpr --data {W}/good.zarr --seed -1"),
    ("train-max-train-0", "train gpr --data {W}/good.zarr --max-train 0"),
    ("train-pixel-no-images", "train pixel --data {W}/good.zarr"),
    ("train-gp-on-images", "train gpr --modality image --data {W}/img.zarr"),
    ("train-truncated-chunk", "train mdn --modality image --data {W}/trunc.zarr"),
    ("train-deleted-chunk", "train pixel --data {W}/holed.zarr"),
    ("train-multimodal-unknown", "train multimodal --modality ee_xyz,smell --data {W}/good.zarr"),
    ("registry-list-bad-scheme", "registry list --tracking-uri notascheme://x"),
    ("registry-list-unreachable", "registry list --tracking-uri http://127.0.0.1:9"),
    ("registry-promote-version-abc", "registry promote bodyschema-x abc"),
    ("registry-promote-bad-scheme", "registry promote bodyschema-x 1 --tracking-uri notascheme://x"),
    ("levels-spec-unknown", "evaluate levels --model nope:spec --out {W}/res"),
    ("levels-spec-short", "evaluate levels --model analytic:planar2 --out {W}/res"),
    ("levels-spec-robot", "evaluate levels --model analytic:mars:ee_xyz --out {W}/res"),
    ("levels-spec-modality", "evaluate levels --model analytic:planar2:smell --out {W}/res"),
    ("levels-registry-bad-scheme", "evaluate levels --model models:/bodyschema-x@champion --no-mlflow "
                                   "--tracking-uri notascheme://x --out {W}/res"),
    ("levels-pickle-state", "evaluate levels --model {W}/pickle_model --out {W}/res"),
    ("levels-pickle-state-trusted", "evaluate levels --model trusted:{W}/pickle_model --out {W}/res"),
    ("levels-garbage-state", "evaluate levels --model trusted:{W}/garbage_model --out {W}/res"),
    ("levels-bad-meta", "evaluate levels --model trusted:{W}/badmeta_model --out {W}/res"),
    ("levels-unregistered-dir", "evaluate levels --model {W}/garbage_model --out {W}/res"),
    ("levels-trials-0", "evaluate levels --trials 0 --out {W}/res"),
    ("levels-level-7", "evaluate levels --levels 7 --out {W}/res"),
    ("levels-noise-nan", "evaluate levels --noise ee_xyz nan --trials 2 --runs 1 --out {W}/res"),
    ("levels-noise-negative", "evaluate levels --noise ee_xyz -1 --trials 2 --runs 1 --out {W}/res"),
    ("levels-tracking-bad-scheme", "evaluate levels --trials 2 --runs 1 --tracking-uri notascheme://x --out {W}/res"),
    ("robustness-sigma-nan", "evaluate robustness --sigmas nan --out {W}/res"),
    ("robustness-modality", "evaluate robustness --modality smell --out {W}/res"),
    ("reaching-robot", "evaluate reaching --robot mars --out {W}/res"),
    ("reaching-trials-0", "evaluate reaching --trials 0 --out {W}/res"),
    ("reaching-goal", "evaluate reaching --goal smell --out {W}/res"),
    ("loop-robustness-sigma-negative", "evaluate loop-robustness --sigmas -1 --out {W}/res"),
    ("marker-shift-unknown", "evaluate adaptation marker-shift --shifts up --out {W}/res"),
    ("jupiter-control-rate", "evaluate adaptation jupiter --control-rate 333 --out {W}/res"),
    ("jupiter-trials-negative", "evaluate adaptation jupiter --trials -1 --out {W}/res"),
    ("self-recognition-trials-0", "evaluate self-recognition --trials 0 --out {W}/res"),
    ("self-recognition-source", "evaluate self-recognition --sources alien --out {W}/res"),
    ("report-missing", "report --results {W}/missing"),
    ("report-stale-nan", "report --results {W}/res --stale-after-s nan"),
    ("demo-n-nao-0", "demo --n-nao 0 --out {W}/demo"),
    ("demo-workers-0", "demo --workers 0 --out {W}/demo"),
    ("demo-tracking-bad-scheme", "demo --tracking-uri notascheme://x --out {W}/demo"),
    ("command-unknown", "frobnicate"),
]
VALIDATE_ANSWERS = {"validate-not-a-store", "validate-truncated-chunk", "validate-deleted-chunk",
                    "validate-bad-json"}                 # exit 1: "this store has problems" is validate's answer
TYRO_PHRASES = ("Error parsing", "Invalid choice", "Required options", "Unrecognized options", "Value error")
SUBPROCESS = ["datagen-n-abc", "train-hyper-epochs-abc", "levels-pickle-state-trusted"]   # the real console entry point


class _Payload:
    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    return build_world(tmp_path_factory.mktemp("fuzz"))


def build_world(w: Path) -> Path:
    """The scratch folder of CASES (also used by bench-style tallies run outside pytest)."""
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.generate import generate

    generate(DatagenConfig(robot="planar2", n=64, images=False, shard_size=32, out=w / "good.zarr"), progress=False)
    generate(DatagenConfig(robot="planar2", n=16, shard_size=8, out=w / "img.zarr"), progress=False)
    for name in ("trunc", "holed"):
        shutil.copytree(w / "img.zarr", w / f"{name}.zarr")
    chunk = next(p for p in sorted((w / "trunc.zarr" / "image").rglob("*")) if p.is_file() and p.name != "zarr.json")
    chunk.write_bytes(chunk.read_bytes()[: chunk.stat().st_size // 2])
    (w / "holed.zarr" / chunk.relative_to(w / "trunc.zarr")).unlink()
    shutil.copytree(w / "good.zarr", w / "badjson.zarr")
    (w / "badjson.zarr" / "zarr.json").write_text("{ not json")
    (w / "notastore").mkdir()
    meta = {"format_version": 1, "kind": "gpr", "modality": "ee_xyz", "output_shape": [3], "body": {}, "config": {}}
    for name, state in (("pickle_model", pickle.dumps(_Payload(w / "PWNED"))), ("garbage_model", os.urandom(256))):
        (w / name).mkdir()
        (w / name / "meta.json").write_text(json.dumps(meta))
        (w / name / "state.pt").write_bytes(state)
    (w / "badmeta_model").mkdir()
    (w / "badmeta_model" / "meta.json").write_text(json.dumps({"format_version": 1}))
    (w / "badmeta_model" / "state.pt").write_bytes(b"")
    return w


# The default tracking store may be created or migrated by a command that talks to MLflow: it is not an output.
TRACKING_STORE = {"mlflow.db", "mlflow.db.lock"}


def snapshot(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")
            if p.is_file() and p.name not in TRACKING_STORE}


def run_in_process(argv: list[str], capsys) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exit_:                         # tyro's parsing errors
        code = exit_.code
    return code, capsys.readouterr().err


def check_clear_failure(case_id: str, code: int, err: str, before: dict, after: dict, world: Path) -> None:
    assert "Traceback" not in err, f"{case_id}: a traceback reached the user:\n{err}"
    allowed = {1, 2} if case_id in VALIDATE_ANSWERS else {2}
    assert code in allowed, f"{case_id}: exit code {code}, expected {allowed}; stderr:\n{err}"
    assert " must be " in err or any(p in err for p in TYRO_PHRASES), f"{case_id}: no clear message:\n{err}"
    changed = sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))
    assert not changed, f"{case_id}: a refused command wrote {changed[:5]}"
    assert not (world / "PWNED").exists(), f"{case_id}: a crafted pickle ran its payload"


def run_and_check(case_id: str, command: str, world: Path, capsys) -> str:
    """Run one bad-input case in-process in `world` ({W} in the command), check it failed clearly and wrote nothing.
    Returns its stderr."""
    before = snapshot(world)
    code, err = run_in_process(command.format(W=world).split(), capsys)
    check_clear_failure(case_id, code, err, before, snapshot(world), world)
    return err


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_a_clear_error(case_id, command, in_world, capsys):
    run_and_check(case_id, command, in_world, capsys)


@pytest.mark.parametrize("case_id", SUBPROCESS)
def test_bad_input_through_the_console_script(case_id, in_world):
    command = dict(CASES)[case_id].format(W=in_world).split()
    before = snapshot(in_world)
    env = {k: v for k, v in os.environ.items() if k not in ("MLFLOW_TRACKING_URI", "BODYSCHEMA_DEBUG")}
    result = subprocess.run([sys.executable, "-m", "bodyschema.cli", *command], cwd=in_world, env=env,
                            capture_output=True, text=True, timeout=120)
    check_clear_failure(case_id, result.returncode, result.stderr, before, snapshot(in_world), in_world)


def test_there_are_at_least_40_cases_covering_every_subcommand():
    from tests.test_cli import SUBCOMMANDS

    assert len(CASES) >= 40
    for words in SUBCOMMANDS:
        assert any(command.split()[: len(words)] == words for _, command in CASES), f"no bad input for {words}"
