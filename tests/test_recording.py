"""Recordings: Parquet round trip, documented schema, clear errors for malformed input."""

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from envs import HoldPose, SimWorld, Recording, RecordingError, rollout
from robots import nao_h25


@pytest.fixture(scope="module")
def rec():
    env = SimWorld()
    return rollout(env, HoldPose(env.robot), seed=0, seconds=0.5, meta={"source": "test"})


def test_rollout_recording_content(rec):
    robot = nao_h25()
    assert len(rec) == 50
    assert np.allclose(np.diff(rec.t), 0.01) and rec.t[0] == 0
    assert rec.group("q").shape == (50, 24) and rec.group("cmd").shape == (50, 23)
    assert np.array_equal(rec.group("cmd"), np.repeat(robot.pose("crouch", actuated=True)[None], 50, 0))
    assert np.array_equal(rec.group("app"), rec.group("cmd"))
    assert rec.meta["world"] == "sim" and rec.meta["control_dt"] == 0.01 and rec.meta["fell"] is False
    assert rec.meta["source"] == "test"
    assert rec.group("gt.base")[0, 2] == pytest.approx(0.313, abs=0.003)


def test_parquet_round_trip(rec, tmp_path):
    path = rec.to_parquet(tmp_path / "r.parquet")
    back = Recording.from_parquet(path)
    assert back.meta == json.loads(json.dumps(rec.meta))
    assert set(back.columns) == set(rec.columns)
    for k in rec.columns:
        assert np.array_equal(back.columns[k], rec.columns[k], equal_nan=True)
    # column names follow the documented scheme
    names = pq.read_schema(path).names
    assert "q.LKneePitch" in names and "cmd.LKneePitch" in names and "gyro.x" in names and "t" == names[0]
    assert "cmd.RHipYawPitch" not in names


def test_minimal_user_written_log(tmp_path):
    """A log written without this package: only t, cmd.*, q.* and the two required metadata keys."""
    robot = nao_h25()
    n = 20
    cols = {"t": np.arange(n) * 0.012}
    cols.update({f"cmd.{j}": np.zeros(n) for j in robot.actuated_joint_names})
    cols.update({f"q.{j}": np.zeros(n) for j in robot.joint_names})
    table = pa.table(cols).replace_schema_metadata({b"sgatwalk": json.dumps({"robot": "nao", "control_dt": 0.012})})
    pq.write_table(table, tmp_path / "mine.parquet")
    r = Recording.from_parquet(tmp_path / "mine.parquet")
    assert len(r) == n and not r.has("dq") and r.group("app").shape == (n, 23)


def _write(tmp_path, rec, drop=(), meta=None, change=None):
    cols = {k: v.copy() for k, v in rec.columns.items() if k not in drop}
    if change:
        change(cols)
    r = Recording.__new__(Recording)
    r.columns, r.meta = cols, dict(meta if meta is not None else rec.meta)
    path = tmp_path / "bad.parquet"
    pq.write_table(r.to_table(), path)
    return path


@pytest.mark.parametrize("drop,match", [(("q.LKneePitch",), "q.LKneePitch"), (("t",), "'t'"),
                                        (("gyro.y",), "incomplete.*gyro.*gyro.y"),
                                        (("cmd.LHipRoll", "q.RKneePitch"), "cmd.LHipRoll, q.RKneePitch"),
                                        (("gyro.y", "acc.z"), "gyro.*gyro.y.*acc.*acc.z")])
def test_missing_columns_are_named(rec, tmp_path, drop, match):
    with pytest.raises(RecordingError, match=match):
        Recording.from_parquet(_write(tmp_path, rec, drop=drop))


def test_malformed_values_are_named(rec, tmp_path):
    def nan_cmd(c):
        c["cmd.LAnkleRoll"][7] = np.nan
    with pytest.raises(RecordingError, match=r"cmd.LAnkleRoll.*row 7"):
        Recording.from_parquet(_write(tmp_path, rec, change=nan_cmd))

    def backwards(c):
        c["t"][10] = 0.0
    with pytest.raises(RecordingError, match="not strictly increasing"):
        Recording.from_parquet(_write(tmp_path, rec, change=backwards))


def test_bad_metadata_and_files(rec, tmp_path):
    with pytest.raises(RecordingError, match="control_dt"):
        Recording.from_parquet(_write(tmp_path, rec, meta={"robot": "nao"}))
    with pytest.raises(RecordingError, match="robot 'atlas'"):
        Recording.from_parquet(_write(tmp_path, rec, meta={"robot": "atlas", "control_dt": 0.01}))
    junk = tmp_path / "junk.parquet"
    junk.write_bytes(b"this is not parquet at all")
    with pytest.raises(RecordingError, match="not a readable Parquet"):
        Recording.from_parquet(junk)
    with pytest.raises(FileNotFoundError):
        Recording.from_parquet(tmp_path / "nope.parquet")
    pq.write_table(pa.table({"t": [0.0]}), tmp_path / "nometa.parquet")
    with pytest.raises(RecordingError, match="no 'sgatwalk' metadata"):
        Recording.from_parquet(tmp_path / "nometa.parquet")
    empty = {k: v[:0] for k, v in rec.columns.items()}
    with pytest.raises(RecordingError, match="empty"):
        Recording(empty, rec.meta).validate()
    str_table = pa.table({"t": ["a"]}).replace_schema_metadata({b"sgatwalk": b'{"robot":"nao","control_dt":0.01}'})
    pq.write_table(str_table, tmp_path / "str.parquet")
    with pytest.raises(RecordingError, match="column 't' has type string"):
        Recording.from_parquet(tmp_path / "str.parquet")


def test_rollout_rejects_bad_duration():
    with pytest.raises(ValueError, match="seconds"):
        rollout(SimWorld(), lambda o: None, seconds=0)
