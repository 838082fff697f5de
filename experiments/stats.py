"""Statistics the experiments report: intervals, rank agreement, calibration and paired tests.

Everything here is a thin, documented layer over ``scipy.stats``:

* :func:`wilson_interval` -- Wilson's score interval of a proportion (E. B. Wilson, JASA 1927;
  ``scipy.stats.binomtest(...).proportion_ci(method="wilson")``).
* :func:`spearman` and :func:`bootstrap_spearman` -- Spearman's rank correlation
  (``scipy.stats.spearmanr``) and its percentile bootstrap interval over paired real trials
  (Efron & Tibshirani 1993, ch. 13).
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
