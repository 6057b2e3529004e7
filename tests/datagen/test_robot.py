"""The Robot wrapper: rendered marker vs projected ee, Jacobians vs finite differences, DH kinematics, errors."""

from __future__ import annotations

import numpy as np
import pytest

from bodyschema.datagen.body.kinematics import VECTORIZE_FROM
from bodyschema.datagen.body.record import SHIPPED
from bodyschema.datagen.body.robot import LIMIT_TOLERANCE, Robot

FD_STEP = 1e-6          # rad
TEST_SIZES = {"planar2": (128, 128), "nao_arm": (56, 80), "panda": (192, 192)}   # (H, W) px
_CACHE: dict[tuple, Robot] = {}


def robot(name: str, **kwargs) -> Robot:
    key = (name, tuple(sorted(kwargs.items())))
    if key not in _CACHE:
        _CACHE[key] = Robot.load(name, **kwargs)
    return _CACHE[key]


def random_q(r: Robot, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    low, high = r.sampling_ranges.T
    return rng.uniform(low, high, size=(n, r.dq))                               # (n, Dq) rad


def marker_centroid(image: np.ndarray) -> tuple[np.ndarray, float]:
    """Coverage-weighted centroid (u, v) px of the yellow marker in an RGB image, and its area in px."""
    rgb = image.astype(np.float64)
    # On a grey background a pixel = α·yellow + (1 − α)·grey, so min(R, G) − B = 255 α: the coverage α.
    weight = np.clip((np.minimum(rgb[..., 0], rgb[..., 1]) - rgb[..., 2]) / 255.0, 0.0, 1.0)
    weight[weight < 0.05] = 0.0
    v, u = np.indices(weight.shape)
    total = weight.sum()
    return np.array([(u * weight).sum(), (v * weight).sum()]) / max(total, 1e-12), total


def marker_radius_px(r: Robot, name: str, xyz: np.ndarray) -> np.ndarray:
    """Approximate projected radius (px) of the marker sphere at each ee position."""
    radius = r.model.geom("marker").size[0]
    depth = (np.c_[xyz, np.ones(len(xyz))] @ r.extrinsics().T)[:, 2]         # (N,) m along the optical axis
    return r.intrinsics()[0, 0] * radius / depth


# ---- the camera model agrees with the renderer ------------------------------------------------------------
@pytest.mark.parametrize("name", SHIPPED)
def test_projected_ee_lies_on_rendered_marker(name):
    r = robot(name, image_size=TEST_SIZES[name], rgb=True)
    q = random_q(r, 24, seed=1)
    obs = r.observe(q)
    expected_area = np.pi * marker_radius_px(r, name, obs["ee_xyz"].astype(np.float64)) ** 2
    checked = 0
    for i in range(len(q)):
        centroid, area = marker_centroid(obs["image"][i])
        under_floor = name == "panda" and obs["ee_xyz"][i, 2] < 0.05                 # panda floor: z = 0
        if area < 0.8 * expected_area[i] or under_floor:                            # (partly) hidden
            continue
        checked += 1
        err = np.linalg.norm(centroid - obs["ee_pixel"][i])
        assert err <= 1.0, f"{name} pose {i}: marker centroid {centroid} vs projected {obs['ee_pixel'][i]}"
    assert checked >= 12, f"only {checked} of {len(q)} poses show the whole marker"


def test_default_grayscale_marker_is_the_brightest_blob_at_the_projection():
    r = robot("planar2")
    assert r.image_size == (64, 64) and r.channels == 1
    q = random_q(r, 8, seed=2)
    obs = r.observe(q)
    assert obs["image"].shape == (8, 64, 64) and obs["image"].dtype == np.uint8
    for i in range(len(q)):
        v, u = np.nonzero(obs["image"][i] > 170)                               # marker ≈ 226, links ≤ ~110
        assert len(u) > 0
        assert np.hypot(u.mean() - obs["ee_pixel"][i, 0], v.mean() - obs["ee_pixel"][i, 1]) <= 1.0


def test_nao_hand_stays_in_view_for_most_poses_of_the_camera_workspace():
    r = robot("nao_arm")
    assert r.image_size == (56, 80) and r.camera_name == "CameraBottom" and r.workspace == "camera"
    pixels = r.project(r.fk(random_q(r, 2000, seed=3)))                       # (2000, 2) px
    h, w = r.image_size
    inside = (pixels >= 0).all(axis=1) & (pixels[:, 0] <= w - 1) & (pixels[:, 1] <= h - 1)
    assert inside.mean() >= 0.85, f"the ee is inside the image for only {inside.mean():.0%} of the poses"


def test_nao_former_wide_camera_sees_every_pose_of_the_full_workspace():
    # "eye" (the bench baseline) was fitted to this: corners, edges and interior of the box project inside.
    r = robot("nao_arm", camera="eye", workspace="full")
    grid = np.stack(np.meshgrid(*[np.linspace(lo, hi, 7) for lo, hi in r.sampling_ranges]), -1).reshape(-1, 4)
    pixels = r.project(r.fk(np.r_[grid, random_q(r, 2000, seed=3)]))
    h, w = r.image_size
    assert (pixels >= 0).all() and (pixels[:, 0] <= w - 1).all() and (pixels[:, 1] <= h - 1).all()


@pytest.mark.parametrize("name", SHIPPED)
def test_projection_matches_intrinsics_times_extrinsics_and_its_jacobian(name):
    r = robot(name)
    xyz = r.fk(random_q(r, 6, seed=4))
    cam = np.c_[xyz, np.ones(len(xyz))] @ r.extrinsics().T                     # (N, 4)
    uvw = cam[:, :3] @ r.intrinsics().T
    np.testing.assert_allclose(r.project(xyz), uvw[:, :2] / uvw[:, 2:], atol=1e-9)
    fd = np.stack([(r.project(xyz + e) - r.project(xyz - e)) / 2e-7 for e in np.eye(3) * 1e-7], axis=-1)
    np.testing.assert_allclose(r.project_jacobian(xyz), fd, rtol=1e-5, atol=1e-4)
    rot = r.extrinsics()[:3, :3]
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-9)


