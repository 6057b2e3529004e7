"""Malformed recordings of every source `bodyschema import` reads (issue 32, items 3, 4, 11 and the messages):
images that are not 8-bit or not 1/3 channels, a CSV naming a joint twice or with a fractional or huge episode,
own-format HDF5 and LeRobot folders missing or mistyping what they need, image paths leaving the recording. Each is
the house error naming the file, exit 2, no traceback and nothing written (the fuzz harness of
tests/test_cli_fuzz.py, as tests/reliability/test_import.py). Adding a case is one line in CASES."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.datagen.import_sources import planar2_frames, write_demo_hdf5, write_folder
from tests.test_cli_fuzz import run_and_check, run_in_process

pytest.importorskip("pyarrow")

OUT = " --out {W}/new.zarr"
DEMO = " --angles rad --robot planar2 --joint-key joint_pos --image-key agentview_image" + OUT
FOLDER = " --angles deg --robot planar2" + OUT
LEROBOT = " --angles rad --robot planar2" + OUT
CASES = [
    # item 3: pixels that are not 8-bit, or not gray / RGB, from every source
    ("hdf5-float-image", "import {W}/float.h5" + DEMO),
    ("hdf5-uint16-image", "import {W}/u16.h5" + DEMO),
    ("hdf5-int16-image", "import {W}/i16.h5" + DEMO),
    ("hdf5-two-channel-image", "import {W}/two_channels.h5" + DEMO),
    ("lerobot-16-bit-png", "import {W}/lr_u16" + LEROBOT),
    # item 4: the CSV
    ("csv-joint-named-twice", "import {W}/twice" + FOLDER),
    ("csv-episode-fraction", "import {W}/episode_fraction" + FOLDER),
    ("csv-episode-huge", "import {W}/episode_huge" + FOLDER),
    ("csv-latin-1", "import {W}/latin1" + FOLDER),
    ("csv-negative-t", "import {W}/negative_t" + FOLDER),
    ("csv-image-absolute-path", "import {W}/absolute" + FOLDER),
    ("csv-image-leaves-the-folder", "import {W}/dotdot" + FOLDER),
    # item 11: own-format HDF5 and demo HDF5 structure
    ("own-hdf5-without-store-attrs", "import {W}/own_no_attrs.h5" + OUT),
    ("own-hdf5-q-a-group", "import {W}/own_q_group.h5" + OUT),
    ("own-hdf5-store-attrs-not-json", "import {W}/own_attrs_text.h5" + OUT),
    ("demo-joint-key-a-group", "import {W}/key_group.h5" + DEMO),
    ("demo-q-strings", "import {W}/q_strings.h5" + DEMO),
    ("demo-empty-episode", "import {W}/empty_episode.h5" + DEMO),
    ("demo-ee-width-2", "import {W}/ee2.h5 --ee-key eef_pos" + DEMO),
    # item 11: LeRobot structure
    ("lerobot-info-a-list", "import {W}/lr_info_list" + LEROBOT),
    ("lerobot-features-a-list", "import {W}/lr_features_list" + LEROBOT),
    ("lerobot-feature-a-string", "import {W}/lr_feature_string" + LEROBOT),
    ("lerobot-bodyschema-json-a-list", "import {W}/lr_ours_list" + LEROBOT),
    ("lerobot-no-index-column", "import {W}/lr_no_index" + LEROBOT),
    ("lerobot-no-episode-index", "import {W}/lr_no_episode" + LEROBOT),
    ("lerobot-no-timestamp", "import {W}/lr_no_timestamp" + LEROBOT),
    ("lerobot-video-not-in-episodes", "import {W}/lr_video" + LEROBOT),
    ("lerobot-state-strings", "import {W}/lr_state_strings" + LEROBOT),
]


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return make_world(tmp_path_factory.mktemp("import_sources"))


def make_world(w: Path) -> Path:
    q, images = planar2_frames(6)
    _hdf5(w, q, images)
    _folders(w, q, images)
    _lerobot(w)
    return w


def _hdf5(w: Path, q: np.ndarray, images: np.ndarray) -> None:
    write_demo_hdf5(w / "good.h5", q, images, episodes=2)
    pixels = {"float": images.astype(np.float32) / 255, "u16": images.astype(np.uint16) * 257,
              "i16": images.astype(np.int16), "two_channels": np.stack([images, images], axis=-1)}
    for name, frames in pixels.items():
        write_demo_hdf5(w / f"{name}.h5", q, frames, episodes=2)
    _demo_edit(w / "good.h5", w / "key_group.h5", lambda obs: (obs.__delitem__("joint_pos"),
                                                              obs.create_group("joint_pos")))
    _demo_edit(w / "good.h5", w / "q_strings.h5", lambda obs: (
        obs.__setitem__("q_text", np.array([b"a", b"b", b"c"])), obs.__delitem__("joint_pos"),
        obs.move("q_text", "joint_pos")))
    _demo_edit(w / "good.h5", w / "empty_episode.h5", lambda obs: _empty(obs))
    write_demo_hdf5(w / "ee2.h5", q, images, episodes=2, ee=np.zeros((len(q), 2)))
    _own(w)


def _demo_edit(src: Path, dst: Path, edit) -> None:
    """A copy of the demo file with data/demo_0/obs edited."""
    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as f:
        edit(f["data/demo_0/obs"])


def _empty(obs) -> None:
    for key in list(obs):
        shape = obs[key].shape
        del obs[key]
        obs[key] = np.zeros((0, *shape[1:]), np.uint8 if key == "agentview_image" else float)


def _own(w: Path) -> None:
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.exchange.export import export_dataset
    from bodyschema.datagen.generate import generate

    store = generate(DatagenConfig(robot="planar2", n=8, images=False, out=w / "tmp_store.zarr"), progress=False)
    export_dataset(store, w / "own.h5", "hdf5")
    shutil.rmtree(store)
    edits = {"own_no_attrs.h5": lambda f: f.attrs.__delitem__("store_attrs"),
             "own_attrs_text.h5": lambda f: f.attrs.__setitem__("store_attrs", "not json {"),
             "own_q_group.h5": lambda f: (f.__delitem__("q"), f.create_group("q"))}
    for name, edit in edits.items():
        shutil.copy(w / "own.h5", w / name)
        with h5py.File(w / name, "r+") as f:
            edit(f)
    (w / "own.h5").unlink()


def _folders(w: Path, q: np.ndarray, images: np.ndarray) -> None:
    write_folder(w / "rec", q, images)
    _csv(w, "twice", q, images, lambda rows: [r + [r[0]] for r in rows], header="shoulder,elbow,shoulder")
    _csv(w, "episode_fraction", q, images, lambda rows: [r + ["0.143"] for r in rows], header="shoulder,elbow,episode")
    _csv(w, "episode_huge", q, images, lambda rows: [r + ["1e12"] for r in rows], header="shoulder,elbow,episode")
    _csv(w, "negative_t", q, images, lambda rows: [r + [str(i - 3.0)] for i, r in enumerate(rows)],
         header="shoulder,elbow,t")
    _csv(w, "absolute", q, images, lambda rows: [r + [str(w / "rec" / f"img{i}.png")] for i, r in enumerate(rows)],
         header="shoulder,elbow,image")
    _csv(w, "dotdot", q, images, lambda rows: [r + [f"../rec/img{i}.png"] for i, r in enumerate(rows)],
         header="shoulder,elbow,image")
    write_folder(w / "latin1", q, images)
    text = (w / "latin1" / "angles.csv").read_text().replace("shoulder", "shoulder (\u00b0)", 1)
    (w / "latin1" / "angles.csv").write_bytes(text.encode("latin-1"))


def _csv(w: Path, name: str, q, images, edit, header: str) -> None:
    """A recording whose angles.csv has `header` and the rows `edit` makes of the good rows (as lists of cells)."""
    folder = write_folder(w / name, q, images)
    rows = [line.split(",") for line in (folder / "angles.csv").read_text().splitlines()[1:]]
    (folder / "angles.csv").write_text("\n".join([header, *(",".join(r) for r in edit(rows))]) + "\n")


def _lerobot(w: Path) -> None:
    """lr: this project's LeRobot export of a planar2 store with images, then copies each missing or mistyping one
    thing."""
    import pyarrow.parquet as pq

    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.exchange.export import export_dataset
    from bodyschema.datagen.generate import generate

    store = generate(DatagenConfig(robot="planar2", n=6, image_size=(16, 16), out=w / "tmp_img.zarr"),
                     progress=False)
    export_dataset(store, w / "lr", "lerobot")
    shutil.rmtree(store)

    def copy(name: str) -> Path:
        shutil.copytree(w / "lr", w / name)
        return w / name

    def edit_info(name: str, edit) -> None:
        path = copy(name) / "meta" / "info.json"
        path.write_text(json.dumps(edit(json.loads(path.read_text()))))

    def edit_frames(name: str, edit) -> None:
        for path in sorted((copy(name) / "data").glob("chunk-*/file-*.parquet")):
            pq.write_table(edit(pq.read_table(path)), path)

    (copy("lr_info_list") / "meta" / "info.json").write_text("[]")
    (copy("lr_ours_list") / "meta" / "bodyschema.json").write_text("[1]")
    edit_info("lr_features_list", lambda info: {**info, "features": list(info["features"])})
    edit_info("lr_feature_string", lambda info: {**info, "features": {**info["features"],
                                                                      "observation.state": "float32"}})
    edit_info("lr_video", lambda info: {**info, "features": {
        k: {**f, "dtype": "video"} if f.get("dtype") == "image" else f for k, f in info["features"].items()}})
    edit_frames("lr_no_index", lambda t: t.drop(["index"]))
    (copy("lr_foreign") / "meta" / "bodyschema.json").unlink()       # a dataset LeRobot wrote: no record of ours
    for name, column in (("lr_no_episode", "episode_index"), ("lr_no_timestamp", "timestamp")):
        shutil.copytree(w / "lr_foreign", w / name)
        for path in sorted((w / name / "data").glob("chunk-*/file-*.parquet")):
            pq.write_table(pq.read_table(path).drop([column]), path)
    edit_frames("lr_state_strings", _state_as_strings)
    edit_frames("lr_u16", _images_16_bit)


def _image_key(table) -> str:
    return next(name for name in table.column_names if name.startswith("observation.image"))


def _state_as_strings(table):
    import pyarrow as pa

    i = table.column_names.index("observation.state")
    return table.set_column(i, "observation.state", pa.array([["a", "b"]] * len(table)))


def _images_16_bit(table):
    import cv2
    import pyarrow as pa

    key = _image_key(table)
    ok, png = cv2.imencode(".png", np.full((16, 16), 1000, np.uint16))
    cells = [{**cell, "bytes": png.tobytes()} for cell in table.column(key).to_pylist()]
    return table.set_column(table.column_names.index(key), key, pa.array(cells, table.schema.field(key).type))


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_malformed_source_is_a_clear_error_and_writes_nothing(case_id, command, in_world, capsys):
    run_and_check(case_id, command, in_world, capsys)


@pytest.mark.parametrize("source, flags", [("good.h5", DEMO), ("rec", FOLDER), ("lr", LEROBOT),
                                           ("lr_foreign", LEROBOT)])
def test_the_good_sources_of_the_world_import(source, flags, in_world, capsys):
    """The cases fail for their one defect: the source they were made from imports and validates."""
    code, err = run_in_process(f"import {in_world}/{source}{flags}".format(W=in_world).split(), capsys)
    assert code == 0, err
    shutil.rmtree(in_world / "new.zarr")


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_the_message_names_the_file_and_speaks_of_the_recording(case_id, command, in_world, capsys):
    """The line names the recording read (its file, folder or CSV) and does not blame datagen ("rerun datagen",
    "the generator wrote impossible values": wrong for an import)."""
    err = run_and_check(case_id, command, in_world, capsys)
    source = command.split()[1].removeprefix("{W}/")
    assert source in err or "angles.csv" in err, f"{case_id}: the message does not name {source}:\n{err}"
    assert "datagen" not in err and "generator" not in err, f"{case_id}: the message blames datagen:\n{err}"
