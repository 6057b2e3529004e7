"""A local Ray datagen listens on loopback only: no GCS, raylet, agent, worker or driver socket on another address.

Before the fix (Ray 2.60, `_node_ip_address="127.0.0.1"`): the driver, GCS, raylet (2 ports) and workers listened
on `::` (every interface) and the runtime-env agent on the machine's external address.
"""

import os
import sys

import pytest

from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.validate import validate_store
from tests.datagen.processes import descendants, is_loopback, listening

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads sockets from /proc")


def test_a_local_ray_datagen_listens_on_loopback_only(tmp_path, monkeypatch):
    ray = pytest.importorskip("ray")
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    seen, real_wait = set(), ray.wait

    def wait_and_look(*args, **kwargs):  # called by the driver while Ray runs the shards
        me = os.getpid()
        seen.update(listening(descendants(me) | {me}))
        return real_wait(*args, **kwargs)

    monkeypatch.setattr(ray, "wait", wait_and_look)
    out = tmp_path / "ray.zarr"
    generate(DatagenConfig(n=64, shard_size=8, images=False, workers=2, backend="ray", out=out), progress=False)
    assert validate_store(out) == []
    assert not ray.is_initialized()  # the local instance it started is shut down
    owners = {pid for pid, _, _ in seen}
    assert len(owners) >= 3, f"expected the driver, GCS and raylet among the listeners, saw {sorted(seen)}"
    exposed = sorted(s for s in seen if not is_loopback(s[2]))
    assert not exposed, f"sockets listening beyond loopback during a Ray datagen: {exposed}"
    assert os.environ.get("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER") is None  # the switch is restored afterwards
