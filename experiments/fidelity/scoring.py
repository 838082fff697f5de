"""The scores of a fidelity run: how well each training world predicts the real world.

Per world and draw (:func:`draw_metrics`): Spearman ρ between world and real fitness over the gaits,
mean absolute error and bias (world − real), the Brier score of the world's fall frequency per gait
against the real falls, and the regret of its pick (``experiments.runtime.stats.pick_regret``); over
the draws, the median, range and spread of each (:func:`summary`). Whether one world ranks better
than another beyond the noise is a paired bootstrap test (:func:`paired_rows`). A stochastic world
is also scored from the first k of its episodes per gait (:func:`episode_counts`,
:func:`episodes_view`), and a panel with θ files on each group of gaits apart (:func:`group_rows`).
"""

from __future__ import annotations

import math

import numpy as np

from experiments.runtime.stats import brier_score, paired_test, pick_regret, spearman, split_half_reliability
from experiments.runtime.worlds import LEARNED, WorldSpec, parse_world


def recording_summary(path: str) -> tuple[float, bool]:
    """A recording's length [s] and whether the robot fell in it (``meta["fell"]``)."""
    from envs import Recording  # lazy: loads the engines

    rec = Recording.from_parquet(path)
    return float(len(rec) * rec.meta["control_dt"]), bool(rec.meta.get("fell", False))


def replay_summary(rows: list[dict]) -> dict:
    """Teacher-forced replays of one draw's grounding walks: counts of falls (``fell_with_real``: the
    sim fell on a walk that fell for real; ``fell_without_real``: on one that did not) and the median
    RMS error of the leg joint angles against the real walks [rad], forced and ungrounded."""
    real = np.array([r["real_fell"] for r in rows], dtype=bool)
    sim = np.array([r["fell"] for r in rows], dtype=bool)
    return {"walks": len(rows), "real_fell": int(real.sum()), "fell": int(sim.sum()),
            "fell_with_real": int((sim & real).sum()), "fell_without_real": int((sim & ~real).sum()),
            "q_rms_rad": float(np.median([r["q_rms_rad"] for r in rows])),
            "q_rms_plain_rad": float(np.median([r["q_rms_plain_rad"] for r in rows]))}


def replay_totals(replays: list[dict]) -> dict:
    """A world's teacher-forced replays (one :func:`_replay_summary` per draw) over all its draws:
    walks, real falls, the sim's falls on walks that fell and on those that did not (sums), and the
    median over the draws of the leg-joint RMS errors [rad], forced and ungrounded."""
    return {k: sum(r[k] for r in replays) for k in ("walks", "real_fell", "fell_with_real", "fell_without_real")} | {
        k: float(np.median([r[k] for r in replays])) for k in ("q_rms_rad", "q_rms_plain_rad")}


def episode_counts(n: int) -> list[int]:
    """The episode counts per gait a world of ``n`` episodes is also scored at (``by_episodes`` of a
    fidelity result): 1, 2, 4, ... below ``n``, and ``n``; none for a single episode."""
    return [] if n < 2 else sorted({2 ** i for i in range(n.bit_length()) if 2 ** i < n} | {n})


def draw_metrics(wf: np.ndarray, wp: np.ndarray, real_fit: np.ndarray, real_falls: np.ndarray) -> dict:
    """One draw of a world against the real trials: Spearman ρ, MAE and bias (world − real) of the
    fitness, the Brier score of its fall frequencies ``wp`` (G,) against the real falls (G, M), and
    the regret of its pick (``experiments.runtime.stats``)."""
    return {"rho": spearman(wf, real_fit), "mae": float(np.mean(np.abs(wf - real_fit))),
            "bias": float(np.mean(wf - real_fit)), "brier": brier_score(wp, real_falls),
            "pick_regret": pick_regret(wf, real_fit)}


def episodes_view(res: dict, k: int) -> dict:
    """A fidelity result as it would read with ``k`` episodes per gait in every stochastic world: each
    world that has ``by_episodes[k]`` gets those draws and summary (the first k of its episodes, on the
    same seeds as a run with ``--episodes k``); deterministic worlds keep theirs; worlds measured with
    fewer than ``k`` episodes are left out.

    Raises:
        ValueError: ``k`` < 1.
    """
    if k < 1:
        raise ValueError(f"episodes per gait must be >= 1, got {k}")
    worlds = {}
    for name, w in res["worlds"].items():
        cur = (w.get("by_episodes") or {}).get(str(k))
        if cur is not None:
            worlds[name] = {**w, "episodes": k, "draws": cur["draws"], "summary": cur["summary"]}
        elif w.get("episodes") == 1 and w.get("deterministic", w.get("kind") in ("sim", "gat")):  # one episode is its answer
            worlds[name] = w
        elif k == w.get("episodes"):  # a world measured with k episodes, in a run saved before by_episodes
            worlds[name] = w
    return {**res, "worlds": worlds}