# ---- kinematics ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", SHIPPED)
def test_jacobian_equals_central_finite_differences_of_fk(name):
    r = robot(name)
    q = random_q(r, 5, seed=5)
    fd = np.stack([(r.fk(q + e) - r.fk(q - e)) / (2 * FD_STEP) for e in np.eye(r.dq) * FD_STEP], axis=-1)
    np.testing.assert_allclose(r.jacobian(q), fd, atol=1e-7)
    obs = r.observe(q, image=False)
    assert "image" not in obs and obs["jacobian"].dtype == np.float32
    np.testing.assert_allclose(obs["jacobian"], fd, atol=1e-6)
    np.testing.assert_allclose(obs["ee_xyz"], r.fk(q), atol=1e-6)


@pytest.mark.parametrize("name", SHIPPED)
def test_vectorized_chain_equals_the_mujoco_calls(name):
    r = robot(name)
    q = random_q(r, 2 * VECTORIZE_FROM, seed=9)
    obs = r.observe(q, image=False)                                            # batch ≥ VECTORIZE_FROM: numpy chain
    xyz, jac = r.fk_and_jacobian(q)
    np.testing.assert_allclose(xyz, r.fk(q), atol=1e-12)                      # fk: mj_kinematics per pose
    np.testing.assert_allclose(jac, r.jacobian(q), atol=1e-12)                # jacobian: mj_jacSite per pose
    np.testing.assert_allclose(obs["ee_xyz"], xyz.astype(np.float32))
    np.testing.assert_allclose(obs["jacobian"], jac.astype(np.float32))
    np.testing.assert_allclose(obs["ee_pixel"], r.project(xyz).astype(np.float32))


def modified_dh_chain(q: np.ndarray) -> np.ndarray:
    """Franka's published modified-DH (Craig) chain + flange (0.107 m) + hand TCP (0.1034 m). (N, 7) → (N, 3)."""
    a = [0, 0, 0, 0.0825, -0.0825, 0, 0.088, 0]
    d = [0.333, 0, 0.316, 0, 0.384, 0, 0, 0.107 + 0.1034]
    alpha = [0, -np.pi / 2, np.pi / 2, np.pi / 2, -np.pi / 2, np.pi / 2, np.pi / 2, 0]
    out = []
    for row in q:
        t = np.eye(4)
        for i, theta in enumerate([*row, 0.0]):
            ca, sa, ct, st = np.cos(alpha[i]), np.sin(alpha[i]), np.cos(theta), np.sin(theta)
            # T_i = RotX(α_{i-1}) TransX(a_{i-1}) RotZ(θ_i) TransZ(d_i)   (Craig 2005, eq. 3.6)
            t = t @ np.array([[ct, -st, 0, a[i]], [st * ca, ct * ca, -sa, -sa * d[i]],
                              [st * sa, ct * sa, ca, ca * d[i]], [0, 0, 0, 1]])
        out.append(t[:3, 3])
    return np.array(out)


