"""The one model-kind registry (models/kinds.py): one spelling everywhere, old spellings load, lazy imports."""

import json
import subprocess
import sys

import pytest
import torch

from bodyschema.models import kinds, load_model
from tests.models.test_multimodal import BODY, TINY, joint_angles, one_thread, toy_modalities

SHIPPED = [name for name, kind in kinds.KINDS.items() if kind.module.startswith("bodyschema.models.")]


@pytest.mark.parametrize("name", SHIPPED)
def test_each_kind_has_one_spelling_in_its_classes_and_its_config(name):
    kind = kinds.KINDS[name]
    assert "_" not in name, "kind names are hyphenated, as CLI words are"
    assert kinds.saved_class(name).kind == name, f"{kind.saved}.kind is not the registry's spelling {name!r}"
    if kind.config_class is not None:
        assert kind.config_class.kind == name and kinds.of_config(kind.config_class()) is kind


def test_old_spellings_map_to_the_new_and_unknown_names_list_the_available_ones():
    assert kinds.canonical("sklearn_gpr") == "sklearn-gpr" and kinds.canonical("mm_member") == "multimodal"
    assert set(kinds.ALIASES.values()) <= set(kinds.KINDS) and not set(kinds.ALIASES) & set(kinds.KINDS)
    with pytest.raises(ValueError, match=r"Model kind 'xgb' is not available\. Choose one of \[.*'gpr'.*'mdn'"):
        kinds.get("xgb")
    with pytest.raises(ValueError, match="Model kind 'analytic' is not trainable"):
        kinds.model_class("analytic")


def _fitted(kind: str):
    q = joint_angles(64, seed=0)
    if kind == "sklearn-gpr":
        from bodyschema.models.sklearn_gpr import SklearnGPRModel

        return SklearnGPRModel(BODY, "ee_xyz", (3,), max_iter=2).fit(q, toy_modalities(q)["ee_xyz"], progress=False)
    from bodyschema.models.multimodal import MultimodalMember

    with one_thread():
        return MultimodalMember(BODY, "ee_xyz", (3,), **{**TINY, "epochs": 2}).fit(q, toy_modalities(q)["ee_xyz"],
                                                                                    progress=False)


@pytest.mark.parametrize("old, new", sorted(kinds.ALIASES.items()))
def test_a_model_saved_under_an_old_spelling_still_loads(old, new, tmp_path):
    model = _fitted(new)
    model.save(tmp_path / "m")
    meta = json.loads((tmp_path / "m" / "meta.json").read_text())
    assert meta["kind"] == new, "saved under the registry's spelling"
    (tmp_path / "m" / "meta.json").write_text(json.dumps({**meta, "kind": old}))   # as written before issue 13
    loaded = load_model(tmp_path / "m")
    z = joint_angles(5, seed=1).double()
    assert type(loaded) is type(model) and loaded.kind == new
    torch.testing.assert_close(loaded.predict(z), model.predict(z), rtol=0, atol=0)


def test_a_class_cannot_claim_another_modules_kind_or_an_old_spelling():
    from bodyschema.models.contract import BaseSensoryModel, register_kind

    with pytest.raises(ValueError, match="registers kind 'gpr', which the table in models/kinds.py gives to "
                                         "bodyschema.models.gpr.GPRModel"):
        register_kind(type("Impostor", (BaseSensoryModel,), {"kind": "gpr"}))
    with pytest.raises(ValueError, match="'mm_member' is an old spelling: use 'multimodal'"):
        register_kind(type("Old", (BaseSensoryModel,), {"kind": "mm_member"}))


def test_the_registry_imports_no_model_module_until_a_kind_is_chosen():
    code = ("import sys; from bodyschema.models import kinds; import bodyschema.training.config; "
            "heavy = lambda: sorted(m for m in ('gpytorch', 'sklearn', 'bodyschema.models.gpr', "
            "'bodyschema.models.mdn', 'bodyschema.models.pixel') if m in sys.modules); "
            "print(heavy()); kinds.model_class('mdn'); print(heavy())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    before, after = out.stdout.strip().splitlines()
    assert before == "[]", f"imported before any kind was chosen: {before}"
    assert after == "['bodyschema.models.mdn']", f"choosing mdn imported {after}"
