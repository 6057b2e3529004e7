"""Issue 22, item 4: aif owns the choice of update. "auto" is resolved by the Perception from its models for every
caller (levels, goal inference, self-recognition, the controller); each algorithm's knobs are one group of
PerceptionConfig while the CLI keeps their flat spellings; multi-start varies a config through
`Perception.with_config`. Bad values of the grouped knobs are clear CLI errors naming the flag as typed."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from bodyschema import cli
from bodyschema.aif.action import VelocityController
from bodyschema.aif.multistart import infer_multistart
from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import AdamSettings, FlowSettings, LMSettings, PerceptionConfig
from bodyschema.evaluation.core.mlflow_log import config_params
from bodyschema.evaluation.levels.benchmark import LevelsConfig
from bodyschema.evaluation.self_recognition.benchmark import SelfRecognitionConfig
from tests.aif.toys import ToyBlobImage, ToyJoints, perturb, planar_poses
from tests.test_cli_fuzz import run_and_check
from tests.toy_models import ToyPlanarArm

WITH_IMAGE = (ToyBlobImage, ToyJoints)
KINEMATIC = (ToyPlanarArm, ToyJoints)


def resolved(config: PerceptionConfig, kinds) -> PerceptionConfig:
    return Perception([kind() for kind in kinds], config).config


@pytest.mark.parametrize("kinds, method", [(WITH_IMAGE, "adam+lm"), (KINEMATIC, "flow"), ((ToyBlobImage,), "adam+lm")])
def test_auto_is_adam_then_lm_with_an_image_model_else_the_flow(kinds, method):
    assert resolved(PerceptionConfig(), kinds).method == method


def test_every_benchmark_passes_auto_and_gets_the_same_update_for_the_same_models():
    levels = LevelsConfig().perception
    recognition = SelfRecognitionConfig().perception
    assert levels.method == recognition.method == "auto"
    for kinds in (WITH_IMAGE, KINEMATIC):
        assert resolved(levels, kinds).method == resolved(recognition, kinds).method == resolved(PerceptionConfig(),
                                                                                                  kinds).method


@pytest.mark.parametrize("benchmark, config", [("levels", LevelsConfig), ("self-recognition", SelfRecognitionConfig)])
def test_the_perception_method_is_one_knob(benchmark, config, capsys):
    """--perception.method chooses the update; the former alias --update is gone (one knob, no legacy spelling)."""
    assert "update" not in {f.name for f in dataclasses.fields(config)}
    try:
        code = cli.main(["evaluate", benchmark, "--update", "lm"])
    except SystemExit as stop:                                    # tyro's parse error exits 2
        code = stop.code
    assert code == 2
    assert "--update" in capsys.readouterr().err


@pytest.mark.parametrize("order", [1, 2])
def test_above_order_0_auto_is_the_flow_without_descent_control_even_with_an_image_model(order):
    config = resolved(PerceptionConfig(order=order, prior="damping"), WITH_IMAGE)
    assert config.method == "flow" and config.flow.step_control == "none" and not config.descends


def test_a_chosen_update_is_kept_and_step_control_auto_follows_the_order():
    assert resolved(PerceptionConfig(method="lm"), KINEMATIC).method == "lm"
    assert resolved(PerceptionConfig(method="flow"), WITH_IMAGE).method == "flow"
    assert resolved(PerceptionConfig(), KINEMATIC).flow.step_control == "descent"
    kept = PerceptionConfig(flow=FlowSettings(step_control="none"))
    assert resolved(kept, KINEMATIC).flow.step_control == "none"


def test_the_controller_resolves_auto_to_the_flow_without_descent_even_with_an_image_model():
    controller = VelocityController([ToyBlobImage(), ToyJoints()], PerceptionConfig())
    config = controller.perception.config
    assert config.method == "flow" and config.flow.step_control == "none" and config.prior == "attractor"


def test_with_config_keeps_models_overrides_and_limits_and_leaves_the_original_alone():
    arm, joints = ToyPlanarArm(), ToyJoints()
    limits = ([-1.0, -0.5], [1.0, 2.0])
    base = Perception([arm, joints], PerceptionConfig(precisions=(("ee_xyz", 1e4),)), {"joints": 50.0}, limits)
    short = dataclasses.replace(base.config, max_steps=3, precisions=(("ee_xyz", 1e3),))
    varied = base.with_config(short)
    assert varied.models == base.models and varied.config == short
    assert varied.precisions == {"ee_xyz": 1e3, "joints": 50.0}                 # the call's override still wins
    assert torch.equal(varied.low, base.low) and torch.equal(varied.high, base.high)
    assert base.config.max_steps == 300 and base.precisions == {"ee_xyz": 1e4, "joints": 50.0}
    q = planar_poses(8, seed=1)
    obs, mu0 = {"ee_xyz": arm.predict(q), "joints": q}, perturb(q, seed=2)
    fresh = Perception([arm, joints], short, {"joints": 50.0}, limits).infer(obs, mu0)
    torch.testing.assert_close(varied.infer(obs, mu0).mu, fresh.mu, rtol=0, atol=0)


def test_multistart_screens_with_the_short_config_and_refines_with_the_full_one():
    arm = ToyPlanarArm()
    perception = Perception([arm])
    q = planar_poses(6, seed=3)
    starts = torch.stack([perturb(q, seed=s, max_rad=1.0) for s in (4, 5, 6)], dim=1)   # (B, S, Dz) rad
    result = infer_multistart(perception, {"ee_xyz": arm.predict(q)}, starts, screen_steps=2, keep=1)
    screen = perception.with_config(dataclasses.replace(perception.config, max_steps=2)).infer(
        {"ee_xyz": arm.predict(q).repeat_interleave(3, dim=0)}, starts.reshape(-1, 2))
    torch.testing.assert_close(result.screen_F, screen.F.reshape(6, 3), rtol=0, atol=0)
    assert perception.config.max_steps == 300                              # the caller's perception as it was


def parse(*flags: str):
    argv = ["evaluate", "levels", *flags]
    return cli.parse_command(argv)


def test_the_cli_keeps_every_perception_flag_flat_and_fills_the_groups():
    config = parse("--perception.dt", "5", "--perception.step-control", "none", "--perception.damping", "2",
                   "--perception.lr", "0.1", "--perception.handover", "0.05", "--perception.max-steps", "7")
    p = config.perception
    assert p.flow == FlowSettings(dt=5.0, step_control="none") and p.lm == LMSettings(damping=2.0)
    assert p.adam == AdamSettings(lr=0.1, handover=0.05) and p.max_steps == 7


def test_mlflow_params_name_every_grouped_knob():
    params = config_params(LevelsConfig())
    # the levels' static step (evaluation/levels/benchmark.py STATIC_DT), not the library's 1000
    assert params["perception.flow.dt"] == "1.0" and params["perception.adam.lr"] == "0.02"
    assert params["perception.method"] == "auto" and "update" not in params


CASES = [   # (id, argv): a bad value of a grouped knob, named as the flag is typed
    ("levels-perception-lr-inf", "evaluate levels --perception.lr inf --out {W}/res"),
    ("levels-perception-damping-negative", "evaluate levels --perception.damping -1 --out {W}/res"),
    ("levels-perception-step-control-typo", "evaluate levels --perception.step-control descend --out {W}/res"),
    ("levels-perception-method-typo", "evaluate levels --perception.method newton --out {W}/res"),
    ("levels-grouped-spelling", "evaluate levels --perception.adam.lr 0.1 --out {W}/res"),
]
NAMED = {"levels-perception-lr-inf": "perception.lr must be", "levels-perception-damping-negative": "damping must be",
         "levels-perception-step-control-typo": "step_control must be",
         "levels-perception-method-typo": "method must be"}


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return tmp_path_factory.mktemp("aif_config")            # the cases fail before any store is read


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_a_bad_perception_flag_is_a_clear_error(case_id, command, in_world, capsys):
    err = run_and_check(case_id, command, in_world, capsys)
    assert NAMED.get(case_id, "") in err, err
