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
    if seen[-1] == min(seen):                              # still improving at the cap: the user is told to go on
        assert "the last one the best: more --epochs may lower the loss" in caplog.text
    else:
        last_better = len(seen) - 1 - min(range(len(seen)), key=seen.__getitem__)
        assert f"loss last better {last_better} epochs before the end" in caplog.text
    a, b = _fit(seed=1, patience=5)[0], _fit(seed=1, patience=5)[0]
    assert all(torch.equal(p, q) for p, q in zip(a.state_dict().values(), b.state_dict().values()))


def test_a_loss_that_turns_nan_stops_the_fit_with_the_last_finite_epochs_weights(caplog, tmp_path):
    """NaN weights never recover under Adam: the loop stops in the epoch whose loss is not finite (not `patience`
    epochs later), keeps the best finite epoch's weights and says so; the checkpoint holds no NaN."""
    train, val = _noisy_regression()
    gen = torch.Generator().manual_seed(0)
    net = _nn_fit.build(lambda: nn.Sequential(nn.Linear(2, 16), nn.ELU(), nn.Linear(16, 1)), gen)
    calls = {"n": 0}
    steps_per_epoch = -(-len(train[0]) // 8)

    def poisoned(module, x, y):                          # finite for 3 epochs of training steps, then NaN
        loss = _mse(module, x, y)
        if not module.training:                          # the held-out evaluation
            return loss
        calls["n"] += 1
        return loss * float("nan") if calls["n"] > 3 * steps_per_epoch else loss

    seen = []
    with caplog.at_level(logging.INFO, logger="bodyschema.models._nn_fit"):
        info = _nn_fit.train(net, poisoned, train, _nn_fit.TrainSettings(50, 8, 1e-2, 20), gen, val=val,
                             on_epoch=lambda epoch, m: seen.append(m["val_loss"]), checkpoint=tmp_path / "c.pt")
    assert info["diverged_epoch"] == 3 and info["epochs_run"] == 3 and len(seen) == 3
    assert all(torch.isfinite(p).all() for p in net.parameters())
    assert _nn_fit.evaluate(net, _mse, val, 8) == min(seen) == info["best_loss"]
    assert "the training loss became NaN or inf in epoch 4" in caplog.text
    saved = torch.load(tmp_path / "c.pt", weights_only=True)
    assert saved["epoch"] == 2 and all(torch.isfinite(v).all() for v in saved["weights"].values())
