"""What the self-recognition robot perceives through: its models seen through noisy sensors (`NoisySensor`), the
perception update (`perception_config`: "auto" as in the levels), and the two hypotheses it compares:
one body behind the joints and the visual stream (the benchmark's Perception), or a visual stream of its own
(`visual_only`: the same visual models, their belief free of the joints)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from bodyschema.aif.perception import Perception


def perception_config(config):
    """config.perception with the update of this run: --update, else --perception.method; "auto" (both's default) is
    resolved by the Perception for its models (aif/perception_config.py: adam+lm with an image model, else flow)."""
    return replace(config.perception, method=config.update if config.update != "auto" else config.perception.method)


def sensors_of(config, models: Sequence) -> tuple[list, dict[str, float]]:
    """The models as seen through the simulated sensors, and precision overrides. An exact (analytic) model's only
    error is the sensor noise: Π = 1/σ². A learned model's precision covers its own error, the noise adds to it:
    Π = 1/(1/Π_model(μ) + σ²). Modalities in config.perception.precisions keep the configured value."""
    sigma = {**dict(config.visual_noise), "joints": config.proprio_noise}
    fixed, seen = {}, []
    for m in models:
        s = sigma.get(m.modality, 0.0)
        exact = getattr(m, "kind", None) == "analytic"
        if s > 0 and exact and m.modality not in dict(config.perception.precisions):
            fixed[m.modality] = 1.0 / s ** 2
        seen.append(NoisySensor(m, s) if s > 0 and not exact else m)
    return seen, fixed


class NoisySensor:
    """A SensoryModel observed through additive sensor noise σ: precision 1/(1/Π(μ) + σ²); the rest delegated."""

    def __init__(self, model, sigma: float):
        self.model, self.variance = model, float(sigma) ** 2
        self.body, self.latent_dim, self.modality = model.body, model.latent_dim, model.modality
        self.output_shape, self.kind = model.output_shape, getattr(model, "kind", type(model).__name__)
        if hasattr(model, "compute_dtype"):                         # a network keeps its fast float32 path
            self.compute_dtype = model.compute_dtype

    def predict(self, z):
        return self.model.predict(z)

    def jacobian(self, z):
        return self.model.jacobian(z)

    def vjp(self, z, v):
        return self.model.vjp(z, v)

    def precision(self, z):                                         # (B, *out) output units⁻²
        return 1.0 / (1.0 / self.model.precision(z) + self.variance)

    def save(self, path):
        self.model.save(path)


def visual_only(perception: Perception) -> Perception:
    """The same visual models and precisions without the joints model: the "not me" hypothesis, whose belief
    explains the visual stream alone."""
    keep = [m for m in perception.models if m.modality != "joints"]
    precisions = {k: v for k, v in perception.precisions.items() if k != "joints"}
    config = replace(perception.config, precisions=tuple((k, v) for k, v in perception.config.precisions
                                                         if k != "joints"))
    return Perception(keep, config, precisions, (perception.low, perception.high))
