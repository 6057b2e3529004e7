"""Issue 34: a modality is a row. A new vector sensor (joint torque) and a second camera are each one
`register(Modality(...))`, with no file of the package edited: the store's schema, the LeRobot export's keys, and
the branches of the evaluation (images clipped to [0, 1], image goals, pose inference) follow the row's kind."""

from __future__ import annotations

import numpy as np
import pytest

from bodyschema.base import modalities
from bodyschema.base.modalities import Modality
from bodyschema.datagen.exchange.export_lerobot import keys, lerobot_features
from bodyschema.datagen.store.schema import create_store, features

TORQUE = Modality("torque", "N·m", ("Dq",), ("joint",), sensor=True)
WRIST = Modality("wrist_image", "intensity", ("image",), ("row", "col", "channel"), dtype="uint8", kind="image",
                 camera="wrist", error_unit="MSE")


@pytest.fixture
def rows():
    for row in (TORQUE, WRIST):
        modalities.register(row)
    yield
    for row in (TORQUE, WRIST):
        modalities.unregister(row.name)


def test_a_vector_sensor_row_is_in_the_schema_of_robots_that_have_it(rows):
    with_it = features(3, None, sensors=("touch", "torque"), babble=False)
    assert list(with_it)[-2:] == ["touch", "torque"]          # after the arrays every store has, as touch
    assert with_it["torque"] == {"dtype": "float32", "shape": [3], "unit": "N·m", "names": ["joint"]}
    assert "torque" not in features(3, None, sensors=("touch",), babble=False)
    assert keys()["torque"] == "observation.torque"
    assert not modalities.is_image("torque") and modalities.get("torque").reported_unit == "N·m"


def test_a_second_camera_row_is_an_image_everywhere(rows, tmp_path):
    from bodyschema.evaluation.levels.targets import add_noise
    from bodyschema.evaluation.reaching import goal_pose
    from bodyschema.evaluation.reaching.goals import goal_names

    f = features(2, (8, 12), sensors=("wrist_image",), babble=False)    # held for robots that have the camera
    assert list(f)[-2:] == ["image", "wrist_image"] and f["wrist_image"]["dtype"] == "uint8"
    assert "wrist_image" not in features(2, (8, 12), sensors=(), babble=False)
    assert modalities.images_in(f) == ["image", "wrist_image"]
    root = create_store(tmp_path / "s.zarr", f, n=4, chunk_len=4, n_shards=1,
                        attrs={"joint_names": ["a", "b"], "camera_name": "front"})
    exported = lerobot_features(root)
    assert exported["observation.images.front"]["shape"] == [8, 12, 1]
    assert exported["observation.images.wrist"]["shape"] == [8, 12, 1]
    noisy = add_noise({"wrist_image": np.full((2, 8, 12), 0.99)}, {"wrist_image": 1.0}, np.random.default_rng(0))
    assert noisy["wrist_image"].max() <= 1.0 and noisy["wrist_image"].min() >= 0.0   # clipped as an image
    assert goal_names()[:2] == ("image", "wrist_image") and goal_pose.wanted("auto", "wrist_image")


def test_a_row_is_checked_and_a_taken_name_refused():
    with pytest.raises(ValueError, match="modality name must be new"):
        modalities.register(Modality("touch", "N", (1,), ("contact",)))
    with pytest.raises(ValueError, match="camera must be"):
        Modality("eye", "intensity", ("image",), ("row", "col"), kind="image")
    with pytest.raises(ValueError, match="kind must be one of"):
        Modality("smell", "ppm", (1,), ("odour",), kind="scalar")
    with pytest.raises(ValueError, match="one added by register"):
        modalities.unregister("image")
