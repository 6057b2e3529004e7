"""Resource guards: a GP on images is refused outright; a GP fit whose memory estimate exceeds the available memory
is refused before any work, naming the limit and the --max-train that fits."""

import re

import pytest

from bodyschema.models.configs import GPRConfig, MDNConfig, SklearnGPRConfig
from bodyschema.training import guards
from bodyschema.training.config import TrainConfig, untrained_model
from bodyschema.training.data import load_dataset
from bodyschema.training.train import train

GB = 1e9


@pytest.mark.parametrize("hyper", [GPRConfig(), SklearnGPRConfig()])
def test_a_gp_on_images_is_refused_before_anything_is_loaded(hyper, workdir, tmp_path):
    assert guards.gp_memory(hyper.kind) is not None, "the kind's class declares the GP memory guard"
    config = TrainConfig(model=hyper, data=tmp_path / "never-read.zarr", modality="image", progress=False)
    with pytest.raises(ValueError, match=r"model must be 'pixel' for modality 'image'. .*`bodyschema train pixel`"):
        train(config)
    assert not (workdir / "runs").exists()


def test_the_estimate_grows_with_n_squared_and_with_outputs_for_gpr_only():
    base = guards.gp_peak_bytes("gpr", n=1000, m=100, outputs=3)
    assert guards.gp_peak_bytes("gpr", n=2000, m=100, outputs=3) == pytest.approx(4 * base)
    assert guards.gp_peak_bytes("gpr", n=1000, m=100, outputs=6) == pytest.approx(2 * base)
    sk = guards.gp_peak_bytes("sklearn-gpr", n=1000, m=100, outputs=3)
    assert guards.gp_peak_bytes("sklearn-gpr", n=1000, m=100, outputs=4480) == sk, "one kernel for all outputs"
    # The image GP of the issue (56×80 outputs, 5000 samples) needs terabytes.
    assert guards.gp_peak_bytes("gpr", n=5000, m=500, outputs=4480) > 1e12


def test_a_gp_too_big_for_the_memory_is_refused_with_a_max_train_that_fits(kin_store, workdir, monkeypatch):
    data = load_dataset(kin_store, "ee_xyz")
    model = untrained_model(TrainConfig(model=GPRConfig(), data=kin_store), data.body, {"ee_xyz": (3,)})
    need = guards.gp_peak_bytes("gpr", len(data.train), min(len(data.train), 500), 3)
    available = need / 2                                                # half of what this fit needs
    with pytest.raises(ValueError, match=r"gpr fit memory must be at most .* GB \(80% of the .* GB available\)\. "
                                         r"Got 'an estimated .* GB for n=320 samples × 3 outputs") as info:
        guards.check_memory("gpr", model, len(data.train), (3,), available=available)
    fits = int(re.search(r"--max-train (\d+)", str(info.value))[1])
    assert 2 <= fits < len(data.train)
    guards.check_memory("gpr", model, fits, (3,), available=available)   # the advice is enough
    mdn = untrained_model(TrainConfig(model=MDNConfig(), data=kin_store), data.body, {"ee_xyz": (3,)})
    assert mdn.gp_memory is None and mdn.network, "a network is guarded by its size, not by n²"
    guards.check_memory("mdn", mdn, 10 ** 9, (3,), available=1e12)

    monkeypatch.setattr(guards, "available_memory", lambda: available)  # end to end: refused before a run exists
    with pytest.raises(ValueError, match="gpr fit memory must be at most"):
        train(TrainConfig(model=GPRConfig(), data=kin_store, modality="ee_xyz", progress=False))
    assert not (workdir / "runs").exists() and not (workdir / "mlartifacts").exists()


def test_available_memory_is_a_positive_number_of_bytes():
    assert 0 < guards.available_memory() < 1e15