@pytest.mark.parametrize("name", SHIPPED)
def test_ee_rot_is_mujocos_site_frame_and_its_jacobian_finite_differences(name):
    import mujoco

    r = robot(name)
    q = random_q(r, 5, seed=4)
    rot, jac = r.ee_rot_and_jacobian(q)
    np.testing.assert_array_equal(r.ee_rot(q), rot)
    data = mujoco.MjData(r.model)
    for q_i, rot_i in zip(q, rot):
        data.qpos[:] = q_i
        mujoco.mj_kinematics(r.model, data)
        np.testing.assert_allclose(rot_i, data.site_xmat[r.model.site(r.ee_site).id], atol=1e-12)
    np.testing.assert_allclose(rot.reshape(-1, 3, 3) @ rot.reshape(-1, 3, 3).transpose(0, 2, 1),
                               np.broadcast_to(np.eye(3), (len(q), 3, 3)), atol=1e-12)   # a rotation
    fd = np.stack([(r.ee_rot_and_jacobian(q + e, check=False)[0] - r.ee_rot_and_jacobian(q - e, check=False)[0])
                   / (2 * FD_STEP) for e in np.eye(r.dq) * FD_STEP], axis=-1)
    np.testing.assert_allclose(jac, fd, atol=1e-8)          # central differences at 1e-6 rad: error ~1e-10
    np.testing.assert_allclose(r.observe(q, image=False)["ee_rot"], rot.astype(np.float32))


def test_panda_fk_equals_the_modified_dh_chain():
    r = robot("panda")
    q = random_q(r, 20, seed=6)
    np.testing.assert_allclose(r.fk(q), modified_dh_chain(q), atol=1e-6)
    np.testing.assert_allclose(r.joint_limits[3], [-3.0718, -0.0698])
    np.testing.assert_allclose(r.joint_limits[5], [-0.0175, 3.7525])


def test_nao_arm_has_nao_joints_axes_and_link_lengths():
    r = robot("nao_arm")
    assert r.joint_names == ("LShoulderPitch", "LShoulderRoll", "LElbowYaw", "LElbowRoll")
    axes = np.array([r.model.joint(j).axis for j in r.joint_names])
    np.testing.assert_allclose(axes, [[0, 1, 0], [0, 0, 1], [1, 0, 0], [0, 0, 1]])
    np.testing.assert_allclose(r.joint_limits, [[-2.0857, 2.0857], [-0.3142, 1.3265], [-2.0857, 2.0857],
                                                [-1.5446, -0.0349]])
    # Arm stretched forward (ER at its limit nearest 0): shoulder (0, 98, 100) + upper arm 105 + elbow y 15
    # + lower arm 55.95 + hand 57.75 mm, with the tiny residual elbow roll applied to the last two.
    er = -0.0349
    fore = 0.05595 + 0.05775
    expected = [0.105 + fore * np.cos(er), 0.098 + 0.015 + fore * np.sin(er), 0.100]
    np.testing.assert_allclose(r.fk(np.array([[0.0, 0.0, 0.0, er]]))[0], expected, atol=1e-9)
    # Pitch about +y: positive pitch lowers the arm.
    assert r.fk(np.array([[0.5, 0.0, 0.0, er]]))[0, 2] < 0.100


def test_planar2_reaches_the_sum_of_its_links():
    r = robot("planar2")
    np.testing.assert_allclose(np.linalg.norm(r.fk(np.zeros((1, 2)))[0, :2]), 0.55, atol=1e-9)


# ---- sensing, actuators, gravity, state ---------------------------------------------------------------------
def test_touch_reads_contact_only_for_the_panda():
    assert robot("planar2").touch(np.zeros((1, 2))) is None
    assert "touch" not in robot("planar2").observe(np.zeros((1, 2)), image=False)
    r = robot("panda")
    q = random_q(r, 200, seed=7)
    z = r.fk(q)[:, 2]
    above, below = q[z > 0.1][:3], q[z < -0.02][:3]
    assert len(above) and len(below)
    reading = r.touch(np.r_[above, below])[:, 0]
    assert (reading[:len(above)] == 0).all() and (reading[len(above):] > 0).all()
    assert r.observe(above, image=False)["touch"].shape == (len(above), 1)


def test_actuator_variants_and_gravity_are_configurable():
    import mujoco

    pos = robot("panda")
    torque = Robot.load("panda", actuators="torque", gravity=3.0)
    assert (pos.model.actuator_biastype == mujoco.mjtBias.mjBIAS_AFFINE).all()
    assert (torque.model.actuator_biastype == mujoco.mjtBias.mjBIAS_NONE).all()
    np.testing.assert_allclose(torque.model.actuator_ctrlrange, pos.model.actuator_forcerange)
    np.testing.assert_allclose(torque.model.opt.gravity, [0, 0, -3.0])
    np.testing.assert_allclose(pos.model.opt.gravity, [0, 0, -9.81])
    assert torque.mjcf_sha256 == pos.mjcf_sha256 and len(pos.mjcf_sha256) == 64


