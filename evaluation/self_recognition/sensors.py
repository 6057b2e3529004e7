"""What the self-recognition robot perceives through: its models seen through noisy sensors (core/sensing.py), and
the two hypotheses it compares: one body behind the joints and the visual stream (the benchmark's Perception), or a
visual stream of its own (`visual_only`: the same visual models, their belief free of the joints)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from bodyschema.aif.perception import Perception
from bodyschema.evaluation.core.sensing import through_noise


def sensors_of(config, models: Sequence) -> tuple[list, dict[str, float]]:
    """The models as seen through the simulated sensors (core/sensing.through_noise), and precision overrides;
    modalities in config.perception.precisions keep the configured value."""
    sigma = {**dict(config.visual_noise), "joints": config.proprio_noise}
    return through_noise(models, sigma, dict(config.perception.precisions))


def visual_only(perception: Perception) -> Perception:
    """The same visual models and precisions without the joints model: the "not me" hypothesis, whose belief
    explains the visual stream alone."""
    keep = [m for m in perception.models if m.modality != "joints"]
    precisions = {k: v for k, v in perception.precisions.items() if k != "joints"}
    config = replace(perception.config, precisions=tuple((k, v) for k, v in perception.config.precisions
                                                         if k != "joints"))
    return Perception(keep, config, precisions, (perception.low, perception.high))
