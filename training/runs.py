"""The life cycle of a training run across processes: who owns a run directory, which MLflow run to continue, which
finished run to reuse, and which RUNNING runs are dead.

A run directory (`<run_root>/<kind>-<modality>-<config hash>`) is owned by one process at a time (`claim`, an
flock released by the kernel even on kill -9). Its `mlflow_run_id` file is only a hint to find the run: what
decides is the run as the tracking database knows it (status, `bodyschema.identity` tag, experiment).
- RUNNING or KILLED, found by the owner of the directory: the process that ran it is gone (it would hold the
  lock), so it is marked KILLED and continued — same MLflow run, from the checkpoint.
- FINISHED, same identity and experiment, every model registered: nothing to do; its versions are reused.
- FAILED: a new run starts (from the checkpoint).
Runs of other configs found RUNNING whose process (pid and start time recorded as tags, on this host) is dead
are marked KILLED by the next `train` in their experiment (`reap_dead_runs`).
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from mlflow.exceptions import MlflowException

from bodyschema.base.locks import exclusive
from bodyschema.base.processes import pid_alive, process_start
from bodyschema.training.digest import DIGEST_TAG

IDENTITY_TAG = "bodyschema.identity"         # full config hash (sha256 of TrainConfig.identity)
PID_TAG, HOST_TAG, START_TAG = "bodyschema.pid", "bodyschema.host", "bodyschema.pid_start"
MARKER = "mlflow_run_id"
_log = logging.getLogger(__name__)


@contextmanager
def claim(run_dir: Path) -> Iterator[None]:
    """Own `run_dir` for the `with` body; a second process with the same config is refused, naming the pid."""
    with exclusive(run_dir / ".lock", wait=False, what=f"run directory {run_dir}",
                   hint="Another `bodyschema train` with the same config is running there; wait for it to finish "
                        "(started again afterwards, this command reuses its result), or stop that process."):
        yield


def owner_tags(identity: str) -> dict[str, str]:
    """Tags that let a later process tell whether this run's process is still alive."""
    tags = {IDENTITY_TAG: identity, PID_TAG: str(os.getpid()), HOST_TAG: socket.gethostname()}
    start = process_start()
    if start is not None:
        tags[START_TAG] = start
    return tags


def marked_run(client, run_dir: Path):
    """The MLflow run named by the run directory's marker, or None (no marker, other store, deleted run)."""
    marker = run_dir / MARKER
    if not marker.is_file():
        return None
    try:
        run = client.get_run(marker.read_text().strip())
    except MlflowException:
        return None
    return run if run.info.lifecycle_stage == "active" else None


def resumable_run(client, run_dir: Path) -> str | None:
    """The run to continue (RUNNING after a hard kill, or KILLED), marked KILLED first; else None.
    Call while holding `claim(run_dir)`: then a RUNNING run's process is certainly gone."""
    run = marked_run(client, run_dir)
    if run is None or run.info.status not in ("RUNNING", "KILLED"):
        return None
    if run.info.status == "RUNNING":
        client.set_terminated(run.info.run_id, "KILLED")
        client.set_tag(run.info.run_id, "bodyschema.ended", "process found dead by the next owner of its run dir")
    _log.debug("continuing run %s (was %s) from %s", run.info.run_id, run.info.status, run_dir)
    return run.info.run_id


def finished_run(client, run_dir: Path, identity: str, experiment_id: str, modalities: tuple[str, ...],
                 register: bool):
    """The FINISHED run of this identity in this experiment and its registered versions (one per modality, each
    with its digest) when nothing is left to do; else None. → (Run, {modality: ModelVersion})"""
    run = marked_run(client, run_dir)
    if (run is None or run.info.status != "FINISHED" or run.info.experiment_id != experiment_id
            or run.data.tags.get(IDENTITY_TAG) != identity):
        return None
    versions = {}
    if register:
        for version in client.search_model_versions(f"run_id = '{run.info.run_id}'"):
            if DIGEST_TAG in version.tags and version.tags.get("modality") in modalities:
                versions[version.tags["modality"]] = version
        if set(versions) != set(modalities):
            return None                # registered nothing (register=False then) or a version was deleted
    return run, versions


def reap_dead_runs(client, experiment_id: str) -> list[str]:
    """Mark KILLED every RUNNING run of the experiment started on this host whose process is gone. → their ids"""
    host, reaped = socket.gethostname(), []
    for run in client.search_runs([experiment_id], "attributes.status = 'RUNNING'", max_results=1000):
        tags = run.data.tags
        if tags.get(HOST_TAG) != host or not tags.get(PID_TAG, "").isdigit():
            continue                   # another machine's run (or not ours): its pid means nothing here
        if pid_alive(int(tags[PID_TAG]), tags.get(START_TAG)):
            continue
        client.set_terminated(run.info.run_id, "KILLED")
        client.set_tag(run.info.run_id, "bodyschema.ended", f"process {tags[PID_TAG]} found dead")
        reaped.append(run.info.run_id)
        _log.debug("run %s marked KILLED: its process %s is gone", run.info.run_id, tags[PID_TAG])
    return reaped
