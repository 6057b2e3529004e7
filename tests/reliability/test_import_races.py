"""Two writers, one OUT (issue 32, items 1 and 2): `import`, `export` and `datagen` hold OUT's lock
(base/locks.py) for the whole write, check OUT again under it, and move a new output in with a rename that fails
when OUT appeared meanwhile. Whatever the interleaving, one writer wins, the others get the house error, nothing is
lost silently and the store validates.

The interleavings are forced, not hoped for: the first writer is held inside its write (after building its partial,
before the rename) while the second runs to its end; then it is let go. A process test runs real CLI processes at
once, and a kill test kills an import mid-write.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from bodyschema.base import outputs
from bodyschema.base.locks import Locked, lock_path
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.exchange.export import export_dataset
from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.datagen.exchange.importers.run import import_recording
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.schema import open_store
from bodyschema.datagen.store.validate import validate_store
from tests.datagen.import_sources import planar2_frames, write_folder

KINEMATIC = dict(robot="planar2", n=48, shard_size=16, images=False, seed=3)  # no rendering: ~1 s


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> Path:
    """rec_a, rec_b: two recordings (different poses) of planar2, 6 frames each; store.zarr: a kinematic store."""
    w = tmp_path_factory.mktemp("import_races")
    for name, seed in (("rec_a", 0), ("rec_b", 1)):
        q, images = planar2_frames(6, seed=seed)
        write_folder(w / name, q, images)
    generate(DatagenConfig(**KINEMATIC, out=w / "store.zarr"), progress=False)
    return w


def _import(source: Path, out: Path) -> Path:
    return import_recording(ImportConfig(source=source, out=out, angles="deg", robot="planar2"))


class Held:
    """The first `write_atomically` to get here builds its partial, then waits until `release()`; later ones run."""

    def __init__(self, monkeypatch):
        self.built, self.go, self.first = threading.Event(), threading.Event(), True
        original = outputs._write_with_marker

        def held(tmp, write, kind, source):
            original(tmp, write, kind, source)
            if self.first:
                self.first = False
                self.built.set()
                assert self.go.wait(60), "the held writer was never released"

        monkeypatch.setattr(outputs, "_write_with_marker", held)

    def run_first(self, job) -> tuple[threading.Thread, dict]:
        """Start `job` in a thread; return once it holds its partial (or has failed)."""
        result: dict = {}

        def target():
            try:
                result["value"] = job()
            except BaseException as error:  # noqa: BLE001 — reported to the test
                result["error"] = error
            finally:
                self.built.set()

        thread = threading.Thread(target=target)
        thread.start()
        assert self.built.wait(60)
        return thread, result

    def release(self, thread) -> None:
        self.go.set()
        thread.join(60)


def _loser(error: BaseException) -> None:
    """The second writer's error is the house one: OUT is locked by a writer, or already there."""
    assert isinstance(error, (Locked, FileExistsError)), repr(error)
    assert " must be " in str(error), str(error)


