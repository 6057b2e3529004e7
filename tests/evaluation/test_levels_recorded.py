"""`evaluate levels --targets STORE`: the levels scored on a store's recorded frames equal the simulator's levels on
the same poses with the same seed, within float32 storage of q (the store keeps q as float32: ~1e-7 rad, so the
per-trial mean joint errors agree to TOLERANCE_DEG); the plain Pixel-AIF row comes beside the default update on the
same frames; the run records the target store's digest; bad targets are the house error."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.datagen.exchange.importers.run import import_recording
from bodyschema.evaluation.core.seeds import eval_rng
from bodyschema.evaluation.core.specs import load_robot
from bodyschema.evaluation.levels.benchmark import LevelsConfig, measure_levels, run_levels
from bodyschema.evaluation.levels.plain import PLAIN_LABEL
from bodyschema.evaluation.levels.targets import make_targets
from bodyschema.models.analytic import AnalyticModel
from tests.datagen.import_sources import write_folder
from tests.threads import one_thread

TOLERANCE_DEG = 1e-3      # per-trial mean |joint error|: float32 q in the store vs float64 in the simulator
TOLERANCE_MM = 1e-2


def _simulator_poses_as_recording(folder, models, config: LevelsConfig, image_size=None):
    """The poses (and renders) the simulator would draw for config's runs, written as a folder + CSV (rad, exact
    decimal repr) and imported with --fk: the recorded targets of the equality test."""
    robot = load_robot(models, image_size)
    runs = [make_targets(robot, config.trials, eval_rng(config.seed, r, "targets"), image_size is not None)
            for r in range(config.runs)]
    q = np.concatenate([t.q for t in runs])
    images = None
    if image_size is not None:
        with Robot.load(robot.name, image_size=image_size) as renderer:
            images = renderer.observe(q)["image"]
    write_folder(folder, q, images, names=robot.joint_names, deg=False)
    return import_recording(ImportConfig(source=folder, out=folder.with_suffix(".zarr"), angles="rad",
                                         robot=robot.name, fk=True, images=image_size is not None,
                                         ranges=tuple(map(tuple, robot.sampling_ranges))))


def _assert_same_levels(sim, rec):
    assert [r["level"] for r in sim.table] == [r["level"] for r in rec.table if PLAIN_LABEL not in str(r["level"])]
    for level, errors in sim.per_trial.items():
        np.testing.assert_allclose(rec.per_trial[level], errors, atol=TOLERANCE_DEG, err_msg=f"level {level}")
    recorded = {r["level"]: r for r in rec.table}
    for s in sim.table:
        r = recorded[s["level"]]
        assert abs(s["ee_err_mm"] - r["ee_err_mm"]) < TOLERANCE_MM and s["success"] == r["success"], s["level"]


def test_levels_on_recorded_targets_equal_the_simulators_on_the_same_poses(tmp_path):
    models = [AnalyticModel("nao_arm", "ee_xyz"), AnalyticModel("nao_arm", "ee_pixel")]
    config = LevelsConfig(trials=12, runs=2, multistart=4, screen_steps=3, mlflow=False, progress=False, plots=False,
                          out=tmp_path / "res")
    store = _simulator_poses_as_recording(tmp_path / "rec", models, config)
    sim, _ = measure_levels(config, models)
    rec, _ = measure_levels(replace(config, targets=store), models)
    _assert_same_levels(sim, rec)
    assert {"1", "2", "3", "3+ms"} <= set(rec.per_trial)


def test_image_levels_on_recorded_frames_with_the_plain_pixel_aif_row(tmp_path, tiny_decoder):
    config = LevelsConfig(trials=4, runs=1, levels=(1, 3), multistart=0, plain_steps=30, mlflow=False,
                          progress=False, out=tmp_path / "res",
                          perception=replace(LevelsConfig().perception, max_steps=20))   # seconds, not minutes
    store = _simulator_poses_as_recording(tmp_path / "rec", [tiny_decoder], config, image_size=(16, 16))
    with one_thread():
        sim, _ = measure_levels(config, [tiny_decoder])
        summary = run_levels(replace(config, targets=store), models=[tiny_decoder])
    _assert_same_levels(sim, summary)
    labels = [r["level"] for r in summary.table]
    assert labels == ["1", f"1 {PLAIN_LABEL}", "3", f"3 {PLAIN_LABEL}"]
    plain = next(r for r in summary.rows if r["level"] == f"1 {PLAIN_LABEL}")
    assert plain["steps"] == 30 and plain["trials"] == 4
    text = summary.paths["summary_md"].read_text()
    assert f"1 {PLAIN_LABEL}" in text and "wins" in text
    lineage = json.loads(summary.paths["targets_json"].read_text())
    from bodyschema.datagen.store.reader import store_digest
    from bodyschema.datagen.store.schema import open_store
    assert lineage["sha256"] == store_digest(open_store(store)) and lineage["frames"] == 4


@pytest.fixture(scope="module")
def tiny_decoder():
    """A pixel decoder of planar2's 16 × 16 camera, fitted for a few epochs at a small constant step: its accuracy
    does not matter here, the smoothness of its F does. The float32 poses of a store and the simulator's float64 ones
    must end each trial within TOLERANCE_DEG; at lean's default step (4e-3, wsd) three epochs left F rough enough for
    that rounding to move a floor trial by 0.33°, and with the default inputs (learned products of cos and sin,
    models/pose_inputs.py) by 0.027° (0.004° after 20 epochs on 512 images): it reads u."""
    import torch

    from bodyschema.models.pixel import PixelDecoder
    from bodyschema.models.scaling import BodySpec

    torch.manual_seed(0)
    with Robot.load("planar2", image_size=(16, 16)) as robot:
        q = np.random.default_rng(0).uniform(*robot.sampling_ranges.T, size=(64, 2))
        images = torch.from_numpy(robot.observe(q)["image"]).float() / 255.0
        body = BodySpec(robot.name, robot.joint_names, *map(tuple, robot.sampling_ranges.T))
    model = PixelDecoder(body, "image", (16, 16), fc_hidden=16, channels=(8, 4), epochs=3, batch_size=32, lr=2e-3,
                         lr_schedule="constant", inputs="unit")
    with one_thread():
        return model.fit(torch.from_numpy(q).float()[:48], images[:48],
                         val=(torch.from_numpy(q).float()[48:], images[48:]), progress=False)


def test_targets_of_another_body_or_without_the_observed_array_are_refused(tmp_path):
    models = [AnalyticModel("planar2", "ee_xyz")]
    config = LevelsConfig(trials=3, runs=1, mlflow=False, progress=False, plots=False, out=tmp_path / "res")
    store = _simulator_poses_as_recording(tmp_path / "rec", models, config)
    with pytest.raises(ValueError, match="robot 'planar2'"):
        measure_levels(replace(config, targets=store), [AnalyticModel("nao_arm", "ee_xyz")])
    with pytest.raises(ValueError, match="at least trials × runs"):
        measure_levels(replace(config, targets=store, trials=4), models)
    plain = import_recording(ImportConfig(source=tmp_path / "rec", out=tmp_path / "q_only.zarr", angles="rad",
                                          robot="planar2", images=False))
    with pytest.raises(ValueError, match=r"--targets arrays \['ee_xyz'\]"):
        measure_levels(replace(config, targets=plain), models)
