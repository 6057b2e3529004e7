"""Issue 35 item 8: a bar written to a log file (stderr not a terminal) redraws at most every
`log.FILE_BAR_INTERVAL_S` s, also the network fit's bar, whose per-epoch postfix forced a redraw each epoch (~1.3 s
for the pixel decoder). Run in a subprocess: tqdm reads its defaults (TQDM_MININTERVAL) when first imported, after
the CLI's `log.configure`. The clock is fake: each epoch takes 1.3 s of it."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from bodyschema import cli, log

SCRIPT = r'''
import sys
from bodyschema import log
log.configure(log.NORMAL)                          # stderr is a file here: bars redraw at most every 30 s
import torch
import tqdm.std
from torch import nn
from bodyschema.models import _nn_fit

now = [0.0]
tqdm.std.time = lambda: now[0]                     # the bar's clock (tqdm reads it through tqdm.std.time)
gen = torch.Generator().manual_seed(0)
x = torch.rand(16, 2, generator=gen)
net = _nn_fit.build(lambda: nn.Linear(2, 1), gen)
epochs = 60


def tick(epoch, metrics):
    now[0] += 1.3                                   # one epoch: 1.3 s


_nn_fit.train(net, lambda m, a, b: (m(a) - b).pow(2).mean(), (x, x.sum(1, keepdim=True)),
              _nn_fit.TrainSettings(epochs, 16, 1e-3, epochs), gen, on_epoch=tick, progress=True, desc="fitbar")
print(now[0])
'''


def test_a_bar_in_a_log_file_redraws_at_most_every_interval_on_a_fake_clock(tmp_path: Path):
    err = tmp_path / "stderr.log"
    env = {k: v for k, v in os.environ.items() if not k.startswith("TQDM_")}
    with err.open("w") as stderr:
        out = subprocess.run([sys.executable, "-c", SCRIPT], stdout=subprocess.PIPE, stderr=stderr, text=True,
                             env=env, check=True, timeout=300).stdout
    elapsed = float(out.split()[-1])                                             # 78 s of the fake clock
    draws = [d for d in err.read_text().replace("\n", "\r").split("\r") if d.startswith("fitbar") and "%|" in d]
    allowed = elapsed / log.FILE_BAR_INTERVAL_S + 2                              # + the first and the last draw
    assert 2 <= len(draws) <= allowed, f"{len(draws)} draws in {elapsed:.0f} s (at most {allowed:.1f}): {draws}"


@pytest.mark.parametrize("argv, on", [(["datagen"], True), (["datagen", "--no-progress"], False),
                                      (["datagen", "--progress"], True)])
def test_datagen_takes_progress_flags_as_every_command(argv, on, monkeypatch):
    """`datagen --no-progress` was refused (no such flag) while the other commands took it."""
    monkeypatch.setattr(log, "_verbosity", log.NORMAL)
    config = log.progress_of(cli.parse_command(argv), cli.progress_flag(argv))
    assert config.progress is on
    assert "progress" not in config.identity(), "how, not what: a store made with bars resumes without"
