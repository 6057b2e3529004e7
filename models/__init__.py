"""Sensory generative models x = g(z) under one contract (see `contract.py`)."""

from bodyschema.models.contract import BaseSensoryModel, SensoryModel, load_model, register_kind
from bodyschema.models.scaling import BodySpec

__all__ = ["BaseSensoryModel", "BodySpec", "SensoryModel", "load_model", "register_kind"]
