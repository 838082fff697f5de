"""``common``: the spatial maths agree with scipy.spatial.transform, the atomic writers leave no
torn file or temporary behind, the value parser handles ranges and refuses bad text."""

import os

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from common import spatial
from common.files import WallClock, atomic_path, atomic_write_json, atomic_write_text, jsonable
from common.parse import parse_values


def _wxyz(r: Rotation) -> np.ndarray:
    return np.roll(r.as_quat(), 1, axis=-1)  # scipy is (x, y, z, w)


def test_spatial_agrees_with_scipy():
    rng = np.random.default_rng(0)
    rpy = rng.uniform([-1.2, -1.2, -3.0], [1.2, 1.2, 3.0], size=(50, 3))
    ref = Rotation.from_euler("ZYX", rpy[:, ::-1])  # R = Rz(yaw) Ry(pitch) Rx(roll)
    q = spatial.quat_from_rpy(rpy[:, 0], rpy[:, 1], rpy[:, 2])
    assert np.allclose(np.abs(np.sum(q * _wxyz(ref), axis=1)), 1.0, atol=1e-12)  # same rotation (±q)
    assert np.allclose(spatial.quat_roll_pitch(q), rpy[:, :2], atol=1e-9)
    assert np.allclose(spatial.quat_yaw(q), rpy[:, 2], atol=1e-9)
    for k in range(5):
        R = spatial.quat_to_mat(q[k])
        assert np.allclose(R, ref[k].as_matrix(), atol=1e-12)
        assert np.allclose(spatial.roll_pitch(R), rpy[k, :2], atol=1e-9)
    a, b = Rotation.random(20, random_state=1), Rotation.random(20, random_state=2)
    ab = spatial.quat_mul(_wxyz(a), _wxyz(b))
    assert np.allclose(np.abs(np.sum(ab * _wxyz(a * b), axis=1)), 1.0, atol=1e-12)
    v = rng.normal(size=(20, 3))
    assert np.allclose(spatial.quat_rotate(_wxyz(a), v), a.apply(v), atol=1e-12)
    assert np.allclose(spatial.cross(v[0], v[1]), np.cross(v[0], v[1]))
    assert spatial.quat_from_rpy(0.3, -0.2).shape == (4,)


def test_atomic_writers_leave_no_temporary_on_failure(tmp_path):
    p = tmp_path / "sub" / "a.json"
    atomic_write_json(p, {"x": np.float64(1.5), "y": float("nan"), "z": np.arange(2)})
    assert p.read_text() == '{\n "x": 1.5,\n "y": null,\n "z": [\n  0,\n  1\n ]\n}\n'
    with pytest.raises(RuntimeError):
        with atomic_path(p) as tmp:
            open(tmp, "w").write("torn")
            raise RuntimeError("killed mid-write")
    assert p.read_text().startswith('{\n "x": 1.5')  # the old file, whole
    assert sorted(os.listdir(p.parent)) == ["a.json"]  # no temporary left behind
    (tmp_path / "plain_file").write_text("")
    with pytest.raises(OSError):  # a parent that is a file: the error reaches the caller, nothing is written
        atomic_write_text(tmp_path / "plain_file" / "x", "")
    assert jsonable({"_private": 1, "a": 2}, private=False) == {"a": 2}


def test_wall_clock_accumulates_over_invocations(tmp_path):
    c = WallClock(tmp_path)
    first = c.save()
    assert first >= 0
    c2 = WallClock(tmp_path)
    assert c2.total() >= first and c2.before == pytest.approx(first)


@pytest.mark.parametrize("spec,expect", [("0:0.04:5", [0.0, 0.01, 0.02, 0.03, 0.04]), ("0.1,0.2,0.1", [0.1, 0.2]),
                                         (0.5, [0.5]), ("-0", [0.0])])
def test_parse_values(spec, expect):
    assert parse_values(spec, "--x") == expect


@pytest.mark.parametrize("spec,words", [("0:1", "malformed range"), ("a,b", "malformed value"), ("0:1:0", "count"),
                                        ("1:1:3", "start equals stop"), ("nan", "finite"), ("", "no values")])
def test_parse_values_refuses(spec, words):
    with pytest.raises(ValueError, match=words) as e:
        parse_values(spec, "--x")
    assert "--x" in str(e.value)
