"""experiments.runtime.stats: intervals and tests against hand-computed values; fidelity metrics on constructed worlds."""

import math

import numpy as np
import pytest

from experiments.runtime import stats as S


def test_wilson_hand_computed():
    # k = 3, n = 10, z = 1.95996: centre (0.3 + z²/20) / (1 + z²/10) = 0.35550,
    # half-width z sqrt(0.021 + z²/400) / (1 + z²/10) = 0.24772
    lo, hi = S.wilson_interval(3, 10)
    assert lo == pytest.approx(0.10779, abs=1e-4) and hi == pytest.approx(0.60322, abs=1e-4)
    # k = 0: [0, z² / (n + z²)] = [0, 3.8415 / 23.8415]
    lo, hi = S.wilson_interval(0, 20)
    assert lo == 0 and hi == pytest.approx(0.16113, abs=1e-4)
    assert math.isnan(S.wilson_interval(0, 0)[0])
    with pytest.raises(ValueError):
        S.wilson_interval(5, 3)


def test_paired_permutation_exact_hand_computed():
    # d = (1, 2, 3): of the 8 sign patterns only +-(1+2+3) reach |sum| >= 6 -> p = 2/8
    r = S.paired_permutation_test([2, 4, 6], [1, 2, 3])
    assert r["mean_diff"] == pytest.approx(2.0) and r["p_value"] == pytest.approx(0.25)
    # d = (1, 2, 3, 4): 2 of 16 patterns reach |sum| >= 10
    assert S.paired_permutation_test([1, 2, 3, 4], [0, 0, 0, 0])["p_value"] == pytest.approx(0.125)
    assert S.paired_permutation_test([1, 2], [1, 2])["p_value"] == 1.0
    with pytest.raises(ValueError):
        S.paired_permutation_test([1, 2, 3], [1, 2])


def test_seed_level_t_test_hand_computed():
    # d = (3.1, 5.0, 7.2): mean 5.1, sd sqrt(((-2)^2 + 0.1^2 + 2.1^2) / 2) = sqrt(4.21), se = sd / sqrt(3);
    # t = mean / se on 2 degrees of freedom; t(0.975, 2) = 4.302653 (Student's table); two-sided p of
    # t = 4.3052 on 2 df is 2 (1 - F(t)) = 1 - t / sqrt(t^2 + 2) (the closed form for 2 df)
    r = S.seed_level_test([3.1, 5.0, 7.2])
    se = math.sqrt(4.21) / math.sqrt(3)
    assert r["n_seeds"] == 3 and r["df"] == 2 and r["mean_diff"] == pytest.approx(5.1)
    assert r["t"] == pytest.approx(5.1 / se)
    assert r["ci"] == pytest.approx([5.1 - 4.302653 * se, 5.1 + 4.302653 * se], abs=1e-5)
    assert r["p_value"] == pytest.approx(1 - r["t"] / math.sqrt(r["t"] ** 2 + 2))
    assert 0.049 < r["p_value"] < 0.05  # the interval just excludes 0
    # seeds that disagree: the interval holds 0 whatever the trial-level test said
    r2 = S.seed_level_test([17.4, -19.7, 10.5])
    assert r2["ci"][0] < 0 < r2["ci"][1] and r2["p_value"] > 0.5
    assert S.seed_level_test([2.0]) is None and S.seed_level_test([1.5, 1.5, 1.5]) is None
    with pytest.raises(ValueError):
        S.seed_level_test([1.0, float("nan")])
    with pytest.raises(ValueError):
        S.seed_level_test([1.0, 2.0], confidence=1.0)


def test_mcnemar_hand_computed():
    # 4 pairs where only the first fell, 1 where only the second: P(X <= 1 or X >= 4), X ~ B(5, 1/2)
    # = (1 + 5 + 5 + 1) / 32
    r = S.mcnemar_test([1, 1, 1, 1, 0, 0, 1], [0, 0, 0, 0, 0, 1, 1])
    assert (r["only_a"], r["only_b"]) == (4, 1) and r["p_value"] == pytest.approx(12 / 32)
    assert S.mcnemar_test([1, 0], [1, 0])["p_value"] == 1.0


def test_brier_score():
    assert S.brier_score([0.5, 1.0], [[1, 0], [1, 1]]) == pytest.approx((0.25 + 0.25 + 0 + 0) / 4)
    with pytest.raises(ValueError):
        S.brier_score([1.5], [[1]])


def _panel(G=20, M=10, seed=0, noise=3.0):
    rng = np.random.default_rng(seed)
    true = np.linspace(-10, 20, G)
    return true, true[:, None] + rng.normal(0, noise, (G, M))


