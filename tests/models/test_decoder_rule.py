"""Training until the held-out error stops improving (`_nn_fit.train`: `epochs` is a cap, `patience` ends it)."""

import logging

import torch
from torch import nn

from bodyschema.models import _nn_fit
from tests.threads import one_thread


def _noisy_regression(seed: int = 0):
    """16 training and 16 held-out rows of a line plus noise: a 64-wide MLP fits the noise, the held-out loss
    falls, then rises. (x (N, 2), y (N, 1)) per split."""
    gen = torch.Generator().manual_seed(seed)
    x = torch.rand(32, 2, generator=gen) * 2 - 1
    y = x.sum(1, keepdim=True) + 0.3 * torch.randn(32, 1, generator=gen)
    return (x[:16], y[:16]), (x[16:], y[16:])


def _mse(m, x, y):
    return (m(x) - y).pow(2).mean()


def _fit(seed: int, patience: int, epochs: int = 400):
    with one_thread():
        return _fit_here(seed, patience, epochs)


def _fit_here(seed: int, patience: int, epochs: int):
    train, val = _noisy_regression()
    gen = torch.Generator().manual_seed(seed)
    net = _nn_fit.build(lambda: nn.Sequential(nn.Linear(2, 64), nn.ELU(), nn.Linear(64, 64), nn.ELU(),
                                              nn.Linear(64, 1)), gen)
    seen = []
    info = _nn_fit.train(net, _mse, train, _nn_fit.TrainSettings(epochs, 8, 1e-2, patience), gen, val=val,
                         on_epoch=lambda epoch, m: seen.append(m["val_loss"]))
    return net, info, seen, val


def test_training_stops_once_the_held_out_loss_stops_improving_and_keeps_the_best_epochs_weights(caplog):
    with caplog.at_level(logging.INFO, logger="bodyschema.models._nn_fit"):
        net, info, seen, val = _fit(seed=0, patience=5)
    best = min(range(len(seen)), key=seen.__getitem__)
    assert info["stopped_early"] and info["epochs_run"] == len(seen) < 400          # before the cap
    assert info["best_epoch"] == best and info["epochs_run"] == best + 1 + 5        # `patience` epochs past the best
    assert seen[-1] > seen[best]                                                    # the last epoch's were worse
    assert _nn_fit.evaluate(net, _mse, val, 8) == seen[best] == info["best_loss"]    # and the best's are returned
    assert f"stopped after {len(seen)} of at most 400 epochs" in caplog.text
    assert f"kept epoch {best + 1}'s weights" in caplog.text


def test_the_cap_ends_a_fit_still_improving_and_a_seed_gives_one_model(caplog):
    with caplog.at_level(logging.INFO, logger="bodyschema.models._nn_fit"):
        _, info, seen, _ = _fit(seed=0, patience=5, epochs=3)
    assert not info["stopped_early"] and info["epochs_run"] == len(seen) == 3
    assert "ran all 3 epochs (the cap)" in caplog.text
    a, b = _fit(seed=1, patience=5)[0], _fit(seed=1, patience=5)[0]
    assert all(torch.equal(p, q) for p, q in zip(a.state_dict().values(), b.state_dict().values()))
