"""The walk-level fit of the identified sim's actuation (``experiments.runtime.walkfit``)."""

import json
import os

import numpy as np
import pytest

from envs import Recording
from experiments.runtime.executors import SerialExecutor
from experiments.runtime.tasks import run_episode
from experiments.runtime.walkfit import (GRIDS, candidates, describe_terms, fit_walk_terms, moment_distance,
                                 statistic_names, tracking_statistics)
from robots import get_robot

THETA0 = [0.3, 0.2, 0.04, 0.1, 0.265, 0.05, 0.01, 0.01, 0.0, -6.0, 0.02, 0.2, 0.04, 0.03, 0.02, 0.02]
LEGS = [j for j in get_robot("nao").groups["legs"] if j in get_robot("nao").actuated_joint_names]


def _columns(n=300, offset=0.01, amp=0.02):
    t = np.arange(n) * 0.01
    cols = {"t": t, "angle.pitch": 0.1 * np.sin(t), "angle.roll": np.zeros(n)}
    for j in LEGS:
        cols[f"cmd.{j}"] = np.sin(3 * t)
        cols[f"q.{j}"] = np.sin(3 * t) + offset + amp * np.sign(np.sin(7 * t))
    return cols


def test_tracking_statistics_on_a_constructed_walk():
    s = tracking_statistics(_columns())
    J = len(LEGS)
    assert s.shape == (2 * J + 2,) == (len(statistic_names()),)
    err = 0.01 + 0.02 * np.sign(np.sin(7 * np.arange(300) * 0.01))  # measured - commanded, by hand
    assert s[:J] == pytest.approx(np.full(J, np.sqrt(np.mean(err ** 2))))
    assert s[J:2 * J] == pytest.approx(np.full(J, err.mean()))
    assert s[-2] == pytest.approx(np.std(0.1 * np.sin(np.arange(300) * 0.01)))
    # a walk that fell loses its last 0.5 s: a spike there no longer counts
    cols = _columns()
    for j in LEGS:
        cols[f"q.{j}"][-20:] += 1.0
    assert tracking_statistics(cols, fell=True)[:J] == pytest.approx(s[:J], rel=0.05)
    assert np.all(tracking_statistics(cols)[:J] > 2 * s[:J])


def test_tracking_statistics_errors():
    cols = _columns()
    del cols[f"cmd.{LEGS[0]}"]
    with pytest.raises(ValueError, match=f"cmd.{LEGS[0]}"):
        tracking_statistics(cols)
    with pytest.raises(ValueError, match="too short"):
        tracking_statistics(_columns(n=60), fell=True)


def test_moment_distance_prefers_the_candidate_that_matches():
    rng = np.random.default_rng(0)
    real = rng.normal([1.0, 2.0], 0.1, size=(4, 2))
    sim = np.stack([real + 0.5, real, real - 0.2])  # candidates: far, the same walks, near
    d = moment_distance(sim, real)
    assert d[1] == pytest.approx(0.0) and d[2] < d[0]
    with pytest.raises(ValueError, match="at least 2"):
        moment_distance(sim[:, :1], real[:1])
    with pytest.raises(ValueError, match="disagree"):
        moment_distance(sim[..., :1], real)


def test_candidates_cover_the_grid():
    g = GRIDS["actuation"]
    c = candidates("actuation")
    assert len(c) == len(g["torque_limit"]) * len(g["pd_gain"]) * len(g["latency"]) == 48
    assert sum("latency" not in m for m in c) == 12  # None: the diagnosis's latency stays
    assert all(len([k for k in m if k.startswith("pd_gain[")]) == 12 for m in c)
    ground = candidates("ground")
    assert len(ground) == 36 and ground[0] == {}  # the diagnosis's own latency and ground come first
    assert {m.get("terrain_roughness") for m in ground} == {None, 0.0015, 0.002, 0.0025, 0.003, 0.0035}
    assert describe_terms(c[1]) == "torque limit x1, leg kp x1, latency 10 ms"
    assert describe_terms({"terrain_roughness": 0.002}) == "ground RMS 2 mm" and describe_terms({}) == "the diagnosis's values"
    with pytest.raises(ValueError, match="unknown walk-fit grid"):
        candidates("friction")
    with pytest.raises(ValueError, match="unknown"):
        candidates({"backlash": (0.01,)})


