"""Each candidate family: inject it (synthetic short logs, 1 mrad noise), screen, refit, recover.

The logs are made with the candidate augmentations themselves (``sysid.synthetic``), so these
tests check that screening names the right family and place and that the refit recovers the
value; the blind benchmark checks the physics with independently injected effects.
"""

import numpy as np
import pytest

from robots import nao_h25
from sysid.candidates import FIXED_BASE_FAMILIES, Term
from sysid.identify import Problem, refit, screen
from sysid.replay import whole_logs
from sysid.synthetic import synthetic_logs

CASES = [
    ({Term("latency"): 0.018}, 0.001),  # absolute tolerance [s]
    ({Term("backlash", "RKneePitch"): 0.03}, 0.10),  # relative tolerances
    ({Term("coulomb_friction", "LHipPitch"): 0.2}, 0.10),
    ({Term("viscous_damping", "RHipRoll"): 0.25}, 0.10),
    ({Term("pd_gain", "LAnklePitch"): 0.6}, 0.05),
    ({Term("torque_limit"): 0.6}, 0.05),
    ({Term("link_mass", "r_ankle"): 1.7}, 0.10),
    ({Term("armature", "LKneePitch"): 0.008}, 0.15),
    ({Term("sensor_bias", "RShoulderRoll"): -0.012}, 0.05),
    ({Term("joint_compliance", "LHipPitch"): 0.02}, 0.10),  # [rad/(N m)]: k = 50 N m/rad vs kp 30
]


@pytest.mark.parametrize("truth,tol", CASES, ids=[next(iter(c[0])).family for c in CASES])
def test_family_injection_and_recovery(truth, tol):
    robot = nao_h25()
    logs = synthetic_logs(truth, n_logs=2, seconds=3.0, seed=3, traj_seed=40,
                          segments=("holds", "ramps", "steps", "reversals", "chirp"))
    floor = np.full(24, 1e-3)
    problem = Problem(logs, whole_logs(logs, [0]), whole_logs(logs, [1]), floor)
    sr = screen(problem, robot, {}, FIXED_BASE_FAMILIES)
    (t_true, v_true), = truth.items()
    assert t_true in sr.selected, f"screening picked {[t.label() for t in sr.selected]}"
    fit = refit(problem, {t_true: sr.selected[t_true]})
    v = fit.values[t_true]
    err = abs(v - v_true) if t_true.family == "latency" else abs(v - v_true) / abs(v_true - t_true.fam.nominal)
    assert err < tol, f"{t_true.label()}: fitted {v:.5g}, truth {v_true:.5g}"
    c = problem.cost([{}, fit.values], "heldout")
    assert c[1] - 24 < 0.3 * (c[0] - 24)  # the fitted effect explains held-out data (24 = floor)


def test_omp_bic_picks_the_generating_columns():
    from sysid.identify import omp_bic

    rng = np.random.default_rng(0)
    D = rng.normal(size=(2000, 12))
    r = 2.0 * D[:, 3] + 0.7 * D[:, 8] + rng.normal(size=2000)
    sel, w, path = omp_bic(D, r, n_eff=200)
    assert sorted(sel) == [3, 8]
    np.testing.assert_allclose(sorted(w), [0.7, 2.0], atol=0.1)
    sel0, _, _ = omp_bic(D, rng.normal(size=2000), n_eff=200)
    assert sel0 == []  # pure noise: nothing selected
    # every candidate already in the model (an empty dictionary) or fewer columns than max_k
    assert omp_bic(np.zeros((2000, 0)), r, n_eff=200)[0] == []
    assert sorted(omp_bic(D[:, [3, 8]], r, n_eff=200, max_k=6)[0]) == [0, 1]


def test_terms_within_the_smallest_reported_effect_are_flagged():
    from sysid.diagnose import _below_min_effect

    vals = {Term("sensor_bias", "LHipPitch"): 1e-4, Term("pd_gain", "RKneePitch"): 1.013,
            Term("pd_gain", "LKneePitch"): 0.9, Term("latency"): 0.02, Term("armature", "LHipRoll"): 5e-4}
    assert sorted(t.label() for t in _below_min_effect(vals)) == ["pd_gain[RKneePitch]", "sensor_bias[LHipPitch]"]


def test_torque_constant_is_named_by_the_diagnosis_not_as_kp_plus_damping():
    """A torque-constant error (kp and kd x1.4) lies in the span of the kp-only and the viscous
    damping columns, so linear screening alone may pick those two; the refit's family competition
    and backward elimination name the single family that made the logs, with its value."""
    from sysid.diagnose import diagnose

    logs = synthetic_logs({Term("torque_constant", "RHipPitch"): 1.4}, n_logs=3, seconds=3.0, seed=3, traj_seed=40,
                          segments=("holds", "ramps", "steps", "reversals", "chirp"))
    rep = diagnose(logs, families=FIXED_BASE_FAMILIES + ("torque_constant",))
    fams = {(e["family"], tuple(e["joints"])): e for e in rep["effects"]}
    assert list(fams) == [("torque_constant", ("RHipPitch",))], rep["verdict"]
    assert abs(fams[("torque_constant", ("RHipPitch",))]["value"] - 1.4) < 0.05 * 0.4
