"""GaitParams: the 16 names, θ0 in bounds, normalisation, JSON round trip, validation errors."""

import json
import math
import os

import numpy as np
import pytest

from walk_engine import N_PARAMS, NAMES, SPECS, GaitParams
from walk_engine.params import HIGH, LOW


def test_sixteen_named_parameters_with_units_and_bounds():
    assert N_PARAMS == 16 and len(set(NAMES)) == 16
    for s in SPECS:
        assert s.unit and s.doc
        assert s.low < s.high and s.low <= s.init <= s.high, s.name
    assert GaitParams().to_dict() == {s.name: s.init for s in SPECS}


def test_normalised_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(50):
        u = rng.uniform(0, 1, N_PARAMS)
        p = GaitParams.from_vector(u)
        np.testing.assert_allclose(p.to_vector(), u, atol=1e-12)
        np.testing.assert_allclose(GaitParams.from_array(p.to_array()).to_array(), p.to_array())
    np.testing.assert_allclose(GaitParams.from_vector(np.zeros(16)).to_array(), LOW)
    np.testing.assert_allclose(GaitParams.from_vector(np.ones(16)).to_array(), HIGH)
    u0 = GaitParams().to_vector()
    assert np.all((u0 >= 0) & (u0 <= 1))


def test_from_vector_clip_and_errors():
    u = np.full(16, 0.5)
    u[3] = 1.7
    with pytest.raises(ValueError, match="feet_spacing"):
        GaitParams.from_vector(u)
    assert GaitParams.from_vector(u, clip=True).feet_spacing == pytest.approx(SPECS[3].high)
    with pytest.raises(ValueError, match="16"):
        GaitParams.from_vector(np.zeros(15))
    u[5] = np.nan
    with pytest.raises(ValueError, match="torso_pitch"):
        GaitParams.from_vector(u, clip=True)


def test_json_round_trip_is_atomic(tmp_path):
    p = GaitParams.from_vector(np.linspace(0.1, 0.9, 16))
    path = p.save(tmp_path / "sub" / "theta.json")
    assert GaitParams.load(path) == p
    assert os.listdir(tmp_path / "sub") == ["theta.json"]  # no temporary file left behind
    doc = json.loads((tmp_path / "sub" / "theta.json").read_text())
    assert set(doc["params"]) == set(NAMES) and doc["units"]["step_period"] == "s"
    # a write that dies before the rename leaves the old file whole and no temporary behind
    import common.files

    def crash(fd):
        raise OSError(28, "No space left on device")

    orig = common.files.os.fsync
    common.files.os.fsync = crash
    try:
        with pytest.raises(OSError, match="No space"):
            GaitParams(step_length=0.05).save(path)
    finally:
        common.files.os.fsync = orig
    assert GaitParams.load(path) == p and os.listdir(tmp_path / "sub") == ["theta.json"]
    # a plain {name: value} object loads too
    plain = tmp_path / "plain.json"
    plain.write_text(json.dumps(p.to_dict()))
    assert GaitParams.load(plain) == p


def test_validation_names_every_problem():
    d = GaitParams().to_dict()
    del d["step_height"]
    d["bogus"] = 1.0
    d["com_height"] = float("nan")
    d["step_period"] = 2.0
    d["feet_spacing"] = "wide"
    with pytest.raises(ValueError) as exc:
        GaitParams.from_dict(d)
    msg = str(exc.value)
    for word in ("missing step_height", "bogus", "com_height", "step_period=2", "feet_spacing"):
        assert word in msg, (word, msg)


@pytest.mark.parametrize("kw, name", [({"step_length": 0.5}, "step_length"),
                                      ({"gyro_hip_roll_gain": math.inf}, "gyro_hip_roll_gain"),
                                      ({"double_support_ratio": -0.1}, "double_support_ratio")])
def test_constructor_and_replace_validate(kw, name):
    with pytest.raises(ValueError, match=name):
        GaitParams(**kw)
    with pytest.raises(ValueError, match=name):
        GaitParams().replace(**kw)
    with pytest.raises(ValueError, match="unknown"):
        GaitParams().replace(nonsense=1.0)


def test_wrong_count_and_bad_files(tmp_path):
    with pytest.raises(ValueError, match="expected 16"):
        GaitParams.from_array(np.zeros(17))
    with pytest.raises(FileNotFoundError):
        GaitParams.load(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        GaitParams.load(bad)
    bad.write_text("[1, 2, 3]")
    with pytest.raises(ValueError, match="JSON object"):
        GaitParams.load(bad)
    bad.write_text(json.dumps({"params": {"step_period": 0.3}}))
    with pytest.raises(ValueError, match="missing"):
        GaitParams.load(bad)
