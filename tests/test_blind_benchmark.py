"""The blind benchmark of ``sgatwalk diagnose``: what reaches the tool holds nothing of
the truth, and the scorer counts every reported term."""

import os
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from benchmarks.blind.referee import META_KEYS, opaque_id, record, trial_id  # noqa: E402
from benchmarks.blind.report import metrics  # noqa: E402
from benchmarks.blind.scorer import DETECTABLE_RMS, score  # noqa: E402


def _eff(family, joints=(), links=(), value=0.0, ci=(None, None), cost=1.0):
    return {"family": family, "joints": list(joints), "links": list(links), "value": value, "ci95": list(ci),
            "heldout_cost_without": cost}


def _report(*effects, peak: float = 5.0):
    """A diagnosis report; ``peak``: the largest channel RMS over floor before fitting (localisation)."""
    return {"effects": list(effects), "noise_floor": 1e-3, "heldout_rms_before": 5e-3, "heldout_rms_after": 1e-3,
            "gap_closed": 0.8, "runtime_s": 1.0,
            "localisation": {"channels": {"HeadYaw": {"rms_over_floor": 1.0}, "LKneePitch": {"rms_over_floor": peak}}}}


def test_the_blind_folder_holds_only_a_robots_own_logs(tmp_path):
    hidden = [{"family": "latency", "targets": [None], "values": [0.02]}]
    tid = trial_id("single", 0, "latency")
    folder = tmp_path / "trials" / opaque_id(tid, 1000) / "logs"
    record("sim", hidden, str(folder), n_logs=1, seconds=3.0, seed=5, fixed_base=True)
    assert "latency" not in str(folder) and opaque_id(tid, 1000) != opaque_id(tid, 2000)
    files = sorted(os.listdir(folder))
    assert files and all(f.endswith(".parquet") for f in files)
    for f in files:
        t = pq.read_table(folder / f)
        assert not [c for c in t.column_names if c.startswith("gt.")]
        from envs.recording import Recording

        meta = Recording.from_parquet(folder / f).meta
        assert set(meta) <= set(META_KEYS) and meta["robot"] == "nao" and meta["fixed_base"] is True
        raw = (folder / f).read_bytes()
        assert b"latency" not in raw and b"0.02" not in raw  # no trace of the hidden value anywhere


def test_spurious_terms_count_against_precision_whatever_the_truth():
    truth = [{"family": "latency", "targets": [None], "values": [0.02]}]  # global: no joint
    rep = _report(_eff("latency", value=0.0201, ci=(0.0195, 0.0205), cost=50.0),
                  _eff("sensor_bias", joints=["LKneePitch"], value=0.003, ci=(0.002, 0.004)))
    s = score(truth, rep)
    assert s["pred_top1"] == "latency" and s["loc_tp"] == 1 and s["loc_true"] == 1
    assert s["loc_pred"] == 2 and s["pred_matched"] == 1 and s["spurious"] == ["sensor_bias[LKneePitch]"]
    # coverage over every reported term: the true one covers 20 ms, the spurious one misses the sim's 0
    assert s["ci_cover"] == [True, False]
    assert s["param_err"][0]["family"] == "latency" and abs(s["param_err"][0]["abs_ms"] - 0.1) < 1e-9


def test_a_term_on_clean_logs_is_spurious_and_its_interval_is_judged_against_the_sim():
    rep = _report(_eff("link_mass", links=["LTibia"], value=1.3, ci=(0.9, 1.6)))
    s = score([], rep)
    assert s["true_families"] == ["none"] and s["pred_top1"] == "link_mass"
    assert s["loc_pred"] == 1 and s["pred_matched"] == 0 and s["spurious"] == ["link_mass[LTibia]"]
    assert s["ci_cover"] == [True]  # the interval holds the nominal x1.0


def test_a_term_on_the_wrong_joint_is_not_a_hit():
    truth = [{"family": "backlash", "targets": ["RKneePitch"], "values": [0.02]}]
    s = score(truth, _report(_eff("backlash", joints=["LKneePitch"], value=0.02, ci=(0.018, 0.022))))
    assert s["loc_tp"] == 0 and s["pred_matched"] == 0 and s["param_err"] == []
    assert s["spurious"] == ["backlash[LKneePitch]"] and s["ci_cover"] == [False]