def _no_leftovers(out: Path) -> None:
    left = [p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.partial")]
    assert not left, f"partials left beside OUT: {left}"
    assert not lock_path(out).exists(), "the lock file was left beside OUT"


def test_two_imports_to_one_new_out_the_second_is_refused_and_the_first_kept(sources, tmp_path, monkeypatch):
    """Old: both returned and the later import silently replaced the earlier (2/2)."""
    out, held = tmp_path / "new.zarr", Held(monkeypatch)
    thread, first = held.run_first(lambda: _import(sources / "rec_a", out))
    with pytest.raises((Locked, FileExistsError)) as second:
        _import(sources / "rec_b", out)
    _loser(second.value)
    held.release(thread)
    assert "error" not in first, first
    assert validate_store(out) == []
    assert open_store(out).attrs["source"]["path"] == str((sources / "rec_a").resolve())   # the winner's data
    _no_leftovers(out)


def test_a_rename_into_place_fails_when_out_appeared_meanwhile(sources, tmp_path):
    """No lock taken by whoever made OUT (e.g. a user's copy): the import that found OUT absent must not replace it."""
    out = tmp_path / "new.zarr"

    def appear_then_write(tmp):
        out.mkdir()
        (out / "theirs.txt").write_text("kept")
        tmp.mkdir()
        (tmp / "ours.txt").write_text("ours")

    with pytest.raises(FileExistsError, match="must be a path that does not exist yet"):
        outputs.write_atomically(out, appear_then_write, overwrite=False)
    assert (out / "theirs.txt").read_text() == "kept" and not (out / "ours.txt").exists()
    _no_leftovers(out)


def test_two_exports_to_one_target_the_second_is_refused(sources, tmp_path, monkeypatch):
    out, held = tmp_path / "out.h5", Held(monkeypatch)
    thread, first = held.run_first(lambda: export_dataset(sources / "store.zarr", out, "hdf5"))
    with pytest.raises((Locked, FileExistsError)) as second:
        export_dataset(sources / "store.zarr", out, "hdf5")
    _loser(second.value)
    held.release(thread)
    assert "error" not in first, first
    assert out.is_file() and outputs.marker_of(out).get("format")
    _no_leftovers(out)


def test_datagen_into_an_out_an_import_is_writing_is_refused(sources, tmp_path, monkeypatch):
    """Old: datagen created its store at OUT while the import wrote its partial; the import then moved it aside and
    deleted it (both exit 0), or a store validate rejects was left."""
    out, held = tmp_path / "new.zarr", Held(monkeypatch)
    thread, first = held.run_first(lambda: _import(sources / "rec_a", out))
    with pytest.raises(Locked, match=r"must be free .* Got 'locked by pid"):
        generate(DatagenConfig(**KINEMATIC, out=out), progress=False)
    held.release(thread)
    assert "error" not in first, first
    assert validate_store(out) == [] and open_store(out).attrs["sampler"] == "imported"
    _no_leftovers(out)


def test_an_import_into_an_out_datagen_is_writing_is_refused(sources, tmp_path, monkeypatch):
    """datagen holds OUT's lock while it writes the store in place: the import is refused, datagen's store is whole
    (OUT exists already, or, made empty by datagen a moment earlier, is locked)."""
    import bodyschema.datagen.generate as gen

    out, built, go = tmp_path / "new.zarr", threading.Event(), threading.Event()
    original = gen._prepare

    def prepare_then_wait(*args):
        original(*args)
        built.set()
        assert go.wait(60)

    monkeypatch.setattr(gen, "_prepare", prepare_then_wait)
    result: dict = {}
    thread = threading.Thread(target=lambda: result.update(path=generate(DatagenConfig(**KINEMATIC, out=out))))
    thread.start()
    assert built.wait(60)
    try:
        with pytest.raises((Locked, FileExistsError)) as refused:   # OUT exists already, or is locked
            _import(sources / "rec_a", out)
        _loser(refused.value)
    finally:
        go.set()
        thread.join(60)
    assert result.get("path") and validate_store(out) == [] and open_store(out).attrs["sampler"] != "imported"
    _no_leftovers(out)


CLI = [sys.executable, "-m", "bodyschema.cli"]


def test_three_import_processes_to_one_out_exactly_one_wins(sources, tmp_path):
    """Real processes started together (the issue's 3/3 with one source): one exits 0, the others exit 2 with the
    house line and no traceback; the store validates."""
    out = tmp_path / "new.zarr"
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    command = [*CLI, "import", str(sources / "rec_a"), "--angles", "deg", "--robot", "planar2", "--out", str(out)]
    runs = [subprocess.Popen(command, stderr=subprocess.PIPE, text=True, env=env) for _ in range(3)]
    results = [(run.wait(120), run.stderr.read()) for run in runs]
    codes = sorted(code for code, _ in results)
    assert codes == [0, 2, 2], results
    for code, err in results:
        assert "Traceback" not in err, err
        assert code == 0 or " must be " in err, err
    assert validate_store(out) == []
    _no_leftovers(out)


KILLED_CHILD = """
import sys, time
from pathlib import Path
import bodyschema.datagen.exchange.importers.writer as writer
from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.datagen.exchange.importers.run import import_recording
writer.mark_complete = lambda root: time.sleep(600)          # killed here: every shard written, no marker yet
import_recording(ImportConfig(source=Path(sys.argv[1]), out=Path(sys.argv[2]), angles="deg", robot="planar2"))
"""


def test_an_import_killed_mid_write_leaves_no_out_and_the_next_one_succeeds(sources, tmp_path):
    out = tmp_path / "new.zarr"
    child = subprocess.Popen([sys.executable, "-c", KILLED_CHILD, str(sources / "rec_a"), str(out)])
    partial = outputs.partial_path(out.resolve(), child.pid)
    deadline = time.monotonic() + 60
    while not (partial / "q").exists() and child.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert child.poll() is None, "the child ended before it was killed"
    time.sleep(0.3)
    os.kill(child.pid, signal.SIGKILL)
    child.wait()
    assert not out.exists(), "a killed import left OUT"
    _import(sources / "rec_a", out)       # the dead writer's lock and partial are taken over
    assert validate_store(out) == []
    _no_leftovers(out)


@pytest.mark.parametrize("delay_s", [0.0, 0.5, 1.0])
def test_an_import_and_a_datagen_processes_on_one_out_leave_one_valid_store(sources, tmp_path, delay_s):
    """The issue's timings (an import racing a datagen, exit 0 and a store validate rejects in 2 of 6): real
    processes, the import started `delay_s` after datagen. Exactly one exits 0, the other exits 2 with the house
    line; the store validates and is the winner's."""
    out = tmp_path / "new.zarr"
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    datagen = subprocess.Popen([*CLI, "datagen", "--robot", "planar2", "--n", "40000", "--shard-size", "1000",
                                "--no-images", "--out", str(out)], stderr=subprocess.PIPE, text=True, env=env)
    time.sleep(delay_s)
    imported = subprocess.Popen([*CLI, "import", str(sources / "rec_a"), "--angles", "deg", "--robot", "planar2",
                                 "--out", str(out)], stderr=subprocess.PIPE, text=True, env=env)
    results = {name: (run.wait(180), run.stderr.read()) for name, run in (("datagen", datagen),
                                                                          ("import", imported))}
    codes = sorted(code for code, _ in results.values())
    assert codes == [0, 2], results
    assert all("Traceback" not in err and (code == 0 or " must be " in err) for code, err in results.values())
    assert validate_store(out) == []
    winner = "import" if results["import"][0] == 0 else "datagen"
    assert (open_store(out).attrs["sampler"] == "imported") == (winner == "import")
    _no_leftovers(out)
