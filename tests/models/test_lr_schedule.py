"""The training loop's learning-rate schedule (`_nn_fit.TrainSettings.lr_schedule`): "constant" leaves Adam's step
alone (the same weights as before the option existed); "cosine" scales it by ½(1 + cos(π t/T)) over the T steps of
`epochs`; "wsd" holds it until the last fifth of them and decays it over that fifth; an unknown name is the house
error; the neural kinds take it, save it and load it back."""

import math

import pytest
import torch
from torch import nn

from bodyschema.models import _nn_fit
from bodyschema.models.contract import load_model
from tests.models.test_pixel import blob_images, joint_angles, tiny_decoder
from tests.threads import one_thread


def test_the_cosine_factor_runs_from_one_through_a_half_to_zero():
    factors = [_nn_fit.schedule_factor("cosine", step, 10) for step in (0, 5, 10, 12)]
    assert factors == pytest.approx([1.0, 0.5, 0.0, 0.0], abs=1e-12)      # past the cap (a resume): still 0
    assert _nn_fit.schedule_factor("constant", 7, 10) == 1.0
    wsd = [_nn_fit.schedule_factor("wsd", step, 10) for step in range(11)]
    assert wsd == pytest.approx([1.0] * 9 + [0.5, 0.0], abs=1e-12)         # steps 8–9 are the last fifth


def test_an_unknown_schedule_is_the_house_error():
    with pytest.raises(ValueError, match=r"lr_schedule must be one of \['constant', 'cosine', 'wsd'\]. Got 'linear'"):
        _nn_fit.TrainSettings(lr_schedule="linear")


def _slide(schedule: str, steps: int, lr: float = 0.01) -> float:
    """One weight w under the loss w (a constant gradient): Adam moves it by lr × the step's factor each step
    (m/√v = 1 for a constant gradient, up to eps), so its final value is −lr × Σ factors."""

    class Weight(nn.Module):
        def __init__(self):
            super().__init__()
            self.w = nn.Parameter(torch.zeros(()))

    module = Weight()
    data = (torch.zeros(4, 1),)                          # one batch of 4 rows: one step per epoch
    settings = _nn_fit.TrainSettings(steps, 4, lr, patience=steps, lr_schedule=schedule)
    with one_thread():
        _nn_fit.train(module, lambda m, x: m.w + 0 * x.sum(), data, settings, torch.Generator().manual_seed(0))
    return float(module.w.detach())


def test_a_schedule_moves_adam_by_the_sum_of_its_factors():
    steps, lr = 20, 0.01
    # Σ_{t<T} ½(1 + cos(π t/T)) = T/2 + ½ (the cosines sum to 1): half the constant step's distance, plus half a step
    assert _slide("cosine", steps, lr) == pytest.approx(-lr * (steps / 2 + 0.5), rel=1e-5)
    assert _slide("constant", steps, lr) == pytest.approx(-lr * steps, rel=1e-5)
    # wsd: 16 full steps, then the same half cosine over the last 4: 16 + 4/2 + ½
    assert _slide("wsd", steps, lr) == pytest.approx(-lr * (16 + 2 + 0.5), rel=1e-5)


def test_a_pixel_decoder_keeps_its_schedule_through_save_and_load(tmp_path):
    q = joint_angles(64, seed=0)
    with one_thread():
        model = tiny_decoder(epochs=3, lr_schedule="cosine").fit(q, blob_images(q))
    model.save(tmp_path / "m")
    loaded = load_model(tmp_path / "m")
    assert loaded.settings.lr_schedule == "cosine"
    assert torch.equal(loaded.predict(q[:3].double()), model.predict(q[:3].double()))
    assert math.isfinite(model.fit_info_["best_loss"])
