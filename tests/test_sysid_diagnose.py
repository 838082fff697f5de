"""The diagnosis end to end: report content for known cases, "no missing physics", inputs untouched."""

import hashlib
import json
import os

import mujoco
import numpy as np
import pytest

from envs.recording import Recording
from experiments.cli import main
from robots import nao_h25
from sysid.candidates import Term
from sysid.data import load_logs
from sysid.diagnose import diagnose
from sysid.report import format_report, write_report
from sysid.synthetic import synthetic_logs

REPORT_KEYS = {"verdict", "noise_floor", "heldout_rms_before", "heldout_rms_after", "effects"}
EFFECT_KEYS = {"family", "joints", "links", "value", "unit", "ci95"}


def write_logs(logs, folder) -> list[str]:
    r = nao_h25()
    paths = []
    for lg in logs:
        rec = Recording.from_arrays({"robot": "nao", "control_dt": lg.control_dt, "physics_dt": lg.physics_dt,
                                     "fixed_base": True, "source": "test"},
                                    lg.t, cmd=lg.cmd[:, r.actuated_index], q=lg.q)
        paths.append(rec.to_parquet(os.path.join(folder, f"{lg.name}.parquet")))
    return paths


def _hashes(paths):
    return {p: hashlib.sha256(open(p, "rb").read()).hexdigest() for p in paths}


def test_no_missing_physics_on_clean_data():
    logs = synthetic_logs({}, n_logs=3, seconds=4.0, seed=1)
    rep = diagnose(logs)
    assert rep["effects"] == []
    assert rep["verdict"].startswith("no missing physics")
    assert abs(rep["noise_floor"] - 1e-3) < 1.5e-4
    assert rep["heldout_rms_before"] < 1.2e-3


def test_report_for_known_latency_case(tmp_path):
    logs = synthetic_logs({Term("latency"): 0.02}, n_logs=3, seconds=4.0, seed=2)
    paths = write_logs(logs, tmp_path / "logs")
    before = _hashes(paths)
    out = tmp_path / "report"
    rc = main(["diagnose", "--real", str(tmp_path / "logs"), "--out", str(out), "--json"])
    assert rc == 0
    assert _hashes(paths) == before  # a diagnosis never modifies its inputs
    rep = json.loads((out / "report.json").read_text())
    assert REPORT_KEYS <= set(rep)
    assert len(rep["effects"]) == 1
    e = rep["effects"][0]
    assert EFFECT_KEYS <= set(e)
    assert e["family"] == "latency" and e["unit"] == "s" and len(e["joints"]) == 24 and e["links"] == []
    assert abs(e["value"] - 0.02) < 5e-4
    assert e["ci95"][0] <= e["value"] <= e["ci95"][1]
    assert rep["heldout_rms_before"] > 5 * rep["noise_floor"]
    assert rep["heldout_rms_after"] < 1.2 * rep["noise_floor"]
    text = (out / "report.txt").read_text()
    assert "actuation latency" in text and "VERDICT" in text and "CONSIDERED AND REJECTED" in text
    for png in ("overlay.png", "residual_by_joint.png", "residual_by_phase.png"):
        assert (out / png).stat().st_size > 1000
    m = mujoco.MjModel.from_xml_path(str(out / "identified_model.xml"))
    assert np.allclose(m.actuator_delay, e["value"])


@pytest.mark.slow
def test_two_effects_latency_and_knee_friction(tmp_path):
    truth = {Term("latency"): 0.025, Term("coulomb_friction", "LKneePitch"): 0.2}
    logs = synthetic_logs(truth, n_logs=3, seconds=6.0, seed=4)
    rep = diagnose(logs)
    found = {(e["family"], e["joints"][0] if len(e["joints"]) == 1 else None): e for e in rep["effects"]}
    # the knee's dry friction is Found, or, where these logs (no velocity sweep) cannot tell Coulomb from
    # Stribeck friction, named as its class with Coulomb among the candidates and the separating segment
    classes = {(c["family"], c["where"]): c for c in rep.get("equivalent", [])}
    knee = found.get(("coulomb_friction", "LKneePitch")) or classes.get(("coulomb_friction", "LKneePitch"))
    assert set(found) <= {("latency", None), ("coulomb_friction", "LKneePitch")} and ("latency", None) in found
    assert knee is not None and abs(knee["value"] - 0.2) < 0.02
    if ("coulomb_friction", "LKneePitch") not in found:
        assert knee["segment"] == "velocity_sweep"
        assert {c["family"] for c in knee["candidates"]} == {"coulomb_friction", "stribeck_friction"}
    assert abs(found[("latency", None)]["value"] - 0.025) < 1e-3
    assert rep["heldout_rms_after"] < 1.2 * rep["noise_floor"]
    paths = write_report(rep, logs, str(tmp_path), plots=True)
    assert os.path.exists(paths["json"])
    txt = format_report(rep)
    assert "Coulomb" in txt and "LKneePitch" in txt


