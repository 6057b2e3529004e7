"""The core simulator and sensing: the marker hook moves only what a camera sees, by the offset in the hand frame;
the gravity hook changes the dynamics and is undone on exit; a servo batch held against gravity rests; sensing
reads what the robot's own kinematics and camera say."""

from __future__ import annotations

import numpy as np
import pytest

from bodyschema.control.sim import ArmBatch, control_substeps
from bodyschema.datagen.body.robot import GRAVITY, Robot
from bodyschema.evaluation.adaptation.marker_shift import goal_poses, marker_offsets
from bodyschema.evaluation.core.sensing import Sensors, sense, sense_all
from bodyschema.evaluation.core.specs import load_robot
from bodyschema.models.analytic import AnalyticModel


@pytest.fixture(scope="module")
def nao():
    return load_robot([AnalyticModel("nao_arm", "joints")])


def test_marker_is_the_ee_site_moved_by_the_offset_in_the_hand_frame(nao):
    q = goal_poses(nao, 3, seed=1)
    offsets = marker_offsets(["left", "finger", "forearm"], 0.03)
    arms = ArmBatch(nao, q, hold="gravity", marker_offsets=offsets)
    np.testing.assert_allclose(arms.marker_xyz, arms.ee_xyz, atol=1e-12)        # not shifted yet: on the hand
    np.testing.assert_allclose(arms.ee_xyz, nao.fk(q), atol=1e-12)
    arms.shifted[:] = True
    moved = arms.marker_xyz - arms.ee_xyz                                        # (3, 3) m in the world
    np.testing.assert_allclose(np.linalg.norm(moved, axis=1), np.linalg.norm(offsets, axis=1), rtol=1e-12)
    forearm = nao.model.body("LForeArm").id
    direction = [d.xmat[forearm].reshape(3, 3)[:, 0] for d in arms.datas]       # the hand's x axis
    assert np.dot(moved[1], direction[1]) > 0 > np.dot(moved[2], direction[2])  # finger out, forearm back


def test_image_sensing_renders_the_marker_where_it_was_shifted(nao):
    q = np.repeat(goal_poses(nao, 1, seed=0), 3, axis=0)
    offsets = marker_offsets(["none", "left", "finger"], 0.03)   # (forearm: inside the forearm capsule, hidden)
    images = sense(nao, "image", q, marker_offsets=offsets)                      # (3, H, W) in [0, 1]
    arms = ArmBatch(nao, q, marker_offsets=offsets)
    arms.shifted[:] = True
    expected = sense(nao, "ee_pixel", q, xyz=arms.marker_xyz)                    # (3, 2) px
    # The hand's palm and stripe are as bright as the marker: locate the marker by what the shift lit up.
    rows, cols = np.nonzero(images[1] - images[0] > 0.2)                         # "left": the marker in full view
    assert abs(cols.mean() - expected[1, 0]) < 1.0 and abs(rows.mean() - expected[1, 1]) < 1.0
    # "finger": the marker may hide behind the hand at its new place; what changed lies along its path, within the
    # marker's radius (13 mm at ~0.2 m: ~4 px) of the segment from the old to the new projection.
    rows, cols = np.nonzero(np.abs(images[2] - images[0]) > 0.2)
    old = sense(nao, "ee_pixel", q[:1])[0]                                       # (2,) px, the unshifted marker
    path = expected[2] - old
    pixels = np.stack([cols, rows], 1) - old                                     # (P, 2) px
    along = np.clip(pixels @ path / (path @ path), 0.0, 1.0)
    assert len(rows) > 0 and np.linalg.norm(pixels - along[:, None] * path, axis=1).max() < 5.0
    assert np.array_equal(nao.model.geom_pos[nao.model.geom("marker").id], nao.model.site_pos[nao.model.site("ee").id])
    np.testing.assert_array_equal(images[0], sense(nao, "image", q[:1])[0])      # no offset: the plain render


def test_servos_held_against_gravity_rest_where_they_start(nao):
    q = goal_poses(nao, 2, seed=3)
    arms = ArmBatch(nao, q, hold="gravity")
    substeps = control_substeps(100.0, nao.model.opt.timestep)
    for _ in range(50):
        arms.step(arms.ctrl, substeps)
    assert np.abs(arms.q - q).max() < 1e-4 and not arms.failed.any()


def test_gravity_hook_changes_the_dynamics_and_exit_restores_earth():
    panda = Robot.load("panda", actuators="torque")
    q0 = np.tile(np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]), (1, 1))
    falls = {}
    for g in (GRAVITY, 3 * GRAVITY):
        with ArmBatch(panda, q0) as arms:
            arms.set_gravity(g)
            arms.step(np.zeros((1, panda.dq)), 20)                                # motors off: the arm falls
            falls[g] = np.abs(arms.q - q0).max()
    assert falls[3 * GRAVITY] > 2 * falls[GRAVITY] > 0
    np.testing.assert_array_equal(panda.model.opt.gravity, (0.0, 0.0, -GRAVITY))


def test_sensing_is_the_robots_kinematics_and_camera(nao):
    q = goal_poses(nao, 4, seed=2)
    got = sense_all(nao, ("joints", "ee_xyz", "ee_pixel"), q)
    np.testing.assert_array_equal(got["joints"].numpy(), q)
    np.testing.assert_array_equal(got["ee_xyz"].numpy(), nao.fk(q))
    np.testing.assert_array_equal(got["ee_pixel"].numpy(), nao.project(nao.fk(q)))
    gone = np.array([[np.nan, 0.0, 0.0]])
    assert np.isnan(sense(nao, "ee_pixel", q[:1], xyz=gone)).all()              # a point that left the scene


def test_sensors_add_seeded_noise_and_hold_frozen_streams(nao):
    q = goal_poses(nao, 3, seed=4)
    arms = ArmBatch(nao, q)
    sensors = Sensors(("joints", "ee_pixel"), {"joints": 0.01}, frozenset({"ee_pixel"}), np.random.default_rng(5))
    first = sensors.read(arms)
    noise = first["joints"].numpy() - arms.q
    np.testing.assert_allclose(noise, 0.01 * np.random.default_rng(5).standard_normal(q.shape), rtol=1e-12)
    arms.step(arms.ctrl + 0.2, control_substeps(50.0, nao.model.opt.timestep))
    again = sensors.read(arms)
    assert again["ee_pixel"] is first["ee_pixel"]                                # frozen at its first reading
    assert not np.allclose(again["joints"].numpy(), first["joints"].numpy())
