"""Bad input to the diagnosis and the excitation tools: clear errors, exit status 2."""

import json
import os

import numpy as np
import pyarrow.parquet as pq
import pytest

from envs.recording import Recording, RecordingError
from experiments.cli import main
from robots import nao_h25
from sysid.data import load_logs
from sysid.excitation import SEGMENTS, protocol


def _rec(n=300, robot="nao", control_dt=0.01) -> Recording:
    r = nao_h25()
    q = np.tile(r.pose("crouch"), (n, 1))
    return Recording.from_arrays({"robot": "nao", "control_dt": control_dt, "fixed_base": True},
                                 np.arange(n) * control_dt, cmd=q[:, r.actuated_index], q=q)


def _write_raw(rec: Recording, path, meta=None):
    """Write without validation (to make malformed files)."""
    if meta is not None:
        rec.meta = meta
    pq.write_table(rec.to_table(), str(path))
    return str(path)


def _diagnose_error(capsys, *args) -> str:
    rc = main(["diagnose", "--real", *args, "--out", "/tmp/sgatwalk_sysid_never_written"])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("sgatwalk diagnose: error:")
    return err


def test_missing_column(tmp_path, capsys):
    rec = _rec()
    del rec.columns["q.LKneePitch"]
    p = _write_raw(rec, tmp_path / "a.parquet")
    assert "q.LKneePitch" in _diagnose_error(capsys, p)


def test_mismatched_robot(tmp_path, capsys):
    rec = _rec()
    p = _write_raw(rec, tmp_path / "a.parquet", {"robot": "pepper", "control_dt": 0.01})
    assert "pepper" in _diagnose_error(capsys, p)


def test_too_short(tmp_path, capsys):
    p = _rec(n=50).to_parquet(tmp_path / "a.parquet")
    assert "too short" in _diagnose_error(capsys, p)


def test_nan_holed(tmp_path, capsys):
    rec = _rec()
    rec.columns["q.RAnkleRoll"][120] = np.nan
    p = _write_raw(rec, tmp_path / "a.parquet")
    err = _diagnose_error(capsys, p)
    assert "q.RAnkleRoll" in err and "row 120" in err


def test_inconsistent_logs_and_missing_paths(tmp_path, capsys):
    a = _rec().to_parquet(tmp_path / "a.parquet")
    b = _rec(n=150, control_dt=0.02).to_parquet(tmp_path / "b.parquet")
    assert "control_dt" in _diagnose_error(capsys, a, b)
    assert "argument --real: no such file or directory" in _diagnose_error(capsys, str(tmp_path / "nope.parquet"))
    os.makedirs(tmp_path / "empty")
    assert "no .parquet" in _diagnose_error(capsys, str(tmp_path / "empty"))
    with pytest.raises(RecordingError):
        load_logs([a, b])


def test_bad_calibration(tmp_path, capsys):
    a = _rec().to_parquet(tmp_path / "a.parquet")
    (tmp_path / "cal.json").write_text(json.dumps({"hello": 1}))
    assert "calibration" in _diagnose_error(capsys, a, "--calibration", str(tmp_path / "cal.json"))


def test_bad_family(tmp_path, capsys):
    a = _rec().to_parquet(tmp_path / "a.parquet")
    assert "warp_drive" in _diagnose_error(capsys, a, "--families", "latency,warp_drive")


def test_protocol_shapes_limits_and_seeds():
    r = nao_h25()
    a = protocol(r, 6.0, seed=0)
    b = protocol(r, 6.0, seed=1)
    assert a.shape == (600, 23) and not np.allclose(a, b)
    lo, hi = r.lower[r.actuated_index], r.upper[r.actuated_index]
    assert np.all(a >= lo) and np.all(a <= hi)
    np.testing.assert_allclose(a[0], r.pose("crouch", actuated=True))
    assert np.ptp(a, axis=0).min() > 0.05  # every joint moves
    f = protocol(r, 6.0, seed=0, fixed_base=False)
    assert f.shape == (600, 23)
    for bad in ({"seconds": 2.0}, {"segments": ("nope",)}, {"scale": 0.0}):
        kw = {"seconds": 6.0, **bad}
        with pytest.raises(ValueError):
            protocol(r, **kw)
    assert "chirp" in SEGMENTS and "holds" in SEGMENTS


def test_excite_cli_records_logs(tmp_path, capsys):
    rc = main(["excite", "--world", "sim", "--fixed-base", "--out", str(tmp_path), "--logs", "2", "--seconds", "3",
               "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["recordings"]) == 2
    logs = load_logs(str(tmp_path))
    assert logs[0].fixed_base and len(logs[0]) == 300 and not np.allclose(logs[0].cmd, logs[1].cmd)
    assert main(["excite", "--world", "real", "--effect", "nonsense", "--out", str(tmp_path)]) == 2
    assert main(["excite", "--world", "real", "--effect", "warp=1", "--out", str(tmp_path)]) == 2


@pytest.mark.slow
def test_excite_cli_design(capfd):
    """``--design d-optimal --design-only`` prints the shares and the families' identifiability and
    records nothing (slow: a probe replay per family and segment).
    The design's probe replays make MuJoCo warn (solver line searches, unstable probes): the
    warnings are counted (``sysid.replay.MUJOCO_WARNINGS``), so stdout, file descriptor included,
    holds only the JSON."""
    from sysid.replay import MUJOCO_WARNINGS

    before = sum(MUJOCO_WARNINGS.values())
    rc = main(["excite", "--world", "sim", "--fixed-base", "--segments", "holds,saturation", "--design", "d-optimal",
               "--design-only", "--json"])
    assert rc == 0
    d = json.loads(capfd.readouterr().out)["design"]
    assert sum(MUJOCO_WARNINGS.values()) > before
    assert set(d["shares"]) == {"holds", "saturation"} and abs(sum(d["shares"].values()) - 1) < 1e-9
    assert {f["family"] for f in d["families"]} >= {"torque_limit", "pd_gain", "joint_compliance"}


def test_excite_cli_segments(tmp_path, capfd):
    """``--segments +saturation`` records the extra segment; bad combinations exit 2."""
    out = tmp_path / "sat"
    assert main(["excite", "--world", "sim", "--fixed-base", "--segments", "+saturation", "--logs", "1",
                 "--seconds", "4", "--out", str(out), "--json"]) == 0
    capfd.readouterr()
    (lg,) = load_logs(str(out))
    assert len(lg) == 400
    for bad in (["--segments", "holds,nope", "--fixed-base"], ["--segments", "+saturation"],
                ["--design", "d-optimal"], ["--design-only", "--fixed-base"]):
        assert main(["excite", "--world", "sim", "--out", str(tmp_path / "x"), *bad]) == 2, bad
        err = capfd.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err, err
    assert not (tmp_path / "x").exists()


def test_diagnose_families_plus_adds_to_the_defaults():
    from experiments.cli.diagnose import _families
    from sysid.candidates import FIXED_BASE_FAMILIES
    from sysid.synthetic import synthetic_logs

    logs = synthetic_logs({}, n_logs=1, seconds=3.0)
    fams = _families("+torque_constant", logs)
    assert "torque_constant" not in FIXED_BASE_FAMILIES
    assert set(fams) == set(FIXED_BASE_FAMILIES) | {"torque_constant"}
    assert fams.index("torque_constant") == fams.index("pd_gain") + 1  # library order
    assert _families("latency,pd_gain", logs) == ["latency", "pd_gain"]