def test_the_referees_excitation_is_its_own_and_stays_inside_the_limits():
    from benchmarks.blind.excitation import referee_commands
    from robots import nao_h25
    from sysid.excitation import protocol

    robot = nao_h25()
    cmd = referee_commands(robot, 6.0, seed=3)
    assert cmd.shape == (600, len(robot.actuated_joint_names))
    lo, hi = robot.lower[robot.actuated_index], robot.upper[robot.actuated_index]
    assert (cmd >= lo + 0.05 - 1e-12).all() and (cmd <= hi - 0.05 + 1e-12).all()
    legs = [robot.actuated_joint_names.index(j) for j in robot.groups["legs"] if j in robot.actuated_joint_names]
    assert np.ptp(cmd[:, legs], axis=0).min() > 0.1  # every leg joint moves
    jumps = np.abs(np.diff(cmd, axis=0)).max(axis=0)
    assert np.median(jumps) > 0.02  # sharp steps, which a smooth protocol lacks
    prot = protocol(robot, 6.0, seed=3, fixed_base=True)
    c = [abs(np.corrcoef(cmd[:, j], prot[:, j])[0, 1]) for j in legs]
    assert np.median(c) < 0.5  # not the protocol in disguise
    assert not np.allclose(cmd, referee_commands(robot, 6.0, seed=4))


@pytest.mark.slow  # about a minute on a loaded 2-core machine
def test_a_latency_is_found_in_logs_of_the_referees_excitation(tmp_path):
    """The diagnosis on logs it was not designed for: a 20 ms latency in the sim-as-real world."""
    from benchmarks.blind.referee import run_diagnose

    hidden = [{"family": "latency", "targets": [None], "values": [0.02]}]
    record("sim", [], str(tmp_path / "none"), n_logs=3, seconds=4.0, seed=7, source="referee")
    run_diagnose(["diagnose", "--real", str(tmp_path / "none"), "--calibrate", "--out", str(tmp_path / "cal")])
    record("sim", hidden, str(tmp_path / "logs"), n_logs=3, seconds=4.0, seed=8, source="referee")
    rep = run_diagnose(["diagnose", "--real", str(tmp_path / "logs"), "--out", str(tmp_path / "rep"), "--no-plots",
                        "--calibration", str(tmp_path / "cal" / "calibration.json")])
    s = score(hidden, rep)
    assert s["pred_top1"] == "latency" and s["param_err"][0]["abs_ms"] < 2.0, s


def test_uncertain_terms_are_not_findings_but_their_intervals_count():
    truth = [{"family": "coulomb_friction", "targets": ["LElbowYaw"], "values": [0.13]}]
    rep = _report(_eff("coulomb_friction", joints=["LElbowYaw"], value=0.14, ci=(0.12, 0.16), cost=100.0))
    rep["uncertain"] = [_eff("pd_gain", joints=["LElbowYaw"], value=0.97, ci=(0.9, 1.05), cost=0.5),
                        _eff("coulomb_friction", joints=["RKneePitch"], value=0.02, ci=(0.01, 0.03), cost=0.3)]
    s = score(truth, rep)
    assert s["spurious"] == [] and s["loc_pred"] == 1 and s["pred_matched"] == 1  # only findings count here
    assert s["uncertain"] == 2 and s["uncertain_true"] == 0
    # the finding covers 0.13; the uncertain kp holds the sim's x1; the uncertain friction misses the sim's 0
    assert s["ci_cover"] == [True, True, False]


def test_benchmark_refuses_unknown_extra_classes(capsys):
    from benchmarks.sysid_blind import main

    with pytest.raises(SystemExit) as exc:
        main(["--extra-classes", "warp_drive", "--out", "unused"])
    assert exc.value.code == 2 and "warp_drive" in capsys.readouterr().err


@pytest.mark.parametrize("world", ["real", "sim"])
def test_the_referees_parallel_spring_holds_short_of_the_target(world):
    """The referee's own parallel spring (PyBullet: -k q added to the clipped PD torque each physics
    step; MuJoCo: the hinge's stiffness): a head yaw held by its PD at 0.5 rad settles at
    kp / (kp + k) of where it settles without the spring, 0.5 kp / (kp + k) (fixed base, no gravity
    on that axis)."""
    from benchmarks.blind.worlds import make_world
    from robots import nao_h25

    robot = nao_h25()
    j = robot.joint_names.index("HeadYaw")
    kp, k = float(robot.kp[j]), 1.0
    held = []
    for hidden in ([], [{"family": "parallel_spring", "targets": ["HeadYaw"], "values": [k]}]):
        env = make_world(world, hidden, fixed_base=True, noise=1e-9)
        env.reset(seed=0)
        a = env.q0[robot.actuated_index].copy()
        a[robot.actuated_joint_names.index("HeadYaw")] = 0.5
        for _ in range(100):
            env.step(a)
        held.append(float(env._state().q[j]))
        env.close()
    assert held[0] == pytest.approx(0.5, abs=2e-3)
    assert held[1] == pytest.approx(held[0] * kp / (kp + k), abs=2e-3)


