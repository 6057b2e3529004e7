"""The training loop's device plan (`models/_nn_device.py`): the identity on the CPU; on cuda a batch of at least
GPU_MIN_BATCH, the learning rate × √(batch ratio) after a one-epoch linear warm-up; bf16 autocast when asked. The
cuda rule is exercised here on the CPU by handing `_nn_fit.train` the plan cuda would get (CI has no GPU)."""

import math

import torch
from torch import nn

from bodyschema.models import _nn_fit
from bodyschema.models._nn_device import GPU_MIN_BATCH, DevicePlan, plan_for, warmup_factor
from tests.threads import one_thread


def test_the_cpu_plan_is_the_identity_and_cuda_scales_batch_and_learning_rate():
    assert plan_for(torch.device("cpu"), 64) == DevicePlan(64, 1.0, 0, None)
    cuda = plan_for(torch.device("cuda"), 64)
    assert cuda == DevicePlan(GPU_MIN_BATCH, math.sqrt(GPU_MIN_BATCH / 64), 1, None)
    assert plan_for(torch.device("cuda"), 2048) == DevicePlan(2048, 1.0, 0, None)     # a larger batch is kept
    assert plan_for(torch.device("cuda:1"), 64, mixed_precision=True).autocast == torch.bfloat16
    assert "batch 64 → 512" in cuda.describe(64, 2e-3) and "warm-up" in cuda.describe(64, 2e-3)


def test_warm_up_rises_linearly_over_the_first_epoch_then_holds():
    plan = DevicePlan(512, 4.0, 1, None)
    factors = [warmup_factor(plan, step, steps_per_epoch=4) for step in range(7)]
    assert factors == [1.0, 2.0, 3.0, 4.0, 4.0, 4.0, 4.0]
    assert warmup_factor(DevicePlan(64, 1.0, 0, None), 0, 4) == 1.0


def _regression(n=64):
    gen = torch.Generator().manual_seed(0)
    x = torch.rand(n, 2, generator=gen) * 2 - 1
    return x, x.sum(1, keepdim=True) ** 2


def _fit(plan, mixed_precision=False, record=None):
    gen = torch.Generator().manual_seed(1)
    net = _nn_fit.build(lambda: nn.Sequential(nn.Linear(2, 32), nn.ELU(), nn.Linear(32, 1)), gen)

    def loss(m, x, y):
        out = m(x)
        if record is not None:
            record.append((len(x), out.dtype))
        return (out.float() - y).pow(2).mean()

    with one_thread():
        info = _nn_fit.train(net, loss, _regression(), _nn_fit.TrainSettings(6, 8, 1e-2, 100), gen, plan=plan,
                             mixed_precision=mixed_precision)
    return net, info


def test_a_cuda_plan_trains_on_its_batches_with_the_warmed_up_learning_rate(monkeypatch):
    factors, record = [], []

    def spy(plan, step, steps_per_epoch):
        factors.append((step, warmup_factor(plan, step, steps_per_epoch)))
        return factors[-1][1]

    monkeypatch.setattr(_nn_fit, "warmup_factor", spy)
    plan = DevicePlan(32, 2.0, 1, None)                  # what cuda gives batch 8 if GPU_MIN_BATCH were 32
    _, info = _fit(plan, record=record)
    assert {size for size, _ in record} == {32}          # 64 rows: two batches of 32 per epoch
    assert [step for step, _ in factors] == list(range(12))
    assert [f for _, f in factors[:3]] == [1.0, 2.0, 2.0]
    assert info["epochs_run"] == 6


def test_bf16_autocast_runs_the_forward_in_bf16_and_still_learns():
    record = []
    net, info = _fit(plan_for(torch.device("cpu"), 8, mixed_precision=True), record=record)
    assert {dtype for _, dtype in record} == {torch.bfloat16}
    assert all(p.dtype == torch.float32 for p in net.parameters())           # the weights stay float32
    _, plain = _fit(plan_for(torch.device("cpu"), 8))
    assert info["best_loss"] < 1.5 * plain["best_loss"] + 1e-3, (info, plain)


def test_the_cpu_plan_gives_the_same_weights_as_no_plan():
    a, _ = _fit(None)
    b, _ = _fit(plan_for(torch.device("cpu"), 8))
    for (name, x), (_, y) in zip(a.state_dict().items(), b.state_dict().items()):
        assert torch.equal(x, y), name
