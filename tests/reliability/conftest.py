"""The training fixtures (a registry in a scratch folder, a kinematic store, a toy kind) for this folder's tests."""

from tests.training.conftest import empty_db, kin_store, tiny_kind, workdir  # noqa: F401 — fixtures, by name

