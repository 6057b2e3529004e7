"""The streaming tracker on toy models: warm start vs cold start, lost-track recovery, batched = per stream, bad
frames rejected with the state untouched, and Perception.free_energy (its calibration hook)."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
import torch

from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import PerceptionConfig
from bodyschema.aif.tracker import Tracker
from bodyschema.aif.tracker_config import TrackerConfig
from tests.aif.toys import ToyBlobImage, ToyJoints
from tests.threads import one_thread
from tests.toy_models import ToyPlanarArm

DEG = math.pi / 180
DT = 1 / 30                                                                # s between frames
NOISE = 0.05                                                               # σ of the toy images' pixels
ELBOW_BENT = ((-2.5, 0.05), (2.5, 2.5))    # rad: one inverse-kinematics branch (the blob cannot tell the other)


@pytest.fixture(autouse=True)
def single_thread():
    with one_thread():                                                     # toy tensors: per-op overhead only
        yield


def trajectory(frames: int, streams: int, seed: int = 0) -> torch.Tensor:
    """Smooth arm motion, elbow bent (one inverse-kinematics branch): (T, B, 2) rad, up to ~60°/s per joint."""
    g = torch.Generator().manual_seed(seed)
    phase = torch.rand(streams, 2, generator=g, dtype=torch.float64) * 2 * math.pi
    centre = torch.tensor([0.2, 0.9], dtype=torch.float64)
    t = torch.arange(frames, dtype=torch.float64)[:, None, None] * DT
    return centre + 0.5 * torch.sin(2.0 * t + phase)                         # (T, B, 2)


class GridEncoder:
    """A toy image encoder: the pose of a coarse grid whose predicted image is nearest (elbow-bent branch)."""

    modality = "image"                                                      # what it encodes

    def __init__(self, model):
        axis = torch.linspace(-1.5, 1.5, 31, dtype=torch.float64)
        elbow = torch.linspace(0.1, 2.0, 20, dtype=torch.float64)
        self.poses = torch.cartesian_prod(axis, elbow)                      # (G, 2) rad
        self.images = model.predict(self.poses).flatten(1)                  # (G, O)

    def encode(self, images):
        return self.poses[torch.cdist(images.flatten(1).double(), self.images).argmin(dim=1)]


def seen(model, q: torch.Tensor, sigma: float = 0.0, seed: int = 0) -> torch.Tensor:
    """What `model` reads at poses q (..., Dz), plus Gaussian noise σ."""
    x = model.predict(q.reshape(-1, q.shape[-1]))
    x = x + sigma * torch.randn(x.shape, generator=torch.Generator().manual_seed(seed), dtype=x.dtype)
    return x.reshape(*q.shape[:-1], *x.shape[1:])


def run(tracker: Tracker, q: torch.Tensor, model, command: bool = False, sigma: float = 0.0):
    """Feed q's frames (T, B, Dz) through tracker, frame 0 included; → beliefs (T, B, Dz), restart flags (T, B).
    command: the true mean velocity over the interval before each frame."""
    beliefs, restarts = [], []
    frames = seen(model, q, sigma)
    for k, pose in enumerate(q):
        velocity = (pose - q[k - 1]) / DT if command and k > 0 else None
        mu, _ = tracker.step({model.modality: frames[k]}, velocity, dt=DT)
        beliefs.append(mu)
        restarts.append(tracker.last.restarted)
    return torch.stack(beliefs), torch.stack(restarts)


def test_warm_start_follows_the_motion_better_than_a_cold_start_with_the_same_budget():
    image = ToyBlobImage()
    q = trajectory(30, 8)
    config = TrackerConfig(budget=3)
    warm_tracker = Tracker([image], config)
    warm_tracker.reset(q[0])
    warm, _ = run(warm_tracker, q, image)
    cold_start = torch.tensor([[0.2, 0.9]], dtype=torch.float64).expand(8, 2)   # the middle of the motion
    cold = Perception([image], replace(config.perception, max_steps=warm_tracker.steps))
    cold_mu = torch.stack([cold.infer({"image": image.predict(pose)}, cold_start).mu for pose in q])
    warm_err = (warm - q).abs().mean() / DEG
    cold_err = (cold_mu - q).abs().mean() / DEG
    assert warm_err < 0.5 * cold_err and warm_err < 2.0, (warm_err, cold_err)


def test_the_belief_velocity_and_a_command_each_improve_the_warm_start():
    arm = ToyPlanarArm()
    q = trajectory(30, 6, seed=1)
    errors = {}
    for name, order, command in (("still", 0, False), ("velocity", 1, False), ("command", 0, True)):
        tracker = Tracker([arm], TrackerConfig(budget=1 + 1, order=order))          # one Gauss–Newton step a frame
        tracker.reset(q[0])
        mu, _ = run(tracker, q, arm, command)
        errors[name] = float((mu[5:] - q[5:]).abs().mean() / DEG)
    assert errors["velocity"] < errors["still"] and errors["command"] < errors["still"], errors


@pytest.mark.parametrize("restart", ["guess", "multistart"])
def test_a_jump_is_detected_as_lost_track_and_recovered_within_three_frames(restart):
    image = ToyBlobImage()
    q = trajectory(30, 4, seed=2)
    q[15:] = q[15:] + torch.tensor([-1.0, 0.6], dtype=torch.float64)         # the arm jumps ~57°, 34° (teleport)
    config = TrackerConfig(budget=4, restart=restart, restart_starts=16, proposals=False)   # restarts alone
    tracker = Tracker([image], config, GridEncoder(image), limits=ELBOW_BENT)
    calibration = trajectory(50, 4, seed=3).reshape(-1, 2)
    threshold = tracker.calibrate({"image": seen(image, calibration, NOISE, seed=9)}, calibration)
    assert math.isfinite(threshold)
    tracker.reset(q[0])
    mu, restarted = run(tracker, q, image, sigma=NOISE)
    assert restarted[15].all(), "every stream's jump is detected on its frame"
    assert not restarted[1:15].any(), "no false alarm while tracking"
    err = (mu - q).abs().amax(-1) / DEG                                     # (T, B) worst joint, deg
    assert (err[18:] < 5.0).all() and err[18:].mean() < 2.0, err[15:].T    # at the noise floor again (as before)


def test_the_encoders_proposal_catches_a_jump_on_its_frame_without_a_restart():
    image = ToyBlobImage()
    q = trajectory(12, 4, seed=2)
    q[6:] = q[6:] + torch.tensor([-1.0, 0.6], dtype=torch.float64)
    # every frame updated: on the toy blob's flat F the coarse grid guess (> 5° off) can count as settled
    tracker = Tracker([image], TrackerConfig(budget=4, settle_quantile=None), GridEncoder(image), limits=ELBOW_BENT)
    calibration = trajectory(50, 4, seed=3).reshape(-1, 2)
    tracker.calibrate({"image": seen(image, calibration, NOISE, seed=9)}, calibration)
    tracker.reset(q[0])
    mu, restarted = run(tracker, q, image, sigma=NOISE)
    assert not restarted[1:].any() and tracker.steps == 2, "2 of the 4 evaluations go to the proposal, 2 to steps"
    assert ((mu[6:] - q[6:]).abs().amax(-1) < 5 * DEG).all()


def other_branch(q: torch.Tensor) -> torch.Tensor:
    """The other inverse-kinematics branch of poses q (..., 2): the same hand, so the same blob image."""
    from tests.toy_models import LINKS_M
    l1, l2 = LINKS_M
    turn = 2 * torch.atan2(l2 * q[..., 1].sin(), l1 + l2 * q[..., 1].cos())
    return torch.stack([q[..., 0] + turn, -q[..., 1]], -1)


PRECISION = 8.0


@pytest.mark.parametrize("consistency", [True, False])
def test_a_belief_the_joint_encoders_contradict_is_lost_even_where_F_is_not(consistency):
    """On the other elbow branch the blob image is the same and F rises only by the joints' weak term (~21), within
    F's spread (its threshold ~53 above the median): F alone never notices; the joint encoders' own ½ εᵀΠε (~22),
    above their calibrated threshold (~13), does, and the restart's candidate they accept wins."""
    image, joints = ToyBlobImage(precision=NOISE ** -2), ToyJoints(precision=PRECISION)   # σ ≈ 20° joint encoders
    sigma_joints = PRECISION ** -0.5
    q = trajectory(10, 1, seed=10)                                           # elbow 0.9 rad: branches 47°, 103° apart
    assert torch.allclose(image.predict(other_branch(q[0])), image.predict(q[0]), atol=1e-9)
    calibration = trajectory(50, 4, seed=3).reshape(-1, 2)
    config = TrackerConfig(budget=4, consistency=consistency, proposals=False)   # the encoder's proposal would too
    tracker = Tracker([image, joints], config, GridEncoder(image))
    tracker.calibrate({"image": seen(image, calibration, NOISE, seed=9),
                       "joints": seen(joints, calibration, sigma_joints, seed=10)}, calibration)
    images, readings = seen(image, q, NOISE, seed=11), seen(joints, q, sigma_joints, seed=12)
    tracker.reset(other_branch(q[0]))
    restarted = []
    for k in range(len(q)):
        mu, _ = tracker.step({"image": images[k], "joints": readings[k]}, dt=DT)
        restarted.append(bool(tracker.last.restarted))
    err = float((mu - q[-1]).abs().max()) / DEG
    if consistency:
        assert restarted[0] and err < 5 and set(tracker.sensors.bounds) == {"joints"}, (restarted, err)
    else:
        assert not any(restarted) and err > 30, "F alone stays on the wrong branch"