def test_top1_on_detectable_effects_leaves_out_effects_below_the_noise():
    """An effect whose signal stays below the noise (no channel at 1.22x its floor before fitting)
    counts in the all-trials top-1 but not in the detectable one; a detectable miss counts in both."""
    lat = [{"family": "latency", "targets": [None], "values": [0.02]}]
    mass = [{"family": "link_mass", "targets": ["LTibia"], "values": [1.05]}]
    fric = [{"family": "coulomb_friction", "targets": ["LKneePitch"], "values": [0.1]}]
    rows = [{"kind": "single", "truth_class": "latency",
             "score": score(lat, _report(_eff("latency", value=0.02, ci=(0.019, 0.021), cost=9.0)))},
            {"kind": "single", "truth_class": "link_mass", "score": score(mass, _report(peak=1.1))},
            {"kind": "single", "truth_class": "coulomb_friction", "score": score(fric, _report(peak=2.6))},
            {"kind": "single", "truth_class": "none", "score": score([], _report(peak=1.0))}]
    assert [r["score"]["detectable"] for r in rows] == [True, False, True, False]
    assert 1.1 < DETECTABLE_RMS < 1.3
    m = metrics(rows)
    assert (m["top1"]["k"], m["top1"]["n"]) == (1, 3)
    assert (m["top1_detectable"]["k"], m["top1_detectable"]["n"]) == (1, 2)


def test_summary_names_the_trials_encoder_noise():
    """summary.md's header states the noise the trial logs were recorded with, not the default."""
    from benchmarks.blind.report import summarize

    lat = [{"family": "latency", "targets": [None], "values": [0.02]}]
    row = {"kind": "single", "truth_class": "latency", "seed": 1000, "n_logs": 4, "seconds": 6.0,
           "score": score(lat, _report(_eff("latency", value=0.02, ci=(0.019, 0.021), cost=9.0)))}
    assert "encoder noise 3 mrad" in summarize([row], "real", ["latency"], 3.0)
    assert "encoder noise 1 mrad" in summarize([row], "real", ["latency"])


# ------------------------------------------------------------------------------------------ the strangers' setting
def _sreport(effects=(), equivalent=(), peak=5.0):
    rep = _report(*effects, peak=peak)
    rep["equivalent"] = list(equivalent)
    return rep


def test_every_stranger_kind_maps_to_library_families():
    from benchmarks.blind.strangers import KIND_FAMILIES, PARTIAL
    from benchmarks.strangers.effects import KINDS
    from sysid.candidates import FAMILIES

    assert set(KIND_FAMILIES) == set(KINDS)
    assert all(f in FAMILIES for fams in KIND_FAMILIES.values() for f in fams)
    assert all(set(p) <= set(KIND_FAMILIES[k]) for k, p in PARTIAL.items())


def test_stranger_truth_in_the_library_units():
    from benchmarks.blind.strangers import truth_values
    from robots import nao_h25

    r = nao_h25()
    eff = dict(zip(r.joint_names, r.effort))
    e = {"family": "torque_speed", "targets": ["LKneePitch"], "values": [6.0], "params": [{}]}
    assert truth_values(e, r) == [("back_emf", "LKneePitch", pytest.approx(eff["LKneePitch"] / 6.0))]
    e = {"family": "friction_stribeck", "targets": ["LKneePitch"], "values": [0.1], "params": [{"stiction_ratio": 1.5}]}
    assert truth_values(e, r) == [("stribeck_friction", "LKneePitch", pytest.approx(0.05)),
                                  ("coulomb_friction", "LKneePitch", 0.1)]
    e["params"] = [{"stiction_ratio": 1.5, "viscous": 0.02}]
    assert truth_values(e, r)[-1] == ("viscous_damping", "LKneePitch", 0.02)
    e = {"family": "com_offset", "targets": ["LTibia"], "values": [0.02], "params": [{"direction": [0.0, 0.6, 0.8]}]}
    assert [(f, t, round(v, 4)) for f, t, v in truth_values(e, r)] == [
        ("link_com", "LTibia:x", 0.0), ("link_com", "LTibia:y", 0.012), ("link_com", "LTibia:z", 0.016)]


