"""Named workspaces: each robot's joint boxes, how Robot.load and datagen pick one, and what the camera sees there."""

from __future__ import annotations

import numpy as np
import pytest
import zarr

from bodyschema.datagen.body.record import SHIPPED
from bodyschema.datagen.body.robot import DEFAULT_WORKSPACE, Robot
from bodyschema.datagen.config import WORKSPACES, DatagenConfig
from bodyschema.datagen.generate import generate


@pytest.fixture(scope="module")
def nao():
    return Robot.load("nao_arm")


def camera_depth(r: Robot, q: np.ndarray) -> np.ndarray:
    """(N,) m: depth of the ee along the optical axis (OpenCV z); > 0 means in front of the camera."""
    xyz = r.fk(q)                                                             # (N, 3) m
    return (np.c_[xyz, np.ones(len(xyz))] @ r.extrinsics().T)[:, 2]


def box_grid(box: np.ndarray, per_side: int) -> np.ndarray:
    return np.stack(np.meshgrid(*[np.linspace(lo, hi, per_side) for lo, hi in box]), -1).reshape(-1, len(box))


def test_every_robot_names_the_config_workspaces_and_each_box_lies_in_full():
    for name in SHIPPED:
        r = Robot.load(name)
        assert tuple(r.record.workspaces) == WORKSPACES == tuple(r.workspaces)
        full = r.workspaces["full"]
        for ws, box in r.workspaces.items():
            assert box.shape == (r.dq, 2) and box.dtype == np.float64, ws
            assert ((box[:, 0] >= full[:, 0]) & (box[:, 1] <= full[:, 1])).all(), f"{name} {ws} is not in full"


def test_load_samples_the_chosen_workspace_and_defaults_to_the_camera_one(nao):
    assert nao.workspace == DEFAULT_WORKSPACE == "camera"
    np.testing.assert_array_equal(nao.sampling_ranges, nao.workspaces["camera"])
    full = Robot.load("nao_arm", workspace="full")
    assert full.workspace == "full"
    np.testing.assert_array_equal(full.sampling_ranges, full.workspaces["full"])
    assert not np.array_equal(full.sampling_ranges, nao.sampling_ranges)   # the camera cuts the nao box
    full.sampling_ranges[0, 0] = 0.0                                           # a copy: the workspace is kept
    assert full.workspaces["full"][0, 0] != 0.0


def test_unknown_workspace_or_camera_is_named_with_the_valid_ones():
    with pytest.raises(ValueError, match=r"workspace must be one of \('full', 'camera'\) for nao_arm. Got 'reach'"):
        Robot.load("nao_arm", workspace="reach")
    with pytest.raises(ValueError, match=r"camera must be one of the model's cameras \[.*'CameraBottom'.*\] for nao"):
        Robot.load("nao_arm", camera="top")
    with pytest.raises(ValueError, match=r"workspace must be one of \('full', 'camera'\) or None. Got 'reach'"):
        DatagenConfig(workspace="reach")


@pytest.mark.parametrize("name", SHIPPED)
def test_the_ee_of_the_full_workspace_stays_in_front_of_the_camera(name):
    # ee_pixel is defined only for z > 0 in camera coordinates; corners, edges and interior of the box.
    r = Robot.load(name, workspace="full")
    q = np.r_[box_grid(r.sampling_ranges, 5 if r.dq <= 4 else 3),
              np.random.default_rng(0).uniform(*r.sampling_ranges.T, size=(2000, r.dq))]
    assert camera_depth(r, q).min() > 0.0


def test_in_view_is_the_ee_in_front_of_the_camera_and_inside_the_image(nao):
    q = np.random.default_rng(2).uniform(*nao.workspaces["full"].T, size=(600, nao.dq))   # big batch: vectorized
    px, depth = nao.project(nao.fk(q)), camera_depth(nao, q)
    h, w = nao.image_size
    expected = (depth > 0) & (px >= 0).all(axis=1) & (px[:, 0] <= w - 1) & (px[:, 1] <= h - 1)
    np.testing.assert_array_equal(nao.in_view(q), expected)
    np.testing.assert_array_equal(nao.in_view(q[:5]), expected[:5])                      # small batch: MuJoCo
    assert 0 < expected.mean() < 1


def test_nao_camera_workspace_keeps_most_of_the_hand_in_view_and_full_does_not(nao):
    full = Robot.load("nao_arm", workspace="full")

    def seen(r: Robot) -> float:
        return float(r.in_view(np.random.default_rng(1).uniform(*r.sampling_ranges.T, size=(2000, r.dq))).mean())

    assert seen(nao) >= 0.85 > seen(full)                                      # the cut is what keeps it in view


def test_datagen_picks_camera_with_images_full_without_and_explicit_ranges_win(tmp_path):
    assert DatagenConfig().workspace_name == "camera" and DatagenConfig(images=False).workspace_name == "full"
    assert DatagenConfig(images=False, workspace="camera").workspace_name == "camera"
    assert DatagenConfig(workspace="full").identity() != DatagenConfig().identity()
    nao = Robot.load("nao_arm")
    ranges = ((0.0, 0.5), (0.1, 0.5), (-1.0, 1.0), (-0.8, -0.1))
    cases = [(dict(), "camera", nao.workspaces["camera"]), (dict(images=False), "full", nao.workspaces["full"]),
             (dict(images=False, ranges=ranges), None, np.array(ranges))]
    for i, (kwargs, workspace, box) in enumerate(cases):
        path = generate(DatagenConfig(robot="nao_arm", n=64, seed=i, out=tmp_path / f"{i}.zarr", **kwargs),
                        progress=False)
        root = zarr.open_group(str(path), mode="r")
        assert root.attrs["workspace"] == workspace
        np.testing.assert_allclose(root.attrs["sampling_ranges"], box)
        q = root["q"][:]
        assert ((q >= box[:, 0] - 1e-6) & (q <= box[:, 1] + 1e-6)).all(), f"case {kwargs}"