def _report(path, model):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        json.dump({"model": model, "base_model": {}, "effects": []}, f)
    return str(path)


def test_the_fit_recovers_an_injected_ground(tmp_path):
    """"Real" walks from the identified sim on a 3 mm RMS ground the diagnosis put at 1 mm: the ground
    grid's fit, offered 1 (the diagnosis's), 3 and 5 mm, picks 3 mm, written as a declared ground."""
    from sysid.identified import load_identified

    base = str(tmp_path / "diag" / "report.json")
    os.makedirs(os.path.dirname(base))
    with open(base, "w") as f:
        json.dump({"model": {"latency": 0.01}, "base_model": {}, "effects": [{"family": "terrain_roughness", "value": 0.001}]}, f)
    truth = _report(tmp_path / "truth" / "report.json", {})
    with open(truth, "w") as f:
        json.dump({"model": {}, "base_model": {}, "effects": [{"family": "terrain_roughness", "value": 0.003}]}, f)
    real = [Recording(*run_episode({"world": "identified", "identified": [base, truth], "theta": THETA0, "seed": s,
                                    "seconds": 3.0, "record": True})["recording"]) for s in (1, 2, 3)]
    grid = {"terrain_roughness": (None, 0.003, 0.005)}
    fit = fit_walk_terms(real, [base], THETA0, str(tmp_path / "fit"), SerialExecutor(), seeds=[1, 2, 3],
                             seconds=3.0, grid=grid)
    assert fit["terms"] == {"terrain_roughness": 0.003}
    terms, rms = load_identified([base, fit["path"]])  # the fitted ground overrides the diagnosis's
    assert rms == 0.003 and {t.label(): v for t, v in terms.items()} == {"latency": 0.01}


def test_the_fit_recovers_an_injected_actuator_weakness(tmp_path):
    """"Real" walks from the identified sim with its leg servos 20 % weaker than the diagnosis says
    (kp x0.8): the fit, offered kp x1.0 and x0.8, picks x0.8; its saved result resumes."""
    base = _report(tmp_path / "diag" / "report.json", {"latency": 0.01})
    truth = _report(tmp_path / "truth" / "report.json", {f"pd_gain[{j}]": 0.8 for j in get_robot("nao").groups["legs"]})
    real = []
    for s in (1, 2):
        r = run_episode({"world": "identified", "identified": [base, truth], "theta": THETA0, "seed": s,
                         "seconds": 2.0, "record": True})
        real.append(Recording(*r["recording"]))
    grid = {"torque_limit": (1.0,), "pd_gain": (1.0, 0.8), "latency": (None,)}
    fit = fit_walk_terms(real, [base], THETA0, str(tmp_path / "fit"), SerialExecutor(), seeds=[5, 6],
                             seconds=2.0, grid=grid)
    assert fit["terms"]["pd_gain[LKneePitch]"] == 0.8 and "latency" not in fit["terms"]
    d = [c["distance"] for c in fit["walkfit"]["candidates"]]
    assert d[1] < 0.1 * d[0]
    again = fit_walk_terms([], [base], THETA0, str(tmp_path / "fit"), None, seeds=[5, 6], seconds=2.0, grid=grid)
    assert again["terms"] == fit["terms"]  # read back, nothing walked (no executor, no real walks)
    with pytest.raises(ValueError, match="at least 2 real walks"):
        fit_walk_terms(real[:1], [base], THETA0, str(tmp_path / "fit2"), SerialExecutor(), seeds=[5], seconds=2.0)
