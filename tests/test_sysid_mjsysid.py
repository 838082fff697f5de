"""Fits through ``mujoco.sysid`` (its parameterisations, optimizer and intervals) agree with the
package's own least-squares refit on the same replays."""

import copy

import numpy as np
import pytest

from sysid import mjsysid
from sysid.candidates import Term, apply_terms, series_structure
from sysid.identify import Problem, refit
from sysid.model import Structure, replay_model
from sysid.replay import whole_logs
from sysid.synthetic import synthetic_logs


def test_mujoco_sysid_parameterisations_write_what_the_candidates_write():
    """apply_pdgain / body_inertia_param on the replay spec compile to the fields apply_terms edits."""
    vals = {Term("pd_gain", "LKneePitch"): 0.8, Term("kd_gain", "LKneePitch"): 0.6,
            Term("link_mass", "LTibia"): 1.4, Term("link_com", "LTibia:x"): 0.01}
    rm = replay_model(Structure())
    par = mjsysid.parameters(rm, list(vals), vals)
    (rm2, m, bias, _), = mjsysid.compile_models(rm, par, par.vector(vals)[:, None], {})
    ref = copy.copy(rm.model)
    apply_terms(rm, ref, vals)
    a, b = rm.act[rm.robot.joint_names.index("LKneePitch")], rm.body["LTibia"]
    np.testing.assert_allclose(m.actuator_gainprm[a, 0], ref.actuator_gainprm[a, 0])
    np.testing.assert_allclose(m.actuator_biasprm[a, :3], ref.actuator_biasprm[a, :3])
    np.testing.assert_allclose(m.body_mass[b], ref.body_mass[b])
    np.testing.assert_allclose(m.body_ipos[b], ref.body_ipos[b], atol=1e-12)
    np.testing.assert_allclose(m.body_inertia[b], ref.body_inertia[b], rtol=1e-9)
    assert par.values(par.vector(vals)) == pytest.approx(vals)


def test_a_parameterisation_mujoco_sysid_lacks_is_refused():
    rm = replay_model(series_structure(Structure(), {Term("backlash", "LKneePitch"): 0.02}))
    with pytest.raises(ValueError, match="no mujoco.sysid parameterisation"):
        mjsysid.parameters(rm, [Term("backlash", "LKneePitch")], {Term("backlash", "LKneePitch"): 0.02})
    with pytest.raises(ValueError, match="series hinge"):
        mjsysid.parameters(rm, [Term("pd_gain", "LKneePitch")], {Term("pd_gain", "LKneePitch"): 0.9})


def test_a_servo_gain_fit_through_mujoco_sysid_matches_the_packages_own():
    """kp x0.6 at an ankle: mujoco.sysid.optimize (apply_pgain, the "mujoco" optimizer) and
    sysid.identify.refit reach the same value; calculate_intervals holds the truth."""
    t = Term("pd_gain", "LAnklePitch")
    logs = synthetic_logs({t: 0.6}, n_logs=2, seconds=3.0, seed=3, traj_seed=40, segments=("holds", "steps", "chirp"))
    p = Problem(logs, whole_logs(logs, [0]), whole_logs(logs, [1]), np.full(24, 1e-3))
    own = refit(p, {t: 0.8})
    ms = mjsysid.fit(p, {t: 0.8}, [t], max_iters=8)
    assert abs(ms.values[t] - own.values[t]) < 2e-3
    assert abs(ms.values[t] - 0.6) < 0.01
    half = mjsysid.intervals(ms)[t]
    assert 0 < half < 0.05 and abs(ms.values[t] - 0.6) < half + 0.005
