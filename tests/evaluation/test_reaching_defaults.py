"""A record's [reaching] table is the reaching benchmark's: datagen holds it as given (a table, nothing more), and its
reader (`control.robot_defaults`) checks its keys and values with the house line naming the key (issue 34 item 9)."""

import pytest

from bodyschema.control.robot_defaults import reaching_defaults
from bodyschema.datagen.body.record import dumps_toml, read_record, record_from_dict, shipped_dir

GOOD = {"name": "arm", "model": str(shipped_dir() / "planar2.xml"), "image_size": [32, 32],
        "camera": {"name": "eye"}, "workspaces": {"full": [[-2.5, 2.5], [-2.5, 2.5]],
                                                  "camera": [[-2.5, 2.5], [-2.5, 2.5]]}}


@pytest.mark.parametrize("reaching, words", [
    ({"duration_s": -1.0}, "record [reaching] duration_s must be a finite number > 0"),
    ({"control_hz": "fast"}, "record [reaching] control_hz must be a finite number > 0"),
    ({"models": "ee_xyz"}, "record [reaching] models must be a list of modalities"),
    ({"actuators": "muscles"}, "record [reaching] actuators must be 'position' or 'torque'"),
    ({"action": 3}, "record [reaching] action must be a table"),
    ({"speed": 1.0}, "keys among ['models', 'control_hz', 'duration_s', 'actuators', 'action']"),
])
def test_the_record_holds_reaching_as_given_and_its_reader_refuses_it(tmp_path, reaching, words):
    record = record_from_dict({**GOOD, "reaching": reaching}, tmp_path)
    assert record.reaching == reaching
    path = tmp_path / "arm.toml"
    path.write_text(dumps_toml({**GOOD, "reaching": reaching}))
    with pytest.raises(ValueError, match="must be") as info:
        reaching_defaults(str(path))
    assert words in str(info.value)


def test_a_reaching_value_that_is_not_a_table_is_still_refused_by_the_record(tmp_path):
    with pytest.raises(ValueError, match=r"`reaching` of .* must be a table"):
        record_from_dict({**GOOD, "reaching": 5}, tmp_path)


def test_the_shipped_records_read_their_reaching_defaults():
    panda = reaching_defaults("panda")
    assert panda.actuators == "torque" and panda.control_hz == 500.0 and panda.action.k_a == 15.0
    assert read_record(shipped_dir() / "planar2.toml").reaching["action"] == {"k_a": 0.25, "leak": 8.0}
