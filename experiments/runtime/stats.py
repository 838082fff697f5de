"""Statistics the experiments report: intervals, rank agreement, calibration and paired tests.

Everything here is a thin, documented layer over ``scipy.stats``:

* :func:`wilson_interval` -- Wilson's score interval of a proportion (E. B. Wilson, JASA 1927;
  ``scipy.stats.binomtest(...).proportion_ci(method="wilson")``).
* :func:`spearman` and :func:`bootstrap_spearman` -- Spearman's rank correlation
  (``scipy.stats.spearmanr``) and its percentile bootstrap interval over paired real trials
  (Efron & Tibshirani 1993, ch. 13).
* :func:`paired_spearman_difference` -- is one training world's ranking better than another's beyond
  the noise? A paired hierarchical bootstrap (Davison & Hinkley, "Bootstrap Methods and their
  Application", 1997, §3.8: resampling at every level of the design) of the difference of their
  Spearman ρ with the real fitness, over the gaits, the real trials and the worlds' episodes.
* :func:`brier_score` -- the Brier score of forecast probabilities against 0/1 outcomes
  (Brier, Monthly Weather Review 1950).
* :func:`split_half_reliability` -- how reliable a mean over trials is: the Spearman correlation of
  two half-means over random splits, stepped up by the Spearman-Brown formula 2r / (1 + r); its
  square root is the correlation the observed means can reach with the true ones (the "index of
  reliability", Lord & Novick 1968, §3.4), the ceiling of any predictor's correlation with them.
* :func:`paired_permutation_test` -- two-sided sign-flip test of a mean paired difference
  (``scipy.stats.permutation_test`` with ``permutation_type="samples"``).
* :func:`mcnemar_test` -- McNemar's exact test on paired binary outcomes: a binomial test on the
  discordant pairs (McNemar, Psychometrika 1947; ``scipy.stats.binomtest``).
* :func:`seed_level_test` -- the method-level comparison with optimization seeds as the units: a
  one-sample t-test and t-interval of the per-seed mean differences (``scipy.stats.ttest_1samp``;
  seeds as the sample, as Colas, Sigaud & Oudeyer, "How many random seeds?", arXiv:1806.08295, 2018,
  compare RL algorithms).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy import stats

#: z of a two-sided 95 % normal interval.
Z95 = 1.959963984540054


def wilson_interval(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of the proportion ``k / n``; (nan, nan) for ``n == 0``.

    Raises:
        ValueError: ``k`` outside [0, n].
    """
    if n <= 0:
        return (math.nan, math.nan)
    if not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    ci = stats.binomtest(int(k), int(n)).proportion_ci(confidence_level=confidence, method="wilson")
    return (float(ci.low), float(ci.high))


def spearman(x, y) -> float:
    """Spearman's rank correlation of two equal-length vectors; nan if either is constant or shorter
    than 3."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if len(x) != len(y):
        raise ValueError(f"spearman: lengths differ ({len(x)} vs {len(y)})")
    if len(x) < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return math.nan
    return float(stats.spearmanr(x, y).statistic)


def bootstrap_spearman(pred, trials, *, n_boot: int = 1000, level: float = 0.90, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of Spearman's ρ between ``pred`` (G,) and the mean over the
    paired trials ``trials`` (G, M): trial indices are resampled with replacement, the same for every
    gait (the trials are paired: trial j of every gait ran on the same seed).

    Raises:
        ValueError: shapes that do not match.
    """
    pred = np.asarray(pred, dtype=float)
    trials = np.asarray(trials, dtype=float)
    if trials.ndim != 2 or trials.shape[0] != len(pred):
        raise ValueError(f"trials must have shape ({len(pred)}, M), got {trials.shape}")
    rng = np.random.default_rng(seed)
    M = trials.shape[1]
    rhos = []
    for _ in range(n_boot):
        idx = rng.integers(0, M, M)
        r = spearman(pred, trials[:, idx].mean(1))
        if math.isfinite(r):
            rhos.append(r)
    if not rhos:
        return (math.nan, math.nan)
    a = (1 - level) / 2
    return (float(np.quantile(rhos, a)), float(np.quantile(rhos, 1 - a)))