def test_calibration_roundtrip(tmp_path):
    logs = synthetic_logs({}, n_logs=2, seconds=3.0, seed=5)
    write_logs(logs, tmp_path / "none")
    assert main(["diagnose", "--real", str(tmp_path / "none"), "--out", str(tmp_path / "cal"), "--calibrate",
                 "--json"]) == 0
    cal = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    assert cal["kind"] == "sgatwalk-sysid-calibration" and set(cal["gap_rms"]) >= set(nao_h25().joint_names)
    assert main(["diagnose", "--real", str(tmp_path / "none"), "--out", str(tmp_path / "rep"), "--calibration",
                 str(tmp_path / "cal" / "calibration.json"), "--no-plots", "--json"]) == 0
    rep = json.loads((tmp_path / "rep" / "report.json").read_text())
    assert rep["effects"] == [] and rep["noise"]["engine_gap_calibrated"]


def test_load_logs_reads_folder_and_files(tmp_path):
    logs = synthetic_logs({}, n_logs=2, seconds=3.0)
    paths = write_logs(logs, tmp_path)
    assert [lg.name for lg in load_logs(str(tmp_path))] == ["synthetic_000", "synthetic_001"]
    assert len(load_logs(paths)) == 2


def _stepping_logs(friction: float, seeds, seconds=6.0):
    from envs import CommandLog, NaoSimEnv, rollout
    from sysid.data import from_recording
    from sysid.excitation import protocol

    r = nao_h25()
    logs = []
    for s in seeds:
        rec = rollout(NaoSimEnv(fixed_base=False, friction=friction), CommandLog(protocol(r, seconds, seed=s,
                                                                                          fixed_base=False)),
                      seed=0, seconds=seconds)
        rng = np.random.default_rng(s)
        for c in rec.columns:
            if c.startswith("q."):
                rec.columns[c] = rec.columns[c] + rng.normal(0, 1e-3, len(rec))
        logs.append(from_recording(rec, f"step_{s}"))
    return logs


@pytest.mark.slow
def test_foot_friction_found_from_stepping_logs():
    """Floating base, windowed replay: a slippery floor (μ 0.3 vs 0.8) is named and fitted."""
    from sysid.diagnose import calibrate

    cal = calibrate(_stepping_logs(0.8, [50, 51, 52]))
    rep = diagnose(_stepping_logs(0.3, [20, 21, 22]), calibration=cal)
    fams = {e["family"]: e for e in rep["effects"]}
    assert "foot_friction" in fams
    assert abs(fams["foot_friction"]["value"] - 0.3) < 0.05
    assert rep["heldout_rms_after"] < rep["heldout_rms_before"]


@pytest.mark.parametrize("hidden", ["pd_gain", "torque_constant", "joint_compliance"])
def test_softer_servo_and_series_compliance_are_told_apart(hidden):
    """A kp x0.6, a torque-constant error x0.6 (kp and kd together) and a series spring of the same
    static stiffness (c = (1 - 0.6) / (0.6 kp)) at RKneePitch: each is named as itself, with its
    value, not as one of the others (the spring takes the servo damping off the output, a kp-only
    error keeps kd, a torque-constant error scales it: the chirp and steps show each)."""
    kp = dict(zip(nao_h25().joint_names, nao_h25().kp))["RKneePitch"]
    truth = (1 - 0.6) / (0.6 * kp) if hidden == "joint_compliance" else 0.6
    logs = synthetic_logs({Term(hidden, "RKneePitch"): truth}, n_logs=3, seconds=3.0, seed=4)
    rep = diagnose(logs, families=("pd_gain", "torque_constant", "joint_compliance", "sensor_bias"))
    (e,) = rep["effects"]
    assert e["family"] == hidden and e["joints"] == ["RKneePitch"]
    assert abs(e["value"] - truth) < 0.05 * abs(truth - e["nominal"])
    assert hidden.replace("_", " ") in format_report(rep) or e["words"] in format_report(rep)


def test_noise_free_logs_without_calibration_carry_a_caution():
    """Recordings with no sensor noise (a simulator's) and no engine-gap calibration: the floor is
    numerical noise, so the verdict warns that any engine gap reads as physics; noisy logs do not."""
    hidden = {Term("latency"): 0.02}
    clean = diagnose(synthetic_logs(hidden, n_logs=3, seconds=3.0, noise=0.0), families=("latency",))
    assert clean["warnings"] and "--calibration" in clean["warnings"][0]
    assert "CAUTION" in clean["verdict"]
    noisy = diagnose(synthetic_logs(hidden, n_logs=3, seconds=3.0, seed=1), families=("latency",))
    assert noisy["warnings"] == [] and "CAUTION" not in noisy["verdict"]