class CountingEncoder(GridEncoder):
    calls = 0

    def encode(self, images):
        self.calls += 1
        return super().encode(images)


def test_a_restart_reuses_its_frames_encoder_guess():
    image = ToyBlobImage()
    q = trajectory(6, 3, seed=5)
    encoder = CountingEncoder(image)
    tracker = Tracker([image], TrackerConfig(budget=4, lost_threshold=-1e12), encoder)   # every frame is lost
    tracker.reset(q[0])
    _, restarted = run(tracker, q, image)
    assert restarted.all() and encoder.calls == len(q), "one encoder call per frame: proposal and restart share it"


def test_a_joints_reading_is_the_frames_guess_and_catches_a_jump_without_the_encoder():
    """With joint encoders perceived, their reading (1° off) is the frame's guess, not the encoder's (a grid several
    degrees coarse): the encoder is never asked, and the proposal catches a jump on its frame without a restart."""
    image, joints = ToyBlobImage(precision=NOISE ** -2), ToyJoints(precision=DEG ** -2)
    q = trajectory(12, 4, seed=2)
    q[6:] = q[6:] + torch.tensor([-1.0, 0.6], dtype=torch.float64)
    encoder = CountingEncoder(image)
    tracker = Tracker([image, joints], TrackerConfig(budget=4, settle_quantile=None), encoder, limits=ELBOW_BENT)
    calibration = trajectory(50, 4, seed=3).reshape(-1, 2)
    tracker.calibrate({"image": seen(image, calibration, NOISE, seed=9),
                       "joints": seen(joints, calibration, DEG, seed=10)}, calibration)
    images, readings = seen(image, q, NOISE, seed=11), seen(joints, q, DEG, seed=12)
    tracker.reset(q[0])
    beliefs, restarted = [], []
    for k in range(len(q)):
        beliefs.append(tracker.step({"image": images[k], "joints": readings[k]}, dt=DT)[0])
        restarted.append(tracker.last.restarted)
    err = (torch.stack(beliefs) - q).abs().amax(-1) / DEG                  # (T, B) worst joint, deg
    assert tracker.guesses == "reading" and tracker.restart == "guess" and encoder.calls == 0
    assert not torch.stack(restarted)[1:].any() and (err[6:] < 3).all(), err.T


