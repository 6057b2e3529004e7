"""What a model says about itself in MLflow's UI: the descriptions of a logged model, a registered version and its
registered model (kind, body, modality, data digest), so a reader of the registry need not decode the name.

The logged model's description (`model_summary`, the `mlflow.note.content` tag MLflow's UI shows) is written when
`bodyschema train` logs it, from the model itself: what it maps, in which units. At registration the version and
the registered model get that text plus what the version's tags record: the dataset and MJCF digests, the weights'
digest and the held-out score. The registered model's description names its newest registration.
"""

from __future__ import annotations

import re

from bodyschema.base import modalities
from bodyschema.training.digest import DIGEST_TAG

NOTE = "mlflow.note.content"      # the tag MLflow's UI shows (and edits) as a logged model's description


def model_summary(model) -> str:
    """One paragraph, the kind, its body (robot and joints), what it maps and the unit of its score; plain text, as
    MLflow's table of versions shows a description unrendered."""
    body = f"robot {model.body.robot} (joints {', '.join(model.body.joint_names)})"
    z = f"joint angles z (B, {model.latent_dim}) rad"
    if model.encodes:
        images = f"{model.modality} (B, {', '.join(map(str, model.input_shape))}) uint8"
        return f"{model.kind} of {body}: {images} → {z}. Scored by val_rmse in joint degrees."
    unit = modalities.unit(model.modality, "output units")
    x = f"{model.modality} (B, {', '.join(map(str, model.output_shape))}) {unit}"
    chosen = getattr(model, "fitted_choices", "")
    return f"{model.kind} model of {body}: {z} → {x}. Scored by val_rmse in {unit}." + (f" {chosen}" if chosen else "")


def version_description(summary: str, tags: dict[str, str]) -> str:
    """A registered version: the logged model's summary and the data, weights and score its tags record."""
    return "\n\n".join([summary, f"Trained by `bodyschema train` on dataset sha256 `{tags.get('dataset_sha256', '?')}` "
                                 f"(robot MJCF sha256 `{tags.get('mjcf_sha256') or '?'}`); weights sha256 "
                                 f"`{tags.get(DIGEST_TAG, '?')}`; held-out val_rmse {tags.get('val_rmse', '?')}."])


def registered_description(name: str, version: str, summary: str, tags: dict[str, str]) -> str:
    """A registered model: what every version of it is, how to load one, and the newest registration's data."""
    return "\n\n".join([f"bodyschema SensoryModel, one version per `bodyschema train` run: {summary}",
                        f"Load with `bodyschema.load_registered(\"models:/{name}@champion\")`; `@champion` is the "
                        "version with the lowest val_rmse (or one promoted by hand).",
                        f"Newest registration: version {version}, dataset sha256 `{tags.get('dataset_sha256', '?')}`."])


def fallback_summary(tags: dict[str, str]) -> str:
    """For a logged model without a description (logged before descriptions existed): what its tags say."""
    return (f"{tags.get('kind', '?')} model of robot {tags.get('robot', '?')} (joints "
            f"{tags.get('joint_names', '?').replace(',', ', ')}) → {tags.get('modality', '?')}.")


def describe_registration(client, name: str, version: str, tags: dict[str, str], model_id: str) -> None:
    """Write the descriptions of version `version` of `name` and of `name` itself (caller holds the registry lock,
    so the registered model's text names the registration that finished last)."""
    summary = client.get_logged_model(model_id).tags.get(NOTE) or fallback_summary(tags)
    client.update_model_version(name, version, description=version_description(summary, tags))
    client.update_registered_model(name, description=registered_description(name, version, summary, tags))


def score_unit(model) -> str:
    """The unit of a model's held-out scores: joint degrees for an encoder, its modality's unit otherwise."""
    return "deg" if model.encodes else modalities.unit(model.modality, "output units")


def metric_name(text: str) -> str:
    """`text` with every character MLflow refuses in a metric name replaced by '_'."""
    return re.sub(r"[^A-Za-z0-9_./ -]", "_", str(text))


def with_unit(key: str, unit: str) -> str:
    """" <unit>" for a score key ("val_rmse", "train_mean_error", "image/val_rmse"); "" for `val_loss` and
    `train_loss`, the fit's own objective, which is in the model's internal units (unit-box or [0, 1] squared errors),
    and for anything else (fit_seconds)."""
    name = key.rsplit("/", 1)[-1]
    scored = name.startswith(("val_", "train_")) and not name.endswith("_loss")
    return f" {unit}" if unit and scored else ""


def card_markdown(model, name: str | None, tags: dict[str, str], metrics: dict[str, float], params: dict) -> str:
    """`model_card.md`, a training run's artifact: what the model is (`model_summary`), the data it was trained and
    scored on (path, digests, split), its held-out scores and its hyper-parameters."""
    lines = [f"# {name or model.kind + ' model (not registered)'}", "", model_summary(model), "",
             "## Data", "", f"- dataset: `{tags.get('dataset', '?')}`",
             f"- dataset sha256: `{tags.get('dataset_sha256', '?')}`",
             f"- validation data sha256 (store digest + held-out rows): `{tags.get('val_sha256', '?')}`",
             f"- robot MJCF sha256: `{tags.get('mjcf_sha256') or '?'}`",
             f"- rows: {params.get('n_train', '?')} train, {params.get('n_val', '?')} validation, split by "
             f"{params.get('split_by', '?')}", "", "## Held-out scores", ""]
    unit = score_unit(model)
    lines += [f"- {k}: {v:.6g}{with_unit(k, unit)}" for k, v in sorted(metrics.items())]
    lines += ["", "## Hyper-parameters", ""] + [f"- {k}: {v}" for k, v in sorted(params.items())
                                                 if k.startswith("hyper.")]
    lines += ["", f"Weights sha256: `{tags.get(DIGEST_TAG, '?')}` (checked before every load from the registry)."]
    return "\n".join(lines) + "\n"