def test_queries_leave_the_dynamics_state_alone_and_are_deterministic():
    r = robot("nao_arm")
    r.data.qpos[:] = r.sampling_ranges.mean(axis=1)
    before = r.data.qpos.copy()
    q = random_q(r, 3, seed=8)
    first = r.render(q)
    np.testing.assert_array_equal(r.data.qpos, before)
    np.testing.assert_array_equal(r.render(q), first)
    assert first.shape == (3, 56, 80)


def test_rgb_and_any_image_size_are_configurable():
    r = robot("planar2", image_size=(24, 40), rgb=True)
    image = r.render(np.zeros((2, 2)))
    assert image.shape == (2, 24, 40, 3) and r.channels == 3
    assert r.intrinsics()[0, 2] == pytest.approx(19.5) and r.intrinsics()[1, 2] == pytest.approx(11.5)


# ---- errors -------------------------------------------------------------------------------------------------
def test_unknown_robot_raises():
    with pytest.raises(ValueError, match=r"robot must be one of \('planar2', 'nao_arm', 'panda'\) or a path .* 'pr2'"):
        Robot.load("pr2")


@pytest.mark.parametrize("size", [(4, 64), (64, 2000), (64,), "big", (64.5, 64)])
def test_bad_image_size_raises(size):
    with pytest.raises(ValueError, match=r"image_size must be \(H, W\)"):
        Robot.load("planar2", image_size=size)


def test_bad_actuators_or_gravity_raise():
    with pytest.raises(ValueError, match=r"actuators must be one of"):
        Robot.load("planar2", actuators="muscle")
    with pytest.raises(ValueError, match=r"gravity must be"):
        Robot.load("planar2", gravity=float("nan"))
    with pytest.raises(ValueError, match=r"gravity must be"):
        Robot.load("planar2", gravity="down")


def test_bad_q_raises():
    r = robot("planar2")
    with pytest.raises(ValueError, match=r"q must be an array of shape \(N, 2\)"):
        r.fk(np.zeros(2))
    with pytest.raises(ValueError, match=r"q must be an array of shape \(N, 2\)"):
        r.jacobian(np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"q must be finite"):
        r.observe(np.array([[0.0, np.nan]]))
    high = r.joint_limits[1, 1] + 2 * LIMIT_TOLERANCE
    with pytest.raises(ValueError, match=r"q\[:, 1\] \(elbow\) must be inside the joint limits"):
        r.render(np.array([[0.0, 0.0], [0.0, high]]))


def test_check_ranges_rejects_a_range_outside_the_limits():
    r = robot("nao_arm")
    r.check_ranges(r.sampling_ranges)
    bad = r.sampling_ranges.copy()
    bad[3] = [-1.4, 0.2]                                                       # LElbowRoll max is −0.0349
    with pytest.raises(ValueError, match=r"sampling range of LElbowRoll must be ordered and inside"):
        r.check_ranges(bad)
    with pytest.raises(ValueError, match=r"sampling ranges must be a finite array of shape \(4, 2\)"):
        r.check_ranges(bad[:3])
    with pytest.raises(ValueError, match=r"sampling ranges must be"):
        r.check_ranges([[0.0, 1.0], [0.0]])                                   # ragged
    for name in SHIPPED:
        other = robot(name) if name != "nao_arm" else r
        assert ((other.sampling_ranges[:, 0] >= other.joint_limits[:, 0])
                & (other.sampling_ranges[:, 1] <= other.joint_limits[:, 1])).all()


@pytest.mark.parametrize("name", SHIPPED)
def test_unchecked_kinematics_serve_simulated_states_past_the_limits(name):
    r = robot(name)
    q = random_q(r, 8, seed=3)
    past = q.copy()
    past[:, 0] = r.joint_limits[0, 1] + LIMIT_TOLERANCE + 0.05                 # a simulated arm overshoots a little
    with pytest.raises(ValueError, match="inside the joint limits"):
        r.fk(past)
    np.testing.assert_array_equal(r.fk(q, check=False), r.fk(q))              # same numbers inside the limits
    xyz, jac = r.fk_and_jacobian(past, check=False)
    np.testing.assert_allclose(xyz, r.fk(past, check=False), atol=1e-12)
    np.testing.assert_allclose(jac, r.jacobian(past, check=False), atol=1e-12)
    assert np.isfinite(xyz).all() and not np.allclose(xyz, r.fk(q))


def test_actuation_says_what_the_actuators_take():
    assert robot("nao_arm").actuation == "position"
    assert robot("panda", actuators="torque").actuation == "torque"
    assert robot("panda").actuation == "position"