def test_the_first_frame_is_acquired_by_a_restart():
    image = ToyBlobImage()
    q = trajectory(5, 3, seed=4)
    tracker = Tracker([image], TrackerConfig(budget=4), GridEncoder(image))
    mu, restarted = run(tracker, q, image)
    assert restarted[0].all() and (mu[-1] - q[-1]).abs().max() < 2 * DEG


@pytest.mark.parametrize("proposals,settle", [(False, None), (True, None), (True, 0.5)],
                         ids=["restarts", "proposals", "settled"])
def test_batched_streams_equal_each_stream_alone(proposals, settle):
    image, joints = ToyBlobImage(), ToyJoints(precision=10.0)
    q = trajectory(12, 3, seed=5)
    q[6:, 1] += 0.8                                                          # stream 1 jumps: a restart in the mix
    calibration = trajectory(20, 2, seed=6).reshape(-1, 2)

    def fused_run(poses):
        config = TrackerConfig(budget=4, proposals=proposals, settle_quantile=settle)
        tracker = Tracker([image, joints], config, GridEncoder(image))
        tracker.calibrate({"image": seen(image, calibration, NOISE), "joints": calibration + 0.01}, calibration)
        tracker.reset(poses[0])
        restarts = []
        for pose in poses:
            tracker.step({"image": image.predict(pose), "joints": pose + 0.01}, dt=DT)
            restarts.append(tracker.last.restarted)
        return tracker, torch.stack(restarts)

    together, restarts = fused_run(q)
    assert restarts.sum() == (0 if proposals else 1) and (proposals or restarts[6, 1]), "the jump alone restarts"
    for i in range(3):
        alone, _ = fused_run(q[:, i:i + 1])
        torch.testing.assert_close(alone.mu_tilde[0], together.mu_tilde[i], atol=1e-9, rtol=0)
        torch.testing.assert_close(alone.free[0], together.free[i], atol=1e-9, rtol=1e-12)


