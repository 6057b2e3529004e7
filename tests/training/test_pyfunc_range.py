"""Issue 35 item 8: the pyfunc (`mlflow models serve`, `mlflow models predict`) refuses a joint angle outside the range
the model was fitted on with the house error naming the joint and its range; `params={"extrapolate": True}` allows
it. `train` prints its held-out scores with their unit."""

import re

import mlflow
import numpy as np
import pytest

from bodyschema.training.train import TrainResult, train
from tests.training.tiny_model import tiny_config

NAME = "bodyschema-planar2-ee_xyz-tiny"


def test_pyfunc_refuses_9_rad_naming_the_joint_and_its_range_and_extrapolates_when_asked(workdir, kin_store,
                                                                                          tiny_kind):
    result = train(tiny_config(kin_store, epochs=3))
    assert " m" in str(result).split("held-out: ")[1], "the scores carry the model's output unit (m)"
    pyfunc = mlflow.pyfunc.load_model(f"models:/{NAME}@champion")
    body = pyfunc.get_raw_model().body
    inside = np.array([[0.3, -0.4], [body.q_high[0], body.q_low[1]]])            # (2, 2) rad, the edge included
    assert pyfunc.predict(inside).shape == (2, 3)
    far = np.array([[0.3, -0.4], [0.1, 9.0]])                                    # elbow at 9 rad
    limits = re.escape(f"[{body.q_low[1]:.4g}, {body.q_high[1]:.4g}] rad")    # the fitted range, within ±2.6
    with pytest.raises(ValueError, match=rf"z\[1, 1\] \(joint elbow\) must be within its range {limits}"
                                         r".*Got '9 rad'.*extrapolate"):
        pyfunc.predict(far)
    with pytest.raises(ValueError, match="joint elbow"):
        pyfunc.predict(far, params={"output": "jacobian"})
    with pytest.raises(ValueError, match="joint shoulder"):
        pyfunc.predict(np.array([[np.nan, 0.0]]))
    assert np.isfinite(pyfunc.predict(far, params={"extrapolate": True})).all()
    assert pyfunc.predict(far, params={"extrapolate": True, "output": "jacobian"}).shape == (2, 3, 2)


def test_train_prints_each_score_with_its_unit():
    single = TrainResult("r", (), {"val_rmse": 2.56e-4, "val_mean_error": 3e-4, "fit_seconds": 1.0}, units={"": "m"})
    assert "held-out: val_mean_error=0.0003 m, val_rmse=0.000256 m" in str(single)
    multi = TrainResult("r", (), {"ee_xyz/val_rmse": 0.001, "ee_pixel/val_rmse": 1.5},
                        units={"ee_xyz/": "m", "ee_pixel/": "px"})
    assert "ee_pixel/val_rmse=1.5 px, ee_xyz/val_rmse=0.001 m" in str(multi)
    encoder = TrainResult("r", (), {"val_loss": 0.2019, "val_rmse": 52.41}, units={"": "deg"})
    assert "held-out: val_loss=0.2019, val_rmse=52.41 deg" in str(encoder), "val_loss is the fit's unit-box MSE"
    stopped = TrainResult("r", (), {"val_loss": 0.1187, "best_loss": 0.09667, "val_rmse": 45.36}, units={"": "deg"})
    assert "held-out: val_loss=0.09667, val_rmse=45.36 deg" in str(stopped), "the kept epoch's, not the last epoch's"
    from bodyschema.training.model_card import with_unit
    assert [with_unit(k, "deg") for k in ("train_rmse", "train_loss", "fit_seconds", "image/val_rmse")] == \
        [" deg", "", "", " deg"]
