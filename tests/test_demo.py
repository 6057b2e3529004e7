"""The demo's own parts: its stage clock, its models section, and its new flags checked before any work (the flags'
common bounds: tests/reliability/test_flag_bounds.py; the decoder floor it prints, now the levels' floor row:
tests/evaluation/test_levels_floor.py)."""

import dataclasses
import types

import pytest

from bodyschema import demo, demo_config


def test_the_stage_clock_keeps_every_stage_a_failing_one_too():
    clock = demo._Stages()
    assert clock("first", lambda a, b: a + b, 1, 2) == 3
    with pytest.raises(RuntimeError):
        clock("second", lambda: (_ for _ in ()).throw(RuntimeError("stage failed")))
    assert list(clock.seconds) == ["first", "second"] and all(s >= 0 for s in clock.seconds.values())
    assert clock.summary().startswith("demo stages (wall s): first ") and " · total " in clock.summary()


@pytest.mark.parametrize("flag, value", [("pixel_trials", 0), ("encoder_epochs", 0), ("streams", 0),
                                         ("stream_seconds", 0.0)])
def test_the_new_demo_flags_are_checked_before_any_work_naming_the_flag(flag, value, tmp_path):
    config = dataclasses.replace(demo_config.DemoConfig(out=tmp_path / "demo"), **{flag: value})
    with pytest.raises(ValueError, match=" must be ") as error:
        demo_config.check_demo(config)
    assert f"--{flag.replace('_', '-')}" in str(error.value)


def test_the_pixel_levels_use_the_encoder_not_multistart_and_the_tracking_episode_the_demos_models(tmp_path):
    config = demo_config.DemoConfig(out=tmp_path)
    pixel = demo_config.levels_config(config, "models:/dec/1", "pixel", "models:/enc/1")
    gpr = demo_config.levels_config(config, "models:/gpr@champion", "gpr")
    assert (pixel.trials, pixel.multistart, pixel.encoder) == (config.pixel_trials, 0, "models:/enc/1")
    assert (gpr.trials, gpr.encoder) == (config.trials, None) and gpr.multistart > 0
    tracking = demo_config.tracking_config(config, "models:/dec/1", "models:/enc/1")
    assert (tracking.models, tracking.encoder, tracking.trials, tracking.duration) == (
        ("models:/dec/1",), "models:/enc/1", config.streams, config.stream_seconds)
    assert tracking.out == tmp_path / "results" / "tracking", "its section in the demo's report"


def test_the_models_section_says_what_each_trained_model_is_and_the_decoders_floor(tmp_path, monkeypatch):
    import bodyschema.training.registry as registry

    def trained(kind: str, epochs: int) -> types.SimpleNamespace:
        run_dir = tmp_path / "runs" / kind
        run_dir.mkdir(parents=True)
        (run_dir / "history.jsonl").write_text("{}\n" * epochs)
        return types.SimpleNamespace(registered_name=f"bodyschema-{kind}", model_version="3", run_id=kind,
                                     run_dir=run_dir, metrics={"fit_seconds": 12.5, "val_rmse": 0.25})

    runs = {"gpr": types.SimpleNamespace(data=types.SimpleNamespace(params={"n_train": "1500"}))}
    runs["pixel"] = runs["encoder"] = types.SimpleNamespace(data=types.SimpleNamespace(params={"n_train": "1638"}))
    monkeypatch.setattr(registry, "use_tracking", lambda uri: types.SimpleNamespace(get_run=runs.__getitem__))
    config = demo_config.DemoConfig(out=tmp_path / "demo")
    note = demo._models_section(config, {"gpr": trained("gpr", 0), "pixel": trained("pixel", 30),
                                         "encoder": trained("encoder", 20)}, 2.345)
    assert "30 epochs on 1638 images in 12 s" in note and "2.35°" in note and "20-epoch encoder" in note
    assert demo.RECIPE in note
    folder = tmp_path / "demo" / "results" / "models"
    text = (folder / "summary.md").read_text()
    assert "| bodyschema-gpr v3 | 1500 | – |" in text, "a GP has no epochs"
    assert "| bodyschema-pixel v3 | 1638 | 30 |" in text and text.endswith(note + "\n")
    assert (folder / "models.csv").read_text().splitlines()[0] == "model,train_samples,fit_s,val_rmse,epochs,floor_deg"