BAD_FRAMES = {
    "shape": (lambda x: {"ee_xyz": x[:, :2]}, None, DT, r"frame 2: observations\['ee_xyz'\] must be"),
    "dtype": (lambda x: {"ee_xyz": x.to(torch.int64)}, None, DT, r"frame 2: observations\['ee_xyz'\] must be"),
    "non-finite": (lambda x: {"ee_xyz": x * float("nan")}, None, DT, "frame 2: .* must be finite"),
    "dt": (lambda x: {"ee_xyz": x}, None, 0.0, "frame 2: dt must be a positive"),
    "command": (lambda x: {"ee_xyz": x}, torch.zeros(4, 3), DT, "frame 2: command must be"),
    "modality": (lambda x: {"image": x}, None, DT, "frame 2: observations keys must be"),
}


@pytest.mark.parametrize("case", BAD_FRAMES, ids=list(BAD_FRAMES))
def test_a_bad_frame_raises_naming_it_and_leaves_the_state_unchanged(case):
    arm = ToyPlanarArm()
    q = trajectory(3, 4, seed=6)
    tracker = Tracker([arm], TrackerConfig(budget=3))
    for pose in q[:2]:
        tracker.step({"ee_xyz": arm.predict(pose)}, dt=DT)
    before = (tracker.mu_tilde.clone(), tracker.free.clone(), tracker.frames, tracker.last)
    frame, command, dt, message = BAD_FRAMES[case]
    with pytest.raises(ValueError, match=message):
        tracker.step(frame(arm.predict(q[2])), command, dt=dt)
    assert torch.equal(tracker.mu_tilde, before[0]) and torch.equal(tracker.free, before[1])
    assert tracker.frames == before[2] and tracker.last is before[3]
    tracker.step({"ee_xyz": arm.predict(q[2])}, dt=DT)                    # the next good frame is frame 2
    assert tracker.frames == 3


def test_a_settled_start_skips_the_updates_and_loses_nothing_on_a_still_arm():
    image = ToyBlobImage()
    q = trajectory(1, 4, seed=7).expand(8, 4, 2)                             # the arm holds still
    calibration = trajectory(50, 4, seed=3).reshape(-1, 2)
    evaluations, errors = {}, {}
    for settle in (None, 0.9):
        tracker = Tracker([image], TrackerConfig(budget=4, settle_quantile=settle), GridEncoder(image),
                          limits=ELBOW_BENT)
        tracker.calibrate({"image": seen(image, calibration, NOISE, seed=9)}, calibration)
        tracker.reset(q[0])
        mu, _ = run(tracker, q, image, sigma=NOISE)
        evaluations[settle] = tracker.last.evaluations
        errors[settle] = float((mu[-1] - q[-1]).abs().mean() / DEG)
    assert 2 <= evaluations[0.9] < evaluations[None], "a settled stream spends only the proposal's 2 evaluations"
    assert errors[0.9] <= errors[None], errors   # still: updates only jitter at the noise floor (0.4° vs 1.1°)


def test_bad_configs_raise():
    arm = ToyPlanarArm()
    with pytest.raises(ValueError, match="perception.order must be"):
        TrackerConfig(perception=PerceptionConfig(order=1))
    with pytest.raises(ValueError, match="budget must be at least 5"):
        Tracker([arm], TrackerConfig(perception=PerceptionConfig(method="adam+lm"), budget=4))
    with pytest.raises(ValueError, match="restart must be 'multistart'"):
        Tracker([arm], TrackerConfig(restart="guess"))
    with pytest.raises(ValueError, match="restart must be one of"):
        TrackerConfig(restart="encoder")
    with pytest.raises(ValueError, match="guess must be 'encoder' or 'auto' without a joints model"):
        Tracker([arm], TrackerConfig(guess="reading"))
    with pytest.raises(ValueError, match="guess must be 'reading' or 'auto' without an encoder"):
        Tracker([arm], TrackerConfig(guess="encoder"))
    with pytest.raises(ValueError, match="settle_quantile must be"):
        TrackerConfig(settle_quantile=1.0)
    with pytest.raises(ValueError, match="mu0 must be"):
        Tracker([arm]).reset(torch.zeros(2, 3))


def test_a_millisecond_budget_cuts_the_updates_once_the_cost_is_known():
    arm = ToyPlanarArm()
    q = trajectory(3, 2)
    tracker = Tracker([arm], TrackerConfig(budget=10, budget_ms=1e-6))
    tracker.reset(q[0])
    run(tracker, q, arm)
    assert tracker.last.steps == 2 and tracker.steps == 10   # under descent control 2 steps move a belief once


def test_free_energy_is_the_laplace_F_at_the_given_beliefs():
    arm = ToyPlanarArm(precision=1e4)
    q = trajectory(1, 5)[0]
    x = arm.predict(q) + 0.001
    mu = q + 0.05
    free = Perception([arm]).free_energy({"ee_xyz": x}, mu)
    expected = 0.5 * 1e4 * (x - arm.predict(mu)).pow(2).sum(-1) - 0.5 * 3 * math.log(1e4)
    torch.testing.assert_close(free, expected, rtol=1e-12, atol=1e-9)