def over_draws(values) -> dict:
    """``{"median", "min", "max", "spread"}`` of one figure over the draws, its non-finite values left
    out (all NaN where none is finite)."""
    v = np.asarray(values, dtype=float)
    ok = v[np.isfinite(v)]
    if not len(ok):
        return {"median": math.nan, "min": math.nan, "max": math.nan, "spread": math.nan}
    return {"median": float(np.median(ok)), "min": float(ok.min()), "max": float(ok.max()),
            "spread": float(ok.max() - ok.min())}


def range_text(s: dict | None, fmt: str = "{:.2f}") -> str:
    """A figure over the draws as text: 'median [min, max]' ('-' for None)."""
    return "-" if s is None else f"{fmt.format(s['median'])} [{fmt.format(s['min'])}, {fmt.format(s['max'])}]"


def summary(draws: list[dict]) -> dict:
    def agg(key):
        return over_draws([d[key] for d in draws])
    s = {k: agg(k) for k in ("rho", "mae", "bias", "brier")}
    if all("pick_regret" in d for d in draws):  # runs saved before it have none
        s["pick_regret"] = agg("pick_regret")
    if all(d.get("world_ceiling") is not None for d in draws):  # stochastic worlds of runs that measured it
        s["world_ceiling"] = agg("world_ceiling")
    s["abs_bias_median"] = float(np.median(np.abs([d["bias"] for d in draws])))
    s["draws"] = len(draws)
    return s


def first_world(res: dict, kind: str) -> str | None:
    """The first world of ``kind`` that a fidelity result lists (its reference world of that kind:
    the others are variants), or None."""
    return next((n for n, w in res["worlds"].items() if w.get("kind", n.split(":")[0]) == kind), None)


def world_pairs(names: list[str]) -> list[tuple[str, str]]:
    """The pairs (world, reference) that :func:`paired_rows` compares, in the worlds' order: every
    world against the plain ``sim`` (does it rank better than the sim it starts from?); a world with
    options against its plain kind (``hybrid:alpha=0.3`` against ``hybrid``); ``sgat`` − ``gat``,
    ``hybrid`` − ``identified`` and ``hybrid`` − ``sgat`` where the run has both; any two worlds of one
    kind one setting apart, the later against the earlier (``hybrid:alpha=0.3:delay=auto`` against
    ``hybrid:alpha=0.3``); and where the run has the real world itself (``real``, on fresh seeds, as
    many episodes per gait) every world that learns from real data or adds noise against it: does the
    world rank the gaits measurably worse than the real world would as a training world?"""
    specs = {n: parse_world(n) for n in names}
    pairs = []
    for n in names:
        if n != "sim" and "sim" in names:
            pairs.append((n, "sim"))
        base = specs[n].kind
        if n != base and base in names and base != "sim":
            pairs.append((n, base))
    pairs += [p for p in (("sgat", "gat"), ("hybrid", "identified"), ("hybrid", "sgat")) if p[0] in names and p[1] in names]
    pairs += [(a, b) for i, a in enumerate(names) for b in names[:i] if _settings_apart(specs[a], specs[b]) == 1]
    if "real" in names:  # every learned world against the real world itself
        pairs += [(n, "real") for n in names if specs[n].kind in LEARNED]
    return list(dict.fromkeys(pairs))


def _settings_apart(a: WorldSpec, b: WorldSpec) -> int:
    """How many options two worlds of one kind differ in; a large number for worlds of different kinds."""
    if a.kind != b.kind:
        return 1 << 30
    da, db = dict(a.options), dict(b.options)
    return sum(da.get(k) != db.get(k) for k in set(da) | set(db))


def paired_rows(res: dict, *, n_boot: int = 1000, seed: int = 0) -> list[dict]:
    """Paired comparisons of the worlds' rankings (:func:`world_pairs`): per pair, the mean over the
    draws of ρ_world − ρ_reference with a 90 % interval and a two-sided p-value from a bootstrap over
    the gaits, the real trials and the episodes (:func:`experiments.runtime.stats.paired_spearman_difference`).
    The worlds' draws are paired: draw d of every world learns from the same real data. The bootstrap's
    replicates rank worse than the observed worlds, a stochastic world's more than a deterministic
    one's: the test is conservative for a claim that a stochastic world ranks better than the plain
    sim, not for one that it ranks worse (``paired_spearman_difference``'s caveat).

    ``ci_panel`` and ``p_value_panel``: the same with the panel's gaits kept (the trials and episodes
    resampled only): is the difference beyond the noise on this panel? ``ci`` and ``p_value`` also
    resample the gaits: would it hold on another panel of as many gaits from the same region?

    Returns:
        ``[{"world", "reference", "diff", "per_draw", "ci", "p_value", "n_boot", "ci_panel",
        "p_value_panel"}]``.
    """
    trials = res["real"].get("fitness_trials")
    worlds = res["worlds"]
    if trials is None or not all("fitness_episodes" in d for w in worlds.values() for d in w["draws"]):
        return []
    eps = {n: np.array([d["fitness_episodes"] for d in w["draws"]]) for n, w in worlds.items()}
    return [{"world": a, "reference": b, **paired_test(eps[a], eps[b], trials, n_boot=n_boot, seed=seed)}
            for a, b in world_pairs(list(worlds))]