def _rho_rows(x: np.ndarray, ranked_y: np.ndarray) -> np.ndarray:
    """Spearman's ρ along the last axis: Pearson's r (``scipy.stats.pearsonr``, vectorized) of the
    average ranks (``scipy.stats.rankdata``) of ``x`` with ``ranked_y``, already ranks, broadcast to
    ``x``'s shape; nan where a row is constant."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", stats.ConstantInputWarning)
        return stats.pearsonr(stats.rankdata(x, axis=-1), np.broadcast_to(ranked_y, x.shape), axis=-1).statistic


def paired_spearman_difference(world_a, world_b, trials, *, n_boot: int = 1000, level: float = 0.90,
                               seed: int = 0, resample_gaits: bool = True) -> dict:
    """How much better world A ranks the gaits than world B, with a paired bootstrap interval and test.

    The statistic is the mean over the draws of ρ_a − ρ_b, each ρ the Spearman correlation over the
    gaits of a world's mean fitness with the mean real fitness. Each bootstrap replicate resamples
    with replacement, as the experiment's design pairs them (Davison & Hinkley 1997, §3.8):

    * the **gaits** (the panel is a sample of the trust region; pairs (world, real) are resampled
      together, the standard bootstrap of a correlation, Efron & Tibshirani 1993, §6.5);
    * the **real trials**, the same indices for every gait (trial j of every gait ran on one seed);
    * each world's **episodes**, the same indices for every gait (episode seeds are shared by the
      gaits), and for both worlds when they have as many (and so the same seeds);

    and recomputes every draw's ρ from the resampled means. With ``resample_gaits=False`` the gaits
    stay the panel's: the interval then answers whether the difference on *this* panel is beyond the
    trial and episode noise, not whether it would hold on another panel drawn from the same region.
    The draws stay paired (draw d of both worlds was fitted on the same real data; a world without
    draws, such as the plain sim, is the same on every draw). The interval is the percentile interval of the replicates; the two-sided
    p-value is the smallest level at which that equal-tailed interval excludes 0,
    min(1, 2 min(P*(Δ* ≤ 0), P*(Δ* ≥ 0))) (Efron & Tibshirani 1993, §16.4's confidence-interval test);
    0 when every replicate lies on one side of 0 (p < 1/B, what B replicates can resolve).

    A caveat that decides which claims the test may carry: resampling adds noise to means that are
    already noisy, so a replicate's ρ is lower than the observed one, the more so the noisier the
    world's means. Between two worlds of like noise the replicates of Δ shrink toward 0 (the test is
    conservative); a stochastic world's replicates lose more than a deterministic world's (the plain
    sim, GAT), so against one the interval sits below the observed Δ: conservative for a claim that
    the stochastic world ranks better, not for one that it ranks worse. A bias-corrected interval
    (BC, ibid. §14.3) re-centres on the observed Δ, but where the observed Δ lies beyond nearly every
    replicate it stretches to the replicates' extreme; it is not used.

    Args:
        world_a, world_b: per-episode fitness of the two worlds, (D, G, E): D draws (D = 1: the same
            world on every draw), G gaits, E episodes per gait (1 for a deterministic world).
        trials: real fitness per trial (G, M), paired trials.
        n_boot: replicates; level: of the interval; seed: of the resampling.

    Returns:
        ``{"diff": observed mean of ρ_a − ρ_b over the draws, "per_draw": [ρ_a − ρ_b per draw],
        "ci": [lo, hi], "p_value", "n_boot": replicates with every ρ defined}``; nan figures when
        no replicate is defined (constant fitness).

    Raises:
        ValueError: shapes that do not match (gaits, draws other than 1 or the other's D), fewer than
            3 gaits, or n_boot < 1.
    """
    A, B, R = _paired_inputs(world_a, world_b, trials, n_boot)
    D = A.shape[0]
    real = R.mean(1)
    per_draw = [spearman(A[d].mean(1), real) - spearman(B[d].mean(1), real) for d in range(D)]
    diff = _replicate_differences(A, B, R, int(n_boot), seed, resample_gaits)
    obs = float(np.mean(per_draw))
    if not len(diff):
        return {"diff": obs, "per_draw": [float(x) for x in per_draw], "ci": [math.nan, math.nan],
                "p_value": math.nan, "n_boot": 0}
    a = (1 - level) / 2
    ci = [float(np.quantile(diff, a)), float(np.quantile(diff, 1 - a))]
    p = float(min(1.0, 2 * min(np.mean(diff <= 0), np.mean(diff >= 0))))  # 1 for the same world twice
    return {"diff": obs, "per_draw": [float(x) for x in per_draw], "ci": ci, "p_value": p, "n_boot": int(len(diff))}


def _paired_inputs(world_a, world_b, trials, n_boot) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`paired_spearman_difference`'s inputs as float arrays, both worlds broadcast to the same
    number of draws D: (D, G, E_a), (D, G, E_b) and the trials (G, M).

    Raises:
        ValueError: shapes that do not match (gaits, draws other than 1 or the other's D), fewer than
            3 gaits, or n_boot < 1.
    """
    A, B = (np.asarray(w, dtype=float) for w in (world_a, world_b))
    R = np.asarray(trials, dtype=float)
    if A.ndim != 3 or B.ndim != 3 or R.ndim != 2:
        raise ValueError(f"need worlds of shape (draws, gaits, episodes) and trials (gaits, trials), got "
                         f"{A.shape}, {B.shape}, {R.shape}")
    G = R.shape[0]
    if A.shape[1] != G or B.shape[1] != G:
        raise ValueError(f"the worlds have {A.shape[1]} and {B.shape[1]} gaits, the trials {G}")
    if G < 3:
        raise ValueError(f"need at least 3 gaits for a rank correlation, got {G}")
    D = max(A.shape[0], B.shape[0])
    if A.shape[0] not in (1, D) or B.shape[0] not in (1, D):
        raise ValueError(f"draws must match or be 1, got {A.shape[0]} and {B.shape[0]}")
    if int(n_boot) < 1:
        raise ValueError(f"n_boot must be >= 1, got {n_boot}")
    return np.broadcast_to(A, (D, *A.shape[1:])), np.broadcast_to(B, (D, *B.shape[1:])), R


def _replicate_differences(A: np.ndarray, B: np.ndarray, R: np.ndarray, n: int, seed: int,
                           resample_gaits: bool) -> np.ndarray:
    """The ``n`` bootstrap replicates of the mean over the draws of ρ_a − ρ_b (see
    :func:`paired_spearman_difference`), those with every ρ defined; |Δ| < 1e-12 set to 0.

    Args:
        A, B: per-episode fitness (D, G, E_a) and (D, G, E_b); R: real fitness per trial (G, M).
        n: replicates; seed: of the resampling; resample_gaits: resample the gaits too.
    """
    G, M = R.shape
    rng = np.random.default_rng(seed)
    gi = rng.integers(0, G, (n, G)) if resample_gaits else np.broadcast_to(np.arange(G), (n, G))
    ti = rng.integers(0, M, (n, M))
    ea = rng.integers(0, A.shape[2], (n, A.shape[2]))
    eb = ea if B.shape[2] == A.shape[2] else rng.integers(0, B.shape[2], (n, B.shape[2]))
    rr = stats.rankdata(R[gi[:, :, None], ti[:, None, :]].mean(-1), axis=-1)[:, None, :]  # (n, 1, G)

    def rho(W, ei):  # (n, D) ρ of every replicate and draw
        m = W[:, gi[:, :, None], ei[:, None, :]].mean(-1)  # (D, n, G)
        return _rho_rows(np.moveaxis(m, 0, 1), rr)

    diff = (rho(A, ea) - rho(B, eb)).mean(1)
    diff = diff[np.isfinite(diff)]
    # replicates where both worlds rank alike give 0 up to rounding: counted as 0 (on both sides of the test)
    diff[np.abs(diff) < 1e-12] = 0.0
    return diff


def brier_score(p, outcomes) -> float:
    """Mean squared difference between forecast probabilities and outcomes.

    Args:
        p: forecast probability per case (G,), in [0, 1].
        outcomes: 0/1 outcomes (G, M): M paired trials per case, each scored against its case's
            forecast.

    Raises:
        ValueError: shapes that do not match, or a probability outside [0, 1].
    """
    p = np.asarray(p, dtype=float)
    y = np.asarray(outcomes, dtype=float)
    if y.ndim != 2 or y.shape[0] != len(p):
        raise ValueError(f"outcomes must have shape ({len(p)}, M), got {y.shape}")
    if np.any((p < 0) | (p > 1)):
        raise ValueError("forecast probabilities must lie in [0, 1]")
    return float(np.mean((p[:, None] - y) ** 2))


def pick_regret(world, real) -> float:
    """What choosing by a training world costs in the real world: the real fitness of the panel's
    best gait minus that of the gait the world rates best (the mean real fitness of the gaits the
    world ties at the top). 0 when the world picks the real best; ``max - min`` of ``real`` at
    worst. A world can rank a panel well and still pick badly where it is most wrong in its own
    favour, which is where an optimizer in that world goes.

    Args:
        world: the world's fitness per gait (G,).
        real: the real fitness per gait (G,), e.g. the mean over paired trials.

    Raises:
        ValueError: shapes that differ, fewer than 2 gaits, or a non-finite value.
    """
    w = np.asarray(world, dtype=float)
    r = np.asarray(real, dtype=float)
    if w.shape != r.shape or w.ndim != 1 or len(w) < 2:
        raise ValueError(f"world and real must be two vectors of one length >= 2, got {w.shape} and {r.shape}")
    if not (np.all(np.isfinite(w)) and np.all(np.isfinite(r))):
        raise ValueError("pick_regret needs finite fitness values")
    top = w >= w.max() - 1e-12
    return float(r.max() - r[top].mean())


def split_half_reliability(trials, *, n_splits: int = 200, seed: int = 0) -> dict:
    """Reliability of per-case means over paired trials (G, M), M >= 2.

    Returns:
        ``{"split_half_rho": mean Spearman ρ of the two half-means over random splits,
        "reliability": its Spearman-Brown step-up 2ρ/(1+ρ) (the correlation two independent
        M-trial means would have), "ceiling": sqrt(reliability), clipped to [0, 1]}``.

    Raises:
        ValueError: fewer than 2 trials.
    """
    x = np.asarray(trials, dtype=float)
    if x.ndim != 2 or x.shape[1] < 2:
        raise ValueError(f"need (G, M >= 2) trials, got {x.shape}")
    rng = np.random.default_rng(seed)
    M = x.shape[1]
    rs = []
    for _ in range(n_splits):
        perm = rng.permutation(M)
        a, b = perm[: M // 2], perm[M // 2: 2 * (M // 2)]
        r = spearman(x[:, a].mean(1), x[:, b].mean(1))
        if math.isfinite(r):
            rs.append(r)
    r = float(np.mean(rs)) if rs else math.nan
    rel = 2 * r / (1 + r) if math.isfinite(r) and r > -1 else math.nan
    ceiling = math.sqrt(min(max(rel, 0.0), 1.0)) if math.isfinite(rel) else math.nan
    return {"split_half_rho": r, "reliability": rel, "ceiling": ceiling}


def paired_permutation_test(a, b, *, n_resamples: int = 20000, seed: int = 0) -> dict:
    """Two-sided paired permutation (sign-flip) test of mean(a - b) = 0.

    Returns:
        ``{"mean_diff", "se_diff", "p_value", "n"}``.

    Raises:
        ValueError: different lengths or fewer than 2 pairs.
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape or a.ndim != 1 or len(a) < 2:
        raise ValueError(f"need two equal-length vectors of >= 2 paired values, got {a.shape}, {b.shape}")
    d = a - b
    if np.all(d == 0):
        return {"mean_diff": 0.0, "se_diff": 0.0, "p_value": 1.0, "n": len(d)}
    res = stats.permutation_test((a, b), lambda x, y, axis: np.mean(x - y, axis=axis), permutation_type="samples",
                                 n_resamples=n_resamples, alternative="two-sided", random_state=seed, vectorized=True)
    return {"mean_diff": float(d.mean()), "se_diff": float(d.std(ddof=1) / math.sqrt(len(d))),
            "p_value": float(res.pvalue), "n": len(d)}


def mcnemar_test(x, y) -> dict:
    """McNemar's exact test that two paired binary outcomes (e.g. falls of two gaits on the same
    trial seeds) have the same rate.

    Returns:
        ``{"only_a": pairs where only ``x`` is 1, "only_b": where only ``y`` is 1, "p_value"}``
        (p = 1 without discordant pairs).

    Raises:
        ValueError: different lengths.
    """
    x, y = np.asarray(x, dtype=bool), np.asarray(y, dtype=bool)
    if x.shape != y.shape:
        raise ValueError(f"paired outcomes must have the same length, got {x.shape}, {y.shape}")
    b, c = int(np.sum(x & ~y)), int(np.sum(~x & y))
    p = 1.0 if b + c == 0 else float(stats.binomtest(b, b + c, 0.5).pvalue)
    return {"only_a": b, "only_b": c, "p_value": p}


def seed_level_test(per_seed_diff, confidence: float = 0.95) -> dict | None:
    """Is one method better than another, not only its gaits on these trials? A two-sided one-sample
    t-test of the per-optimization-seed mean fitness differences against 0, with its t-interval
    (``scipy.stats.ttest_1samp``; Student 1908). Each seed's difference carries both the spread between
    optimization runs and its own trial noise, so the interval is the one a new seed's run falls
    around; with 3 seeds it has 2 degrees of freedom (t = 4.30), so only large, consistent differences
    reach p < 0.05. Paired by seed: the methods of one seed share its real grounding walks.

    Args:
        per_seed_diff: mean fitness difference (a - b) per optimization seed, shape (k,).
        confidence: level of the interval (default 0.95).

    Returns:
        ``{"n_seeds", "mean_diff", "ci": [lo, hi], "t", "df", "p_value"}``, or None when the test is
        undefined: fewer than 2 seeds, or every seed's difference the same (no spread to test with).

    Raises:
        ValueError: a non-finite difference, or a level outside (0, 1).
    """
    d = np.asarray(per_seed_diff, dtype=float).ravel()
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    if not np.all(np.isfinite(d)):
        raise ValueError(f"per-seed differences must be finite, got {d.tolist()}")
    if len(d) < 2 or np.ptp(d) == 0:
        return None
    res = stats.ttest_1samp(d, 0.0)
    ci = res.confidence_interval(confidence)
    return {"n_seeds": len(d), "mean_diff": float(d.mean()), "ci": [float(ci.low), float(ci.high)],
            "t": float(res.statistic), "df": int(res.df), "p_value": float(res.pvalue)}


def paired_test(world_a, world_b, trials, *, n_boot: int = 1000, seed: int = 0) -> dict:
    """:func:`paired_spearman_difference` of two worlds' per-episode fitness
    ((D, G, E) each) on the real trials ``trials`` (G, M), for a new panel (``ci``, ``p_value``: the
    gaits resampled too) and for this panel (``ci_panel``, ``p_value_panel``: the gaits kept).

    Returns:
        ``{"diff", "per_draw", "ci", "p_value", "n_boot", "ci_panel", "p_value_panel"}``.
    """
    panel = paired_spearman_difference(world_a, world_b, trials, n_boot=n_boot, seed=seed, resample_gaits=False)
    return {**paired_spearman_difference(world_a, world_b, trials, n_boot=n_boot, seed=seed),
            "ci_panel": panel["ci"], "p_value_panel": panel["p_value"]}


def format_ci(ci) -> str:
    """A difference's interval as text, ``"[-0.12, +0.30]"``, or ``"-"`` where it is undefined."""
    return "-" if ci[0] is None or not math.isfinite(ci[0]) else f"[{ci[0]:+.2f}, {ci[1]:+.2f}]"


def p_text(p: float, n_boot: int) -> str:
    """A bootstrap p-value as text: ``"0.042"``, or ``"<0.001"`` for 0 (every one of ``n_boot``
    replicates on one side: p < 1/n_boot)."""
    if p is None or not math.isfinite(p):
        return "-"
    return f"<{1 / max(n_boot, 1):.2g}" if p == 0 else f"{p:.3f}"