def test_a_world_that_is_the_real_world_reaches_the_ceiling():
    true, R = _panel()
    _, R2 = _panel(seed=1)  # the same gaits on independent trials: a perfect training world, trial noise only
    world = R2.mean(1)
    rho = S.spearman(world, R.mean(1))
    rel = S.split_half_reliability(R)
    assert rel["ceiling"] > 0.95 and rho > 0.9
    assert abs(np.mean(world - R.mean(1))) < 1.5  # bias: zero up to the trial noise (s.e. 3/sqrt(10) per mean)
    lo, hi = S.bootstrap_spearman(world, R, n_boot=300)
    assert lo <= rho <= hi and hi - lo < 0.2


def test_a_world_that_shuffles_the_gaits_ranks_at_chance():
    true, R = _panel()
    rng = np.random.default_rng(3)
    rhos = [S.spearman(rng.permutation(true), R.mean(1)) for _ in range(200)]
    assert abs(np.mean(rhos)) < 0.05 and np.std(rhos) > 0.1


def test_noisy_trials_lower_the_ceiling():
    _, clean = _panel(noise=1.0)
    _, noisy = _panel(noise=30.0)
    assert S.split_half_reliability(noisy)["ceiling"] < S.split_half_reliability(clean)["ceiling"] - 0.2
    assert math.isnan(S.spearman([1, 1, 1], [1, 2, 3]))


def test_pick_regret():
    real = [3.0, -2.0, 10.0, 1.0]
    assert S.pick_regret(real, real) == 0.0  # the real world picks the real best
    assert S.pick_regret([-x for x in real], real) == pytest.approx(12.0)  # picks the worst: max - min
    assert S.pick_regret([5, 5, 0, 0], real) == pytest.approx(10.0 - 0.5)  # a tie at the top: their mean
    # an optimistic world that ranks well except for one gait it overrates is charged for that gait
    assert S.pick_regret([3, -2, 9, 20], real) == pytest.approx(9.0)
    for bad in (([1.0], [1.0]), ([1, 2], [1, 2, 3]), ([1, float("nan")], [1, 2])):
        with pytest.raises(ValueError):
            S.pick_regret(*bad)


def _world_episodes(true, noise, draws, episodes, seed, shuffle=False):
    """(draws, gaits, episodes) fitness of a training world: the true fitness (permuted across the gaits
    when ``shuffle``: a world that ranks at chance) plus episode noise."""
    rng = np.random.default_rng(seed)
    base = rng.permutation(true) if shuffle else true
    return base[None, :, None] + rng.normal(0, noise, (draws, len(true), episodes))


def test_paired_rho_difference_tells_a_faithful_world_from_a_shuffled_one_and_not_from_itself():
    """A world that knows the true fitness (episode noise only) against one that shuffles the gaits:
    Δρ near the faithful world's ρ, its interval above 0, p small. Two equally faithful worlds
    (independent noise): Δρ near 0, the interval around 0, p large. A world against itself: Δρ = 0
    exactly on every draw and every replicate, p = 1. The observed figure is the mean of the per-draw
    Spearman differences; a one-draw world (the plain sim) is paired with every draw."""
    true, R = _panel()
    good = _world_episodes(true, 2.0, 5, 4, seed=10)
    bad = _world_episodes(true, 2.0, 5, 4, seed=11, shuffle=True)
    res = S.paired_spearman_difference(good, bad, R, n_boot=400, seed=0)
    want = np.mean([S.spearman(good[d].mean(1), R.mean(1)) - S.spearman(bad[d].mean(1), R.mean(1)) for d in range(5)])
    assert res["diff"] == pytest.approx(want) and len(res["per_draw"]) == 5
    assert res["diff"] > 0.5 and res["ci"][0] > 0.2 and res["p_value"] < 0.01 and res["n_boot"] == 400
    twin = _world_episodes(true, 2.0, 5, 4, seed=12)
    same = S.paired_spearman_difference(good, twin, R, n_boot=400, seed=0)
    assert abs(same["diff"]) < 0.1 and same["ci"][0] < 0 < same["ci"][1] and same["p_value"] > 0.1
    self_ = S.paired_spearman_difference(good, good, R, n_boot=200, seed=0)
    assert self_["diff"] == 0 and self_["ci"] == [0.0, 0.0] and self_["p_value"] == 1.0
    # with the panel's gaits kept, only the trial and episode noise is left: a narrower interval, the same figure
    panel = S.paired_spearman_difference(good, twin, R, n_boot=400, seed=0, resample_gaits=False)
    assert panel["diff"] == same["diff"] and panel["ci"][1] - panel["ci"][0] < same["ci"][1] - same["ci"][0]
    sim = _world_episodes(true, 0.0, 1, 1, seed=13, shuffle=True)  # deterministic, no draws
    vs_sim = S.paired_spearman_difference(good, sim, R, n_boot=200, seed=0)
    assert len(vs_sim["per_draw"]) == 5 and vs_sim["diff"] > 0.5
    for bad_args, words in [((good, bad[:, :5], R), "gaits"), ((good, bad[:3], R), "draws"),
                            ((good[:, :2], bad[:, :2], R[:2]), "at least 3"), ((good[0], bad, R), "shape")]:
        with pytest.raises(ValueError, match=words):
            S.paired_spearman_difference(*bad_args)
