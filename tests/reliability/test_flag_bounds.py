"""Bounds and validation of the evaluate / train / demo flags (issue 25): every count and duration of every benchmark
has an upper bound with its reason, no number is accepted NaN, infinite or negative, a network too large for memory
is refused before a run exists, and the demo checks every flag before its first dataset."""

from __future__ import annotations

import dataclasses
import math

import pytest

from bodyschema.evaluation import registry
from bodyschema.evaluation.core.config import BOUNDED_ELSEWHERE, LIMITS
from bodyschema.models.scaling import BodySpec

BENCHMARKS = [pytest.param(b, id=" ".join(b.words)) for b in registry.BENCHMARKS]
BODY = BodySpec("r", ("a", "b", "c", "d"), (-1.0,) * 4, (1.0,) * 4)


def leaves(config, path=()):
    """(path, value) of every number of a config, nested configs and tuple items included; a path is a tuple of field
    names and tuple indices."""
    for field in dataclasses.fields(config):
        yield from _leaves(getattr(config, field.name), (*path, field.name))


def _leaves(value, path):
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        yield from leaves(value, path)
    elif isinstance(value, tuple):
        for i, item in enumerate(value):
            yield from _leaves(item, (*path, i))
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        yield path, value


def with_value(value, path, new):
    """A copy of `value` (a config or tuple) with the leaf at `path` set to `new`; configs are rebuilt (and so
    checked) from the leaf up."""
    if not path:
        return new
    head, rest = path[0], path[1:]
    if isinstance(head, int):
        return tuple(with_value(v, rest, new) if i == head else v for i, v in enumerate(value))
    return dataclasses.replace(value, **{head: with_value(getattr(value, head), rest, new)})


def field_name(path) -> str:
    return next(p for p in reversed(path) if isinstance(p, str))


@pytest.mark.parametrize("benchmark", BENCHMARKS)
def test_every_integer_of_a_benchmark_is_a_bounded_count_or_bounded_elsewhere(benchmark):
    unbounded = {field_name(path) for path, value in leaves(benchmark.config())
                 if isinstance(value, int)} - set(LIMITS) - set(BOUNDED_ELSEWHERE)
    assert not unbounded, f"{benchmark.words}: counts without an upper bound in core/config.LIMITS: {unbounded}"


@pytest.mark.parametrize("benchmark", BENCHMARKS)
def test_every_count_and_duration_is_refused_above_its_bound_with_the_reason(benchmark):
    config = benchmark.config()
    limited = [(path, value) for path, value in leaves(config) if field_name(path) in LIMITS]
    assert limited, "every benchmark has trials at least"
    for path, value in limited:
        limit = LIMITS[field_name(path)]
        above = math.floor(limit.most) + 1 if isinstance(value, int) else limit.most * 2
        with pytest.raises(ValueError, match=f"{field_name(path)} must be at most") as error:
            with_value(config, path, above)
        assert limit.why in str(error.value)


@pytest.mark.parametrize("benchmark", BENCHMARKS)
def test_no_number_of_a_benchmark_is_accepted_nan_infinite_or_negative(benchmark):
    config, accepted = benchmark.config(), []
    for path, value in leaves(config):
        for bad in ((math.nan, math.inf, -1.0) if isinstance(value, float) else (-1,)):
            try:
                with_value(config, path, bad)
                accepted.append((path, bad))
            except ValueError as error:
                assert field_name(path) in str(error), f"{path}={bad}: the error does not name the field: {error}"
    assert not accepted, f"{benchmark.words}: accepted {accepted}"


@pytest.mark.parametrize("benchmark", BENCHMARKS)
def test_the_seconds_long_config_of_every_benchmark_stays_within_the_bounds(benchmark, tmp_path):
    benchmark.tiny(tmp_path)


def test_a_bad_tuple_value_is_named_with_the_value_itself_not_a_dtype():
    from bodyschema.evaluation.robustness import RobustnessConfig

    with pytest.raises(ValueError, match=r"sigmas must be finite numbers ≥ 0\. Got \(inf,\)"):
        RobustnessConfig(sigmas=(math.inf,))


@pytest.mark.parametrize("words, changes, derived", [
    (("rubber-hand",), dict(period=1e-9), "frames (duration / period)"),
    (("rubber-hand",), dict(stroke_rate_hz=1e9, stroke_jitter_s=0.0), "strokes (duration × stroke_rate_hz)"),
    (("agency",), dict(period=1e6), "steps × period"),
    (("self-recognition",), dict(period=1e6), "steps × period"),
])
def test_counts_a_config_derives_are_bounded_too(words, changes, derived):
    import re

    benchmark = next(b for b in registry.BENCHMARKS if b.words == words)
    with pytest.raises(ValueError, match=f"{re.escape(derived)} must be at most"):
        benchmark.config(**changes)


