"""Tabular GAT / SGAT (sgat.tabular): the toy MDPs (paper Figs. 3-5) and Cliff Walking
(Sec. IV.A, Figs. 6-7)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sgat import tabular as T

UP, DOWN, LEFT, RIGHT = range(4)
A1, A2, A3 = range(3)


def _grounded_choice(sim, real, method, model=None):
    model = T.ForwardModel.exact(real) if model is None else model
    G = T.action_transformer(sim, model, method)
    g = T.grounded_mdp(sim, G)
    return int(T.policy_iteration(g).policy[g.start]), G, g


# ---------------------------------------------------------------------------------- toy MDPs


def test_deterministic_toy_both_choose_a2():
    sim, real = T.toy_deterministic()
    assert T.policy_iteration(sim).policy[0] == A1  # sim prefers a1 (+1)
    assert T.policy_iteration(real).policy[0] == A2  # reality swaps the outcomes
    for method in ("gat", "sgat"):
        choice, G, g = _grounded_choice(sim, real, method)
        assert choice == A2, method
        # paper Fig. 3c: the transformer swaps a1 and a2, so the grounded sim behaves like real.
        assert G[0, A1, A2] == 1.0 and G[0, A2, A1] == 1.0
        np.testing.assert_allclose(g.P, real.P)


def test_stochastic_toy_gat_chooses_a1_sgat_chooses_a2():
    sim, real = T.toy_stochastic()
    assert T.policy_iteration(sim).policy[0] == A3
    assert T.policy_iteration(real).policy[0] == A2
    gat, G_gat, g_gat = _grounded_choice(sim, real, "gat")
    sgat, G_sgat, g_sgat = _grounded_choice(sim, real, "sgat")
    assert gat == A1  # paper Fig. 4c: a2 and a3 both look like "go to s2"
    assert sgat == A2  # paper Fig. 5: the 20 % chance of s3 survives
    np.testing.assert_allclose(G_gat[0, A2], [0, 1, 0])
    np.testing.assert_allclose(G_gat[0, A3], [0, 1, 0])
    np.testing.assert_allclose(G_sgat[0, A2], [0, 0.8, 0.2])
    np.testing.assert_allclose(g_sgat.P, real.P)  # SGAT grounded sim == real (paper Fig. 5)
    assert not np.allclose(g_gat.P, real.P)


@pytest.mark.parametrize("fig, expected", [(T.toy_deterministic, {"gat": A2, "sgat": A2}),
                                           (T.toy_stochastic, {"gat": A1, "sgat": A2})])
def test_toy_grounding_loop_from_sampled_real_data(fig, expected):
    """Algorithm 1 with counted models from seeded real episodes reaches the paper's choices.

    In the stochastic toy the real margin of a2 over a1 is small (1.2 vs 1.0: SGAT needs the
    estimated P(s3 | a2) above 2/11 = 0.18 against a true 0.2), so the data are uniformly
    exploratory and plentiful; with a few dozen a2 samples SGAT can settle on a1 (finite-data
    error).
    """
    sim, real = fig()
    for seed in range(5):
        for method, action in expected.items():
            res = T.ground(sim, real, method, np.random.default_rng(seed), real_episodes=5000,
                           explore=1.0, patience=2)
            assert res.converged
            assert res.initial_policy[0] == T.policy_iteration(sim).policy[0]
            assert res.policy[0] == action, (method, seed)


def test_unvisited_pairs_fall_back_to_the_sim():
    sim, real = T.toy_stochastic()
    # real data only for a2: a1 and a3 keep their sim behaviour (identity transformer)
    model = T.ForwardModel.from_transitions(4, 3, [0] * 10, [A2] * 10, [2] * 8 + [3] * 2)
    G = T.action_transformer(sim, model, "sgat")
    np.testing.assert_allclose(G[0], [[1, 0, 0], [0, 0.8, 0.2], [0, 0, 1]])
    G = T.action_transformer(sim, model, "sgat", min_count=11)  # too little data: identity
    np.testing.assert_allclose(G[0], np.eye(3))


# ----------------------------------------------------------------------------- cliff walking


def test_cliff_layout_and_noise_model():
    sim, p = T.cliff_walking(0.0), 0.4
    real = T.cliff_walking(p)
    assert sim.P.shape == (48, 4, 48) and sim.is_deterministic()
    assert sim.start == 36 and sim.terminal[37:48].all() and sim.terminal.sum() == 11
    nxt = sim.next_state()
    assert nxt[36, LEFT] == 36 and nxt[36, DOWN] == 36  # walls: no-op
    assert nxt[36, RIGHT] == 37 and nxt[36, UP] == 24
    assert sim.R[36, RIGHT, 37] == pytest.approx(-10.1)  # cliff -10 plus the step
    assert sim.R[35, DOWN, 47] == pytest.approx(99.9)  # goal +100 plus the step
    s = 13  # interior cell (1, 1): chosen move w.p. 1 - p + p/4, each other w.p. p/4
    assert real.P[s, RIGHT, 14] == pytest.approx(1 - 3 * p / 4)
    assert real.P[s, RIGHT, 12] == pytest.approx(p / 4)
    assert real.P[0, UP, 0] == pytest.approx(1 - p + p / 2)  # corner: up and left both stay
    full = T.cliff_walking(1.0)
    assert np.allclose(full.P, full.P[:, :1, :])  # noise 1: the action has no effect
    v = T.policy_iteration(sim).v[sim.start]
    assert v == pytest.approx(100 - 13 * 0.1)  # shortest path, 13 steps
    for bad in (-0.01, 1.01, float("nan")):
        with pytest.raises(ValueError, match="noise"):
            T.cliff_walking(bad)


def test_sim_inverse_ties_and_unreachable_states():
    sim = T.cliff_walking(0.0)
    inv = T.sim_inverse_table(sim)
    corner = 0  # (0, 0): up and left both stay
    assert inv[corner, corner, UP] == UP and inv[corner, corner, LEFT] == LEFT
    assert inv[corner, corner, RIGHT] == UP  # tie, agent's action not among them: lowest index
    assert inv[corner, 1, UP] == RIGHT
    assert all(inv[corner, 30, a] == a for a in range(4))  # unreachable: keep the action
    with pytest.raises(ValueError, match="deterministic"):
        T.sim_inverse_table(T.cliff_walking(0.2))


def test_improper_policy_is_guarded_and_policy_iteration_recovers():
    sim = T.cliff_walking(0.0)
    stuck = np.full(48, LEFT, dtype=int)  # the start pushes into the wall forever
    v = T.policy_evaluation(sim, stuck, improper_value=-1e6)
    assert v[sim.start] == -1e6 and np.isfinite(v).all()
    res = T.policy_iteration(sim, stuck)
    assert res.converged
    assert res.v[sim.start] == pytest.approx(98.7)
    ev = T.evaluate_policy(sim, stuck, 50, 0, max_steps=30)
    assert ev.truncated == 50 and ev.mean == pytest.approx(-3.0)


def test_policy_iteration_with_a_trap_no_policy_can_leave():
    # s0 --a0--> s1 (a non-terminal trap), s0 --a1--> s2 (terminal, -1); s1 loops under both
    P = np.zeros((3, 2, 3))
    P[0, 0, 1] = P[0, 1, 2] = P[1, :, 1] = P[2, :, 2] = 1.0
    R = np.zeros((3, 2, 3))
    R[0, 1, 2] = -1.0
    R[1, :, 1] = -0.1
    mdp = T.TabularMDP(P, R, np.array([False, False, True]), 0)
    res = T.policy_iteration(mdp, np.array([0, 0, 0]))
    assert res.converged and res.policy[0] == 1
    assert res.v[0] == pytest.approx(-1.0) and res.v[1] == T.IMPROPER_VALUE


def test_vectorised_evaluation_matches_exact_value():
    real = T.cliff_walking(0.3)
    pi = T.policy_iteration(real).policy
    exact = T.policy_evaluation(real, pi)[real.start]
    ev = T.evaluate_policy(real, pi, 10_000, np.random.default_rng(7))
    assert ev.n == 10_000 and ev.truncated == 0 and 0 < ev.se < 1
    assert abs(ev.mean - exact) < 4 * ev.se
    again = T.evaluate_policy(real, pi, 10_000, np.random.default_rng(7))
    assert again == ev  # seeded: reproducible
    with pytest.raises(ValueError):
        T.evaluate_policy(real, pi, 0)


@pytest.mark.parametrize("p", [0.1, 0.5, 0.9])
def test_exact_sgat_model_grounds_cliff_to_real(p):
    """With the infinite-data forward model SGAT's grounded sim *is* real; GAT's is the sim
    below noise 0.8 (the chosen move stays the most likely one everywhere)."""
    sim, real = T.cliff_walking(0.0), T.cliff_walking(p)
    model = T.ForwardModel.exact(real)
    g_sgat = T.grounded_mdp(sim, T.action_transformer(sim, model, "sgat"))
    np.testing.assert_allclose(g_sgat.P, real.P, atol=1e-12)
    g_gat = T.grounded_mdp(sim, T.action_transformer(sim, model, "gat"))
    if p < 0.8:
        np.testing.assert_allclose(g_gat.P, sim.P)
    v_gat = T.policy_evaluation(real, T.policy_iteration(g_gat).policy)[real.start]
    v_opt = T.policy_iteration(real).v[real.start]
    assert v_gat < v_opt - 0.5


def _combined_se(row, a, b):
    return math.hypot(row[f"{a}_se"], row[f"{b}_se"])


def _check_row(row):
    p = row["noise"]
    se = _combined_se(row, "gat", "sgat")
    if p in (0.0, 1.0):  # the endpoints: no distinction between the algorithms
        assert abs(row["sgat_return"] - row["gat_return"]) <= max(se, 1e-9)
    else:  # intermediate noise: SGAT beats GAT by more than 3 standard errors
        assert row["sgat_return"] > row["gat_return"] + 3 * se
    assert row["sgat_value"] >= row["gat_value"] - 1e-9  # exact expected returns
    # SGAT is within a standard error of the policy solved on the true real MDP
    assert row["optimal_value"] - row["sgat_value"] <= max(row["sgat_se"], 1e-9)
    assert abs(row["sgat_return"] - row["optimal_return"]) <= max(
        _combined_se(row, "sgat", "optimal"), 1e-9)


def test_cliff_gat_vs_sgat_at_key_noise_values():
    from experiments.cliff.run import compare_at_noise

    rows = [compare_at_noise(0.0), compare_at_noise(0.3),
            # at noise 1 every policy is equivalent; a short grounding budget is enough
            compare_at_noise(1.0, max_grounding_steps=3)]
    for row in rows:
        _check_row(row)
    assert rows[0]["gat_return"] == rows[0]["sgat_return"] == pytest.approx(98.7)
    gat, sgat = rows[1]["policies"]["gat"], rows[1]["policies"]["sgat"]
    sim = T.cliff_walking(0.0)
    nxt = sim.next_state()
    # GAT keeps the sim's shortest path next to the cliff; SGAT climbs away from it
    assert nxt[36, gat[36]] == 24 and nxt[24, gat[24]] == 25
    assert nxt[24, sgat[24]] == 12


@pytest.mark.slow
def test_cliff_full_sweep_reproduces_fig7():
    """The paper's Fig. 7 sweep (11 noise values; its speed is measured by ``sgatwalk cliff``, which
    prints the time it took, not asserted here)."""
    from experiments.cliff.run import sweep

    rows = sweep(np.linspace(0, 1, 11).round(12).tolist())
    for row in rows:
        _check_row(row)
