"""`python -m tests.training.run_train '<json>'`: one `train` of the tiny kind in a fresh process, for the tests
that need a second process or a kill. JSON keys: `config` (`tiny_config` keywords), `sleep_s` (per epoch),
`kill_after_version` (SIGKILL this process right after a model version is created, before anything else)."""

from __future__ import annotations

import json
import os
import signal
import sys


def main(spec: dict) -> None:
    from mlflow import MlflowClient

    from bodyschema.models import kinds
    from bodyschema.training.train import train
    from tests.training.tiny_model import TINY, TinyModel, tiny_config

    kinds.register(TINY)
    TinyModel.sleep_s = float(spec.get("sleep_s", 0.0))
    if spec.get("kill_after_version"):
        create = MlflowClient._create_model_version

        def create_then_die(self, *args, **kwargs):
            version = create(self, *args, **kwargs)
            os.kill(os.getpid(), signal.SIGKILL)       # as a kill -9 right after "Created version N"
            return version

        MlflowClient._create_model_version = create_then_die
    print(train(tiny_config(**spec["config"])), flush=True)


if __name__ == "__main__":
    main(json.loads(sys.argv[1]))