#: Fewest gaits of a group that :func:`group_rows` gives a Spearman ρ (a rank correlation over a
#: handful of gaits says little).
GROUP_MIN_RANK = 8


def gait_groups(res: dict) -> dict[str, list[int]]:
    """The groups of a fidelity panel that has θ files (``--params``): ``drawn`` (θ0 and the gaits
    drawn in the trust region), ``given`` (the θ files) and, where the files have more than one
    name, one group per file name (the last part of the gait's name: ``hybrid_step2`` holds every
    Table I seed's ``opt_seed<k>/thetas/hybrid_step2``).

    Returns:
        ``{group: [indices into res["gaits"]]}`` in that order; empty for a panel without θ files.
    """
    n_given = len(res.get("config", {}).get("params") or [])
    if not n_given:
        return {}
    n = len(res["gaits"])
    given = list(range(n - n_given, n))
    out = {"drawn": list(range(n - n_given)), "given": given}
    by_name: dict[str, list[int]] = {}
    for i in given:
        by_name.setdefault(res["gaits"][i].rsplit("/", 1)[-1], []).append(i)
    if len(by_name) > 1:
        out.update({f"given: {k}": v for k, v in by_name.items()})
    return out


def group_rows(res: dict) -> list[dict]:
    """Each world on each gait group of :func:`gait_groups` (gaits optimized in a training world
    apart from those drawn around θ0: what the world promised for them against what they did).

    Per group and world, over the draws (median [min, max]): the world's mean fitness over the
    group's gaits, its bias (world − real, mean over the gaits) and mean absolute error, the Spearman
    ρ within the group
    and the regret of the world's pick within the group (:func:`experiments.runtime.stats.pick_regret`: the
    real fitness lost by taking the gait the world rates best instead of the group's real best). ρ
    only for groups of at least :data:`GROUP_MIN_RANK` gaits, with the group's ceiling of ρ from the
    real trials' noise (:func:`experiments.runtime.stats.split_half_reliability`). The group's real mean
    fitness (with its standard error over the paired trials) and fall rate come with it.

    Returns:
        ``[{"group", "gaits", "real_fitness", "real_fitness_se", "real_ceiling", "real_falls",
        "world", "fitness", "bias", "mae", "rho", "pick_regret"}]``, each figure of the world a
        ``{"median", "min", "max", "spread"}`` (``rho`` and ``real_ceiling`` None for a small group);
        empty without θ files.
    """
    groups = gait_groups(res)
    if not groups:
        return []
    real_fit = np.asarray(res["real"]["fitness"], dtype=float)
    trials = res["real"].get("fitness_trials")
    falls = np.asarray(res["real"]["fall_rate"], dtype=float)
    seed = int(res["config"].get("seed", 0))
    rows = []
    for group, idx in groups.items():
        ix = np.asarray(idx)
        real = {"group": group, "gaits": len(ix), "real_fitness": float(real_fit[ix].mean()),
                "real_fitness_se": (float(np.std(np.asarray(trials)[ix].mean(0), ddof=1) / math.sqrt(len(trials[0])))
                                    if trials else None),
                "real_ceiling": (split_half_reliability(np.asarray(trials)[ix], seed=seed)["ceiling"]
                                 if trials and len(ix) >= GROUP_MIN_RANK else None),
                "real_falls": float(falls[ix].mean())}
        for name, w in res["worlds"].items():
            fit, bias, mae, rho, regret = [], [], [], [], []
            for d in w["draws"]:
                wf = np.asarray(d["fitness"], dtype=float)[ix]
                fit.append(wf.mean())
                bias.append(float(np.mean(wf - real_fit[ix])))
                mae.append(float(np.mean(np.abs(wf - real_fit[ix]))))
                if len(ix) >= GROUP_MIN_RANK:
                    rho.append(spearman(wf, real_fit[ix]))
                if len(ix) >= 2:
                    regret.append(pick_regret(wf, real_fit[ix]))
            rows.append({**real, "world": name, "fitness": over_draws(fit), "bias": over_draws(bias),
                         "mae": over_draws(mae), "rho": over_draws(rho) if rho else None,
                         "pick_regret": over_draws(regret) if regret else None})
    return rows


def episodes_rows(res: dict) -> list[dict]:
    """Fidelity against the number of episodes per gait, one row per stochastic world and count k of
    ``by_episodes`` (1, 2, 4, ... and the run's own): worst and median ρ over the draws, median
    |bias|, bias spread and median Brier score."""
    rows = []
    for name, w in res["worlds"].items():
        for k in sorted(int(k) for k in (w.get("by_episodes") or {})):
            s = w["by_episodes"][str(k)]["summary"]
            rows.append({"world": name, "episodes": k, "rho_worst": s["rho"]["min"], "rho_median": s["rho"]["median"],
                         "abs_bias_median": s["abs_bias_median"], "bias_spread": s["bias"]["spread"],
                         "brier_median": s["brier"]["median"]})
    return rows

