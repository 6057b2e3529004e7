"""Training plots are real PNGs for every output layout, and nothing is drawn when there is nothing to draw."""

import numpy as np
import pytest

from bodyschema.training import plots

PNG = b"\x89PNG\r\n\x1a\n"


def test_loss_curves_draws_losses_and_skips_an_empty_history(tmp_path):
    history = {e: {"train_loss": 1.0 / (e + 1), "val_loss": 1.2 / (e + 1), "epoch_seconds": 0.1} for e in range(5)}
    path = plots.loss_curves(history, tmp_path / "c.png", "t")
    assert path.read_bytes().startswith(PNG)
    assert plots.loss_curves({}, tmp_path / "none.png", "t") is None and not (tmp_path / "none.png").exists()


def test_the_gp_marginal_likelihood_is_a_curve_not_one_point(tmp_path):
    """GPR logs `train_neg_mll` at every MLL evaluation and its validation scores once at the end: both are drawn."""
    history = {step: {"train_neg_mll": 3.0 - 0.01 * step} for step in range(1, 251)}
    history[250] = {**history[250], "val_rmse": 1e-4, "val_mean_error": 8e-5}
    lines = plots.curves(history)
    assert len(lines["train_neg_mll"]) == 250 and lines["val_rmse"] == [(250, 1e-4)]
    assert plots.loss_curves(history, tmp_path / "gp.png", "gp").read_bytes().startswith(PNG)


@pytest.mark.parametrize("shape", [(8, 8), (8, 6, 3)])
def test_image_grid_handles_gray_and_rgb(tmp_path, shape):
    rng = np.random.default_rng(0)
    target, pred = rng.random((3, *shape)), rng.random((3, *shape))
    assert plots.image_grid(target, pred, tmp_path / "g.png", "t").read_bytes().startswith(PNG)


def test_prediction_scatter_one_panel_per_output(tmp_path):
    rng = np.random.default_rng(0)
    x = rng.random((50, 5))
    assert plots.prediction_scatter(x, x + 0.01, tmp_path / "s.png", "m", "t").read_bytes().startswith(PNG)