def test_a_stranger_is_named_right_by_its_family_or_its_class_and_a_wrong_finding_is_counted():
    from benchmarks.blind.strangers import score
    from robots import nao_h25

    r = nao_h25()
    truth = [{"family": "backlash_motor", "targets": ["LKneePitch"], "values": [0.01], "params": [{}]}]
    right = score(truth, _sreport([_eff("backlash_motor", joints=["LKneePitch"], value=0.0102, ci=(0.009, 0.011))]), r)
    assert right["named_right"] and not right["by_class"] and not right["wrong_found"] and right["ci_cover"] == [True]
    cls = {"words": "static angle offset", "joints": ["LKneePitch"], "links": [], "family": "sensor_bias",
           "candidates": [{"family": "sensor_bias"}, {"family": "backlash_motor"}]}
    by_class = score(truth, _sreport(equivalent=[cls]), r)
    assert by_class["named_right"] and by_class["by_class"] and not by_class["wrong_found"]
    wrong = score(truth, _sreport([_eff("sensor_bias", joints=["LKneePitch"], value=-0.005, ci=(-0.006, -0.004))]), r)
    assert not wrong["named_right"] and wrong["wrong_found"] == ["sensor_bias[LKneePitch]"]
    assert wrong["wrong_at_truth"] == ["sensor_bias[LKneePitch]"]
    # a finding elsewhere beside the right one is a confident wrong Found too
    extra = score(truth, _sreport([_eff("backlash_motor", joints=["LKneePitch"], value=0.01),
                                   _eff("coulomb_friction", joints=["RHipRoll"], value=0.05)]), r)
    assert extra["named_right"] and extra["wrong_found"] == ["coulomb_friction[RHipRoll]"] and not extra["wrong_at_truth"]
    # the strangers' gear contact is a spring of 10 x kp in series with the play: a series compliance found
    # there is part of the form (no wrong Found, its interval scored against 1 / kc), and does not name the play
    from benchmarks.strangers.effects import contact_parameters

    c = 1.0 / contact_parameters(r, "LKneePitch")[0]
    spring = _eff("joint_compliance", joints=["LKneePitch"], value=c * 1.1, ci=(c * 0.5, c * 1.5))
    both = score(truth, _sreport([spring], equivalent=[cls]), r)
    assert both["named_right"] and not both["wrong_found"] and both["ci_cover"] == [True]
    alone = score(truth, _sreport([spring]), r)
    assert not alone["named_right"] and not alone["wrong_found"]


def test_a_stribeck_stranger_named_as_coulomb_with_its_excess_not_excluded_is_named_by_its_class():
    from benchmarks.blind.strangers import score
    from robots import nao_h25

    r = nao_h25()
    truth = [{"family": "friction_stribeck", "targets": ["LHipPitch"], "values": [0.1],
              "params": [{"stiction_ratio": 1.5}]}]
    plain = _eff("coulomb_friction", joints=["LHipPitch"], value=0.1, ci=(0.09, 0.11))
    s = score(truth, _sreport([plain]), r)
    assert not s["named_right"] and s["partly_right"] and not s["wrong_found"]
    caveat = {**plain, "not_excluded": [{"family": "stribeck_friction", "terms": {"stribeck_friction[LHipPitch]": 0.03},
                                         "segment": "velocity_sweep", "experiment": "..."}]}
    s = score(truth, _sreport([caveat]), r)
    assert s["named_right"] and s["by_class"] and not s["wrong_found"]
    # the strangers' Stribeck friction has a viscous term: a viscous damping found beside is no wrong Found,
    # and it does not name the Stribeck form alone
    visc = _eff("viscous_damping", joints=["LHipPitch"], value=0.03, ci=(0.02, 0.04))
    s = score([{**truth[0], "params": [{"stiction_ratio": 1.5, "viscous": 0.03}]}], _sreport([visc]), r)
    assert not s["named_right"] and not s["wrong_found"] and s["ci_cover"] == [True]
    s = score(truth, _sreport([_eff("viscous_damping", joints=["RHipRoll"], value=0.03)]), r)
    assert s["wrong_found"] == ["viscous_damping[RHipRoll]"]  # elsewhere it is wrong


def test_own_benchmark_counts_a_class_that_holds_the_truth_as_named_right():
    truth = [{"family": "pd_gain", "targets": ["LElbowRoll"], "values": [0.7]}]
    cls = {"words": "actuator stiffness", "joints": ["LElbowRoll"], "links": [], "family": "joint_compliance",
           "candidates": [{"family": "joint_compliance"}, {"family": "pd_gain"}]}
    rep = _report()
    rep["equivalent"] = [cls]
    s = score(truth, rep)
    assert s["named_right"] and s["by_class"] and not s["wrong_found"] and s["pred_top1"] == "none"
