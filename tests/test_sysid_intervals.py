"""Honest intervals and parsimonious link masses in the diagnosis.

* :func:`sysid.identify.discrepancy_bound`, the model-form part of every interval: on a linear
  least-squares problem with a known systematic error it bounds the bias the error causes, where the
  Gauss-Newton interval alone misses it; at the noise floor it shrinks to what noise can hide.
* :func:`sysid.diagnose._merge_link_masses`: two mass terms on one leg chain that stand in for a
  mass error on the link between them are replaced by that one term.
"""

import types

import numpy as np
import pytest

from robots import nao_h25
from sysid.candidates import Term
from sysid.diagnose import _Clock, _merge_link_masses
from sysid.identify import FitResult, Problem, confidence, discrepancy_bound, refit
from sysid.replay import whole_logs
from sysid.synthetic import synthetic_logs


def _linear_fit(d_along: float, d_perp: float, seed: int, n: int = 4000):
    """One-parameter model y = θ x (θ = 1, a kp scale as the stand-in term) fitted by least
    squares to data with unit white noise and a systematic error d = d_along x̂ + d_perp p̂ (x̂, p̂
    unit-RMS shapes, p̂ ⟂ x̂); residuals in floor units (the floor is the noise σ = 1)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 20.0, n)
    x = np.sin(1.3 * t) + 0.4 * np.sin(3.1 * t)
    x /= np.sqrt(np.mean(x ** 2))
    p = np.cos(0.7 * t) * np.sin(2.2 * t)
    p -= (p @ x) / (x @ x) * x
    p /= np.sqrt(np.mean(p ** 2))
    y = 1.0 * x + d_along * x + d_perp * p + rng.normal(0.0, 1.0, n)
    theta = float(x @ y / (x @ x))
    resid = y - theta * x  # (measured - predicted) / floor
    term = Term("pd_gain", "LKneePitch")
    fit = FitResult(values={term: theta}, terms=[term], cost=float(resid @ resid), jac=-x[:, None],
                    resid=resid, nfev=1)
    return fit, types.SimpleNamespace(k=1), theta - 1.0


@pytest.mark.parametrize("d_along,d_perp", [(0.2, 0.3), (0.3, 0.3), (-0.25, 0.5)])
def test_discrepancy_bound_covers_the_bias_of_a_systematic_error(d_along, d_perp):
    for seed in range(5):
        fit, prob, bias = _linear_fit(d_along, d_perp, seed)
        b = discrepancy_bound(fit, prob, tau_int=1.0)[0]
        sd_gn = np.sqrt(fit.resid @ fit.resid / (len(fit.resid) - 1) / (fit.jac[:, 0] @ fit.jac[:, 0]))
        assert abs(bias) > 1.96 * sd_gn * 3  # the Gauss-Newton interval alone misses the bias by far
        assert abs(bias) <= b, (bias, b)
        assert b < 4 * max(abs(bias), 0.05)  # and the bound is not vacuous


def test_discrepancy_bound_at_the_floor_is_what_noise_can_hide():
    fit, prob, bias = _linear_fit(0.0, 0.0, seed=1)
    n = len(fit.resid)
    excess = max(float(np.mean(fit.resid ** 2)) - 1.0, 0.0)  # noise alone: a few % either way
    assert excess < 0.1
    # sqrt((JᵀJ)⁻¹) = 1/sqrt(n) for a unit-RMS x, so the bound is sqrt(excess + 2 sqrt(2 τ/n))
    for tau in (1.0, 16.0):
        b = discrepancy_bound(fit, prob, tau_int=tau)[0]
        assert b == pytest.approx(np.sqrt(excess + 2.0 * np.sqrt(2.0 * tau / n)), rel=1e-9)
        assert abs(bias) < b
    # a longer autocorrelation time (fewer independent samples) lets more hide
    assert discrepancy_bound(fit, prob, tau_int=16.0)[0] > 1.8 * discrepancy_bound(fit, prob, tau_int=1.0)[0]


def test_confidence_adds_the_bound_to_the_statistical_interval():
    fit, prob, _ = _linear_fit(0.3, 0.3, seed=2)
    prob.robot = nao_h25()
    t = fit.terms[0]
    ci, _ = confidence(fit, prob, 1.0)
    ci0, _ = confidence(fit, prob, 1.0, model_form=False)
    b = discrepancy_bound(fit, prob, 1.0)[0]
    assert (ci[t][1] - ci[t][0]) == pytest.approx(ci0[t][1] - ci0[t][0] + 2 * b, rel=1e-6)
    assert ci[t][0] <= 1.0 <= ci[t][1] and not ci0[t][0] <= 1.0 <= ci0[t][1]


def test_two_masses_on_one_chain_become_the_one_between():
    robot = nao_h25()
    truth = {Term("link_mass", "LTibia"): 1.6}
    logs = synthetic_logs(truth, n_logs=3, seconds=3.0, seed=5, traj_seed=61,
                          segments=("holds", "ramps", "steps", "chirp"))
    problem = Problem(logs, whole_logs(logs, [0, 1]), whole_logs(logs, [2]), np.full(24, 1e-3))
    pair = dict(refit(problem, {Term("link_mass", "LThigh"): 1.3, Term("link_mass", "LAnklePitch"): 1.3},
                      grid=False).values)
    cost = float(problem.cost([pair], "heldout")[0])
    step = _merge_link_masses(problem, pair, cost, robot, _Clock(0.0, None))
    assert set(step.model) == {Term("link_mass", "LTibia")}, step.model
    assert step.model[Term("link_mass", "LTibia")] == pytest.approx(1.6, rel=0.03)
    assert len(step.rejected) == 2 and all("LTibia" in r["reason"] for r in step.rejected)
    # a true pair on two different chains stays as it is
    other = {Term("link_mass", "LThigh"): 1.3, Term("link_mass", "RThigh"): 1.3}
    step2 = _merge_link_masses(problem, other, cost, robot, _Clock(0.0, None))
    assert step2.model == other and not step2.rejected
