"""`kill -9` of a datagen driver stops its loky workers within seconds (they used to run on for ~6 min)."""

import os
import signal
import subprocess
import sys
import time

import pytest

from bodyschema.base.processes import WATCH_S
from tests.datagen.processes import descendants, running

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads processes from /proc")
GRACE_S = 10  # the workers check their parent every WATCH_S; allow for a loaded 2-core CI machine


def shards_done(out) -> int:
    chunks = out / "shard_done" / "c"
    return len(list(chunks.iterdir())) if chunks.exists() else 0


def test_killing_the_driver_stops_its_workers(tmp_path):
    out = tmp_path / "k.zarr"
    job = dict(robot="planar2", n=4000, shard_size=16, workers=2, seed=5)  # 250 rendered shards: still running
    code = ("from bodyschema.datagen.config import DatagenConfig; from bodyschema.datagen.generate import generate; "
            f"generate(DatagenConfig(**{job!r}, out={str(out)!r}), progress=False)")
    driver = subprocess.Popen([sys.executable, "-c", code])
    deadline = time.monotonic() + 120
    while shards_done(out) < 2:  # both workers are up and writing
        assert driver.poll() is None, "the job ended before it could be killed"
        assert time.monotonic() < deadline, "no shard written in 120 s"
        time.sleep(0.05)
    workers = descendants(driver.pid)
    assert len(workers) >= 2, workers  # the 2 loky workers (+ resource trackers)
    os.kill(driver.pid, signal.SIGKILL)
    driver.wait()
    killed = time.monotonic()
    while any(running(pid) for pid in workers) and time.monotonic() - killed < GRACE_S:
        time.sleep(WATCH_S / 5)
    alive = sorted(pid for pid in workers if running(pid))
    for pid in alive:  # never leave them behind, even when the test fails
        os.kill(pid, signal.SIGKILL)
    assert not alive, f"processes of the killed datagen still running {GRACE_S} s later: {alive}"
