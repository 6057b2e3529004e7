"""`bodyschema export dataset|onnx` and `bodyschema show` delete nothing but their own outputs and leave nothing
half-written (issue 25).

- --overwrite replaces only a previous export of the same format (its marker beside OUT): never the input store,
  a folder holding it (`..` included), a foreign file or folder, nor another format's export.
- A full disk: refused before writing when the estimate does not fit; a write failing mid-way (EFBIG under
  RLIMIT_FSIZE, a subprocess) is the house error saying "disk full", with no partial file, traceback or crash.
- Partials of killed exports (a pid that is gone) are removed by the next export to the same OUT.
- --opset is checked against the exporter's range; the metadata states the opset the file really has; the
  onnxruntime check runs before the file is written.
- Ctrl-C says what is true; `show --out` must be a .png.
Bad command lines are one line each in CASES, run through the fuzz harness of tests/test_cli_fuzz.py.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch

from bodyschema.base.outputs import marker_path
from bodyschema.cli import after_interrupt, main
from bodyschema.datagen.exchange.export import export_dataset
from tests.limits import file_size_limit
from tests.test_cli_fuzz import build_world, check_clear_failure, run_in_process, snapshot

pytest.importorskip("h5py"), pytest.importorskip("pyarrow")

# {W}: the scratch folder of tests/test_cli_fuzz.py (stores, crafted model folders), as bench/probe.py builds it.
# Every ONNX case is refused before its model is loaded (the pickle_model's payload never runs).
CASES = [
    ("overwrite-the-store", "export dataset --to hdf5 --overwrite {W}/good.zarr {W}/good.zarr"),
    ("overwrite-the-folder-holding-the-store", "export dataset --to lerobot --overwrite {W}/good.zarr {W}"),
    ("overwrite-dotdot", "export dataset --to lerobot --overwrite {W}/good.zarr .."),
    ("overwrite-dotdot-of-a-subfolder", "export dataset --to lerobot --overwrite {W}/good.zarr {W}/notastore/.."),
    ("out-inside-the-store", "export dataset --to hdf5 --overwrite {W}/good.zarr {W}/good.zarr/x.h5"),
    ("overwrite-another-store", "export dataset --to lerobot --overwrite {W}/good.zarr {W}/img.zarr"),
    ("overwrite-a-foreign-file", "export dataset --to hdf5 --overwrite {W}/good.zarr {W}/badjson.zarr/zarr.json"),
    ("overwrite-a-foreign-folder", "export dataset --to lerobot --overwrite {W}/good.zarr {W}/notastore"),
    ("onnx-opset-0", "export onnx trusted:{W}/pickle_model {W}/m.onnx --opset 0"),
    ("onnx-opset-999", "export onnx trusted:{W}/pickle_model {W}/m.onnx --opset 999"),
    ("onnx-opset-negative", "export onnx trusted:{W}/pickle_model {W}/m.onnx --opset -18"),
    ("onnx-overwrite-its-model", "export onnx trusted:{W}/pickle_model {W}/pickle_model --overwrite"),
    ("onnx-overwrite-a-foreign-file", "export onnx trusted:{W}/pickle_model {W}/badjson.zarr/zarr.json --overwrite"),
    ("show-out-txt", "show {W}/img.zarr --out {W}/x.txt"),
    ("show-out-a-store", "show {W}/img.zarr --out {W}/good.zarr"),
]
# these need what `export_world` adds: previous exports, a file swapped in for one, a folder named like a PNG
CASES_WITH_EXPORTS = [
    ("overwrite-another-format", "export dataset --to hdf5 --overwrite {W}/good.zarr {W}/prev_lerobot"),
    ("overwrite-a-swapped-in-file", "export dataset --to hdf5 --overwrite {W}/good.zarr {W}/swapped.h5"),
    ("existing-without-overwrite", "export dataset --to hdf5 {W}/good.zarr {W}/prev.h5"),
    ("onnx-overwrite-another-format", "export onnx trusted:{W}/mdn_model {W}/prev.h5 --overwrite"),
    ("show-out-a-folder-named-png", "show {W}/img.zarr --out {W}/folder.png"),
]


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    return make_world(tmp_path_factory.mktemp("export_fuzz"))


def make_world(w: Path) -> Path:
    """The fuzz world plus: previous exports (one replaced by a foreign file), a folder named like a PNG and a tiny
    MDN model."""
    from bodyschema.models.mdn import MDNModel
    from bodyschema.models.scaling import BodySpec

    build_world(w)
    export_dataset(w / "good.zarr", w / "prev.h5", "hdf5")
    export_dataset(w / "good.zarr", w / "prev_lerobot", "lerobot")
    export_dataset(w / "good.zarr", w / "swapped.h5", "hdf5")
    (w / "swapped.h5").write_text("a file put where an export was; its marker is still beside it")
    (w / "folder.png").mkdir()
    body = BodySpec("toy", ("a", "b"), (-1.0, -1.0), (1.0, 1.0))
    q = torch.rand(40, 2, generator=torch.Generator().manual_seed(0)) * 2 - 1
    MDNModel(body, "ee_xyz", (3,), hidden=(8,), epochs=2).fit(q, torch.cat([q, q.sum(1, True)], 1),
                                                              progress=False).save(w / "mdn_model")
    return w


@pytest.mark.parametrize("case_id, command", CASES + CASES_WITH_EXPORTS,
                         ids=[c[0] for c in CASES + CASES_WITH_EXPORTS])
def test_bad_export_is_a_clear_error_and_deletes_nothing(case_id, command, in_world, capsys):
    before, around = snapshot(in_world), sorted(p.name for p in in_world.parent.iterdir())
    code, err = run_in_process(command.format(W=in_world).split(), capsys)
    check_clear_failure(case_id, code, err, before, snapshot(in_world), in_world)
    assert sorted(p.name for p in in_world.parent.iterdir()) == around, f"{case_id}: the folder above changed"


# ---- what --overwrite does replace -------------------------------------------------------------------------
@pytest.mark.parametrize("to", ["hdf5", "lerobot"])
def test_overwrite_replaces_a_previous_export_and_leaves_only_it(world, tmp_path, to):
    out = tmp_path / "out"
    export_dataset(world / "good.zarr", out, to)
    export_dataset(world / "img.zarr", out, to, overwrite=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == [marker_path(out).name, "out"]      # no partial, no old one
    if to == "hdf5":
        import h5py
        with h5py.File(out, "r") as f:
            assert "image" in f                                     # the second store's export, not the first's
    else:
        assert any("images" in p.read_text() for p in (out / "meta").glob("info.json"))


# ---- a full disk -------------------------------------------------------------------------------------------
def test_the_free_space_is_checked_before_anything_is_written(world, tmp_path, monkeypatch):
    import bodyschema.base.outputs as outputs

    monkeypatch.setattr(outputs.shutil, "disk_usage", lambda _: SimpleNamespace(free=1000))   # bytes
    with pytest.raises(OSError, match=r"free space beside OUT must be >= .* MB .*Got '0.0 MB free"):
        export_dataset(world / "img.zarr", tmp_path / "d.h5", "hdf5")
    assert list(tmp_path.iterdir()) == []


FULL_DISK = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)      # a write past the limit then fails with EFBIG, as on a full disk
resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
from bodyschema.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("to", ["hdf5", "lerobot"])
def test_a_write_failing_for_space_is_a_disk_full_error_and_leaves_nothing(world, tmp_path, to):
    """In a subprocess: HDF5 used to print tracebacks from destructors and then crash the process."""
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}
    argv = ["export", "dataset", "--to", to, str(world / "img.zarr"), str(tmp_path / "out")]
    result = subprocess.run([sys.executable, "-c", FULL_DISK.format(limit=2048), *argv], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, f"exit {result.returncode} (a negative one is a crash):\n{result.stderr}"
    assert "Traceback" not in result.stderr and "disk full" in result.stderr, result.stderr
    assert list(tmp_path.iterdir()) == [], "a partial output was left"


def test_an_onnx_write_failing_for_space_leaves_no_partial(world, tmp_path):
    pytest.importorskip("onnxruntime"), pytest.importorskip("onnxscript")
    from bodyschema.models.contract import load_model
    from bodyschema.models.onnx_export import export_onnx

    model = load_model(world / "mdn_model")
    with file_size_limit(2048), pytest.raises(OSError, match="disk full"):
        export_onnx(model, tmp_path / "m.onnx")
    assert list(tmp_path.iterdir()) == []




# ---- leftovers of killed exports ---------------------------------------------------------------------------
def test_partials_of_dead_exports_are_removed_and_a_live_ones_kept(world, tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid, live_pid = int(dead.stdout), os.getppid()          # the first has exited; pytest's parent runs
    stale = [tmp_path / f".d.h5.partial-{dead_pid}", tmp_path / f".d.h5.partial-{dead_pid}.json",
             tmp_path / ".d.h5.partial"]                          # the last: an older export's name, without a pid
    for path in stale:
        path.write_bytes(b"half an export")
    (tmp_path / f".d.h5.partial-{dead_pid}.old").mkdir()
    live = tmp_path / f".d.h5.partial-{live_pid}"
    live.write_bytes(b"being written")
    export_dataset(world / "good.zarr", tmp_path / "d.h5", "hdf5")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, ".d.h5.bodyschema-output.json", "d.h5"])


def test_ctrl_c_during_an_export_leaves_nothing_and_says_so(world, tmp_path, monkeypatch, capsys):
    from bodyschema.datagen.exchange import export

    def interrupted(root, out):
        out.write_bytes(b"half")
        raise KeyboardInterrupt

    kind, size_factor, _ = export.WRITERS["hdf5"]
    monkeypatch.setitem(export.WRITERS, "hdf5", (kind, size_factor, interrupted))     # the format table's writer
    code = main(["export", "dataset", "--to", "hdf5", str(world / "good.zarr"), str(tmp_path / "d.h5")])
    err = capsys.readouterr().err
    assert code == 130 and "Nothing was written" in err and "resume" not in err, err
    assert list(tmp_path.iterdir()) == []


def test_after_ctrl_c_only_the_commands_that_resume_say_resume():
    assert "resume" in after_interrupt("bodyschema datagen --n 5")
    assert "resume" in after_interrupt("bodyschema train gpr")
    for command in ("bodyschema export dataset", "bodyschema export onnx", "bodyschema evaluate levels",
                    "bodyschema import x", "bodyschema"):
        assert "resume" not in after_interrupt(command), command


# ---- ONNX: the opset, and the check before the file --------------------------------------------------------
@pytest.mark.parametrize("opset", [12, 17])
def test_the_metadata_states_the_opset_the_file_has(world, tmp_path, opset):
    """torch builds opset 18 and converts: a conversion it cannot do is refused, never written as another opset."""
    pytest.importorskip("onnxruntime"), pytest.importorskip("onnxscript")
    from bodyschema.models.contract import load_model
    from bodyschema.models.onnx_export import export_onnx, read_metadata

    out = tmp_path / "m.onnx"
    try:
        export_onnx(load_model(world / "mdn_model"), out, opset=opset)
    except ValueError as error:
        assert "--opset must be an opset this graph converts to" in str(error) and not out.exists()
        return
    meta = read_metadata(out)
    assert meta["opset"] == meta["bodyschema.opset"] == str(opset)


@pytest.mark.parametrize("failure", ["out of tolerance", "onnxruntime fails"])
def test_the_onnxruntime_check_runs_before_the_file_is_written(world, tmp_path, monkeypatch, failure):
    pytest.importorskip("onnxruntime"), pytest.importorskip("onnxscript")
    import bodyschema.models.onnx_export as onnx_export
    from bodyschema.models.contract import load_model

    def check(model, graph, **_):
        assert isinstance(graph, bytes)                             # the graph in memory, not a file at OUT
        if failure == "onnxruntime fails":
            raise RuntimeError("onnxruntime could not run the graph")
        return 1.0

    monkeypatch.setattr(onnx_export, "verify_onnx", check)
    with pytest.raises((FloatingPointError, RuntimeError)):
        onnx_export.export_onnx(load_model(world / "mdn_model"), tmp_path / "m.onnx")
    assert list(tmp_path.iterdir()) == []