def test_an_integer_too_large_for_a_float_is_refused_not_overflowed():
    from bodyschema.evaluation.levels import LevelsConfig

    with pytest.raises(ValueError, match="trials must be at most"):
        LevelsConfig(trials=10 ** 400)


# ---- train ------------------------------------------------------------------------------------------------------
def test_duplicate_modalities_are_refused():
    from bodyschema.models.configs import MultimodalConfig
    from bodyschema.training.config import TrainConfig

    for modality in ("ee_xyz,ee_xyz", "ee_xyz, image,ee_xyz"):
        with pytest.raises(ValueError, match="modality must be distinct array names"):
            TrainConfig(model=MultimodalConfig(), data="d.zarr", modality=modality)


@pytest.mark.parametrize("field", ["epochs", "batch_size", "patience"])
def test_a_count_every_fit_refuses_at_zero_is_refused_when_parsed(field):
    from bodyschema.models.configs import MDNConfig, PixelConfig

    for config in (MDNConfig, PixelConfig):
        with pytest.raises(ValueError, match=f"--{field.replace('_', '-')} must be an integer ≥ 1"):
            config(**{field: 0})


def networks():
    from bodyschema.models.encoder import ImageEncoder
    from bodyschema.models.mdn import MDNModel
    from bodyschema.models.multimodal import MultimodalModel
    from bodyschema.models.pixel import PixelDecoder

    return {"mdn": MDNModel(BODY, "ee_xyz", (3,)), "pixel": PixelDecoder(BODY, "image", (16, 24)),
            "encoder": ImageEncoder(BODY, "image", (16, 24)),
            "multimodal": MultimodalModel(BODY, {"ee_xyz": (3,), "image": (16, 24)})}


@pytest.mark.parametrize("kind", ["mdn", "pixel", "encoder", "multimodal"])
def test_a_network_is_counted_on_the_meta_device_as_the_real_one(kind):
    import torch

    from bodyschema.training import guards

    model = networks()[kind]
    params, activations = guards.net_sizes(model)
    members = getattr(model, "members", {"": model}).values()
    real = sum(p.numel() for m in members for p in m._factory().parameters())
    outputs = sum(math.prod(m.output_shape) if hasattr(m, "output_shape") else m.latent_dim for m in members)
    assert params == real and activations >= outputs
    assert torch.get_default_device() == torch.device("cpu"), "the meta device does not leak"


def test_a_network_too_large_for_memory_is_refused_naming_what_to_shrink():
    from bodyschema.models.pixel import PixelDecoder
    from bodyschema.training import guards

    huge = PixelDecoder(BODY, "image", (56, 80), channels=(100_000, 100_000))
    with pytest.raises(ValueError, match=r"network fit memory must be at most .*--channels"):
        guards.check_memory("pixel", huge, 1000, (56, 80))


@pytest.mark.parametrize("kind", ["mdn", "pixel", "encoder", "multimodal"])
def test_the_guard_scales_with_the_batch_and_passes_default_networks(kind):
    from bodyschema.training import guards

    model = networks()[kind]
    params, activations = guards.net_sizes(model)
    need = guards.net_peak_bytes(params, activations, 64)
    assert guards.net_peak_bytes(params, activations, 128) > need
    guards.check_memory(kind, model, 10_000, (3,), available=2 * need / guards.LIMIT_FRACTION)
    with pytest.raises(ValueError, match="network fit memory"):
        guards.check_memory(kind, model, 10_000, (3,), available=0.5 * need / guards.LIMIT_FRACTION)


# ---- demo -------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("flag, value", [("episodes", 1), ("runs", 0), ("trials", 100_000), ("reach_targets", 0),
                                         ("pixel_epochs", 0), ("workers", 0), ("n_nao", 0)])
def test_every_demo_flag_is_checked_before_any_work_naming_the_demo_flag(flag, value, tmp_path, monkeypatch):
    import importlib

    from bodyschema import demo
    from bodyschema.demo_config import DemoConfig

    generate = importlib.import_module("bodyschema.datagen.generate")
    monkeypatch.setattr(generate, "generate", lambda *a, **k: pytest.fail("datagen started before the check"))
    config = dataclasses.replace(DemoConfig(out=tmp_path / "demo"), **{flag: value})
    with pytest.raises(ValueError, match=" must be ") as error:
        demo.run_demo(config)
    assert f"--{flag.replace('_', '-')}" in str(error.value)
    assert not any(tmp_path.iterdir()), "nothing is written"


def test_the_default_demo_passes_its_check(tmp_path):
    from bodyschema.demo_config import DemoConfig, check_demo

    check_demo(DemoConfig(out=tmp_path))
