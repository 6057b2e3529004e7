"""`bodyschema import` of a folder of images plus a CSV of joint angles: rows go with images in natural order (or
by a file column), named columns are matched to the body's joints, degrees become rad, images are cropped,
resized and converted, forward kinematics come from the robot when asked, and the store validates and trains."""

from __future__ import annotations

import numpy as np
import pytest
import zarr

from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.datagen.exchange.importers.run import import_recording
from bodyschema.datagen.store.validate import validate_store
from tests.datagen.import_sources import SIZE, planar2_frames, write_folder


def _read(store):
    root = zarr.open_group(str(store), mode="r")
    return root, {k: np.asarray(root[k][:]) for k in root.array_keys()}


def test_degrees_named_columns_in_another_order_and_natural_image_order(tmp_path):
    q, images = planar2_frames(12)                       # img10, img11 sort after img9 only in natural order
    folder = write_folder(tmp_path / "rec", q, images, order=(1, 0), deg=True)
    store = import_recording(ImportConfig(source=folder, out=tmp_path / "rec.zarr", angles="deg", robot="planar2",
                                          fk=True))
    assert validate_store(store) == []
    root, arrays = _read(store)
    np.testing.assert_allclose(arrays["q"], q, atol=1e-6)          # float32 of the CSV's deg → rad
    np.testing.assert_array_equal(arrays["image"], images)
    with Robot.load("planar2", image_size=SIZE) as robot:
        np.testing.assert_allclose(arrays["ee_xyz"], robot.fk(arrays["q"].astype(float)), atol=1e-6)
        np.testing.assert_allclose(arrays["ee_pixel"], robot.project(robot.fk(arrays["q"].astype(float))),
                                   atol=1e-3)
    assert root.attrs["sampler"] == "imported" and root.attrs["source"]["format"] == "folder"
    assert root.attrs["source"]["files"] == 13 and len(root.attrs["source"]["sha256"]) == 64
    np.testing.assert_allclose(root.attrs["sampling_ranges"], [[q[:, 0].min(), q[:, 0].max()],
                                                               [q[:, 1].min(), q[:, 1].max()]], atol=1e-6)


def test_radians_without_header_and_without_images(tmp_path):
    q, images = planar2_frames(5)
    folder = write_folder(tmp_path / "rec", q, images, deg=False, header=False)
    store = import_recording(ImportConfig(source=folder, out=tmp_path / "rec.zarr", angles="rad", robot="planar2",
                                          images=False))
    root, arrays = _read(store)
    assert sorted(arrays) == ["q", "shard_done"] and root.attrs["images"] is False
    np.testing.assert_allclose(arrays["q"], q, atol=1e-6)


def test_a_file_column_maps_rows_to_images(tmp_path):
    q, images = planar2_frames(4)
    folder = write_folder(tmp_path / "rec", q, images, deg=False)
    names = [f"img{i}.png" for i in (3, 1, 0, 2)]
    rows = ["image,shoulder,elbow"] + [f"{n},{float(q[int(n[3]), 0])!r},{float(q[int(n[3]), 1])!r}" for n in names]
    (folder / "angles.csv").write_text("\n".join(rows) + "\n")
    store = import_recording(ImportConfig(source=folder, out=tmp_path / "rec.zarr", angles="rad", robot="planar2"))
    _, arrays = _read(store)
    order = [3, 1, 0, 2]
    np.testing.assert_allclose(arrays["q"], q[order], atol=1e-6)
    np.testing.assert_array_equal(arrays["image"], images[order])


def test_crop_then_resize_then_gray_of_colour_frames(tmp_path):
    import cv2

    q, images = planar2_frames(3, rgb=True)
    folder = write_folder(tmp_path / "rec", q, images, deg=False)
    store = import_recording(ImportConfig(source=folder, out=tmp_path / "rec.zarr", angles="rad", robot="planar2",
                                          crop=(2, 4, 20, 16), resize=(10, 8), gray=True))
    root, arrays = _read(store)
    want = np.stack([cv2.cvtColor(cv2.resize(im[2:22, 4:20], (8, 10), interpolation=cv2.INTER_AREA),
                                  cv2.COLOR_RGB2GRAY) for im in images])
    np.testing.assert_array_equal(arrays["image"], want)
    assert root.attrs["image_size"] == [10, 8] and root.attrs["channels"] == 1


def test_a_body_from_joint_names_and_ranges_trains(tmp_path):
    from bodyschema.training.data import load_dataset

    q, images = planar2_frames(10)
    folder = write_folder(tmp_path / "rec", q, images, deg=True)
    store = import_recording(ImportConfig(source=folder, out=tmp_path / "rec.zarr", angles="deg",
                                          joints=("shoulder", "elbow"), ranges=((-150, 150), (-150, 150)),
                                          name="my_arm"))
    root, _ = _read(store)
    assert root.attrs["robot"] == "my_arm" and root.attrs["mjcf_sha256"] is None
    np.testing.assert_allclose(root.attrs["joint_limits"], np.deg2rad([[-150, 150], [-150, 150]]))
    data = load_dataset(store, "image")
    assert data.body.robot == "my_arm" and data.output_shape("image") == SIZE
    np.testing.assert_allclose(data.body.q_low, np.deg2rad([-150, -150]))


def test_overwrite_replaces_and_refusal_keeps_the_old_store(tmp_path):
    q, images = planar2_frames(3)
    folder = write_folder(tmp_path / "rec", q, images, deg=False)
    config = ImportConfig(source=folder, out=tmp_path / "rec.zarr", angles="rad", robot="planar2")
    import_recording(config)
    with pytest.raises(FileExistsError, match="must be"):
        import_recording(config)
    from dataclasses import replace
    assert validate_store(import_recording(replace(config, overwrite=True))) == []


def test_show_draws_the_contact_sheet_of_a_recording_without_ee_pixel(tmp_path):
    from bodyschema.datagen.store.show import show_store

    q, images = planar2_frames(4)
    folder = write_folder(tmp_path / "rec", q, images)
    store = import_recording(ImportConfig(source=folder, out=tmp_path / "rec.zarr", angles="deg", robot="planar2"))
    shown = show_store(store, tmp_path / "sheet.png", n=4)
    assert shown.sheet.is_file() and shown.sheet.stat().st_size > 0
