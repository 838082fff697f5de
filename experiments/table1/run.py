"""The paper's Table I with power (``sgatwalk table1``): several optimization seeds per method,
every resulting gait scored on the same paired real trials, and paired tests between methods.

1. For each optimization seed s = 0 .. ``seeds`` - 1: one ``sgatwalk optimize`` run with all
   ``methods`` (``experiments.optimize.run``, default settings; methods share the run's real grounding
   walks, as in ``optimize --methods``), without its own real evaluation, in ``opt_seed<s>/``.
2. Every gait -- θ0 and each (method, grounding step, seed) -- walks the same ``trials`` real trial
   seeds (one list for the whole table: every comparison is paired by trial, and across methods also
   by optimization seed).
3. Per (method, step), pooled over seeds: speed mean ± s.e. [cm/s], falls with a Wilson 95 %
   interval, fitness mean ± s.e.; per seed too; and the fitness the training world itself gave the
   gait it chose (the optimizer's selection score): how much a method's world flattered its choice. Paired tests at each step (``experiments.runtime.stats``):
   a permutation test on fitness and McNemar's exact test on falls, pairs = (seed, trial); for
   SGAT vs GAT, SGAT vs none, hybrid vs SGAT, hybrid vs ANE (does the real data beat plain action noise?),
   hybrid vs identified (does the learned grounding add to the identified physics under it?), and every
   method vs θ0; a method trained with the action-noise envelope on top of its grounding
   (``sgat+ane``, ``hybrid+ane``, ...: ``experiments.optimize.run``) also against its base method (what
   the noise adds) and against ANE (what the grounding adds to the noise).

The result keeps every gait's real trials (``trials``: fitness and falls per trial seed), so a later
run on the same trial seeds can be paired with it trial by trial: with ``baseline`` (an earlier
run's ``table1.json``, e.g. another grounding setting) every (method, step) both runs have is tested
against the baseline's gait of the same optimization seed on the same trials, and a method the
baseline lacks against each of the baseline's methods (:func:`compare_runs`). Everything resumes: the
optimization runs from their checkpoints, the evaluation from ``episodes.jsonl``; given more
methods, a finished run adds them to every seed's optimization run (its real grounding walks and
identification reused) and walks only the new gaits.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

from common.defaults import EPISODE_SECONDS
from common.files import WallClock, atomic_write_text, jsonable
from experiments.runtime.progress import Reporter
from experiments.runtime.rundir import EpisodeLog
from experiments.runtime.seeds import derive_seeds
from experiments.runtime.stats import mcnemar_test, paired_permutation_test, seed_level_test, wilson_interval
from experiments.runtime.tasks import EpisodeTask
from experiments.runtime.worlds import parse_world
from experiments.table1.config import EVAL, Table1Config

#: Comparisons tested at every grounding step (a, b): "a vs b" (and :func:`comparisons` adds those of
#: worlds with the action-noise envelope on top).
COMPARISONS = (("sgat", "gat"), ("sgat", "sim"), ("hybrid", "sgat"), ("hybrid", "ane"), ("hybrid", "identified"),
               ("sgat", "real"), ("gat", "real"), ("hybrid", "real"))


def noise_partners(method: str) -> tuple:
    """What a grounded or identified world with the action-noise envelope on top (``sgat:ane=0.05``) is
    tested against besides itself: ``(the world without it, "ane")`` -- what the noise adds to the
    grounding, what the grounding adds to the noise; ``()`` for any other method."""
    spec = parse_world(method)
    return (spec.without("ane").name, "ane") if spec.kind != "ane" and spec.noise else ()


def comparisons(methods) -> list[tuple[str, str]]:
    """The (a, b) pairs tested between ``methods``: :data:`COMPARISONS`, then ``(m, b)`` for every
    ``b`` of :func:`noise_partners` of each method ``m``; only pairs of methods run."""
    pairs = list(COMPARISONS) + [(m, b) for m in methods for b in noise_partners(m)]
    return [(a, b) for a, b in pairs if a in methods and b in methods]




def _slug(method: str) -> str:
    """A training world's name as a folder name (``experiments.optimize.slug``)."""
    from experiments.optimize import slug

    return slug(method)


def last_step_gait(table1_dir: str, method: str, seed: int) -> tuple[int, list, str]:
    """The last grounding step's gait of ``method`` at optimization seed ``seed`` in a Table I run.

    Returns:
        (step, θ in SI units, the directory of that step's saved action transformer: the training
        world the gait was optimized in is the sim grounded by it).

    Raises:
        ValueError: the run holds no optimized gait of the method, or the method is not grounded.
    """
    opt = os.path.join(table1_dir, f"opt_seed{seed}", _slug(method))
    with open(os.path.join(opt, "results.json")) as f:
        rows = [r for r in json.load(f)["rows"] if r["method"] == method and r.get("theta")]
    if not rows:
        raise ValueError(f"{opt} holds no optimized gait of {method}")
    row = max(rows, key=lambda r: r["step"])
    model = os.path.join(opt, "models", f"{_slug(method)}_step{row['step']}")
    if not os.path.isdir(model):
        raise ValueError(f"{method} seed {seed}: no action transformer at {model} (a grounded method only)")
    return int(row["step"]), list(row["theta"]), model


def _identify_job(job, executor) -> dict:
    """One optimization seed's identification of the real world (an executor job)."""
    from experiments.optimize import identify  # lazy: loads the engines
    from experiments.runtime.progress import Reporter

    root, seed, profile, stochasticity, verbose = job
    return identify(root, seed=seed, profile=profile, stochasticity=stochasticity,
                    reporter=Reporter(f"identify seed {seed}") if verbose else Reporter.quiet())


def _optimize_job(job, executor):
    """One method's optimization on one seed (an executor job): ``sgatwalk optimize`` without real
    trials, resumed where it stopped; its episodes on ``executor``."""
    from experiments.optimize import OptimizeConfig, Optimizer  # lazy: loads the engines and torch
    from experiments.runtime.progress import Reporter

    settings, run_dir, identification, verbose = job
    cfg = OptimizeConfig(**settings)
    reporter = Reporter(f"{cfg.methods[0]} seed {cfg.seed}") if verbose else Reporter.quiet()
    opt = Optimizer(cfg, run_dir, executor, reporter=reporter,
                    identification=identification)
    return opt.run(resume=os.path.exists(opt.state_path))


class Table1:
    """Runs (or resumes) a Table I run in ``run_dir`` with ``executor``."""

    def __init__(self, cfg: Table1Config, run_dir: str, executor, *, reporter: Reporter | None = None):
        cfg.validate()
        if cfg.baseline is not None:
            load_baseline(cfg.baseline, cfg)
        # absolute: the optimization jobs write under it, and a Ray worker may run elsewhere
        self.cfg, self.run_dir, self.ex = cfg, os.path.abspath(run_dir), executor
        self.report = reporter or Reporter.quiet()
        self._episodes: dict[str, dict] = {}

    def _say(self, msg: str) -> None:
        self.report.say(msg)

    def _check_config(self) -> None:
        """Claim the run directory (``experiments.runtime.rundir.EpisodeLog``); more seeds or methods reuse what was done."""
        self._log = EpisodeLog(self.run_dir, self.cfg.to_dict(), "Table I run", ignore=self.cfg.RESUMABLE,
                               reporter=self.report)
        self._episodes = self._log.done

    def _optimizations(self) -> list:
        """Every (method, optimization seed) optimization, as independent jobs (side by side on a Ray
        cluster; in order on this machine): first the real world's identification of each seed that a
        method building on it needs (the seed's methods share it), then one ``sgatwalk optimize`` run
        per method and seed without its own real trials, in ``opt_seed<s>/<method>/`` (each resumed where
        it stopped). The results are those of one run of every method per seed: every draw is keyed by
        (seed, purpose), not by the method.

        Returns:
            ``[(method, seed, experiments.optimize.OptimizeResult)]``.
        """
        from experiments.runtime.worlds import parse_world

        cfg = self.cfg
        seeds = list(range(cfg.seeds))
        verbose = self.report.stream is not None
        ident = {}
        if any(parse_world(m).needs_identification for m in cfg.methods):
            self._say(f"identifying the real world for {len(seeds)} optimization seed(s)")
            jobs = [(os.path.join(self.run_dir, f"opt_seed{s}", "identified"), s, cfg.optimize.get("profile", "real"),
                     cfg.optimize.get("stochasticity", 0.0), verbose) for s in seeds]
            ident = dict(zip(seeds, self.ex.jobs(_identify_job, jobs, [f"identification seed {s}" for s in seeds],
                                                 self.report)))
        runs = [(m, s) for s in seeds for m in cfg.methods]
        jobs = [({**cfg.optimize, "methods": (m,), "seed": s, "eval_trials": 0},
                 os.path.join(self.run_dir, f"opt_seed{s}", _slug(m)), ident.get(s) if parse_world(m).needs_identification
                 else None, verbose) for m, s in runs]
        self._say(f"{len(jobs)} optimizations (methods x seeds)")
        results = self.ex.jobs(_optimize_job, jobs, [f"{m} seed {s}" for m, s in runs], self.report)
        return [(m, s, r) for (m, s), r in zip(runs, results)]

    def run(self) -> dict:
        cfg = self.cfg
        self._check_config()
        clock = WallClock(self.run_dir, legacy=os.path.join(self.run_dir, "table1.json"))
        gaits: dict[str, list] = {}
        predicted: dict[str, float] = {}  # the training world's fitness of each selected gait
        real_data: dict = {}
        for m, s, res in self._optimizations():
            real_data.setdefault(s, {}).update(res.real_data)
            gaits.setdefault("theta0", res.theta0)
            for r in res.rows:
                if r.method == m:
                    gaits[f"{r.method}|{r.step}|{s}"] = r.theta
                    if r.select_scores:
                        predicted[f"{r.method}|{r.step}|{s}"] = max(r.select_scores.values())
        seeds = derive_seeds(cfg.seed, EVAL, n=cfg.trials)
        prof = cfg.optimize.get("profile", "real")
        secs = cfg.optimize.get("seconds", EPISODE_SECONDS)
        robot = cfg.optimize.get("robot", "nao")
        level = cfg.optimize.get("stochasticity", 0.0)
        tasks = [EpisodeTask("real", th, sd, secs, robot=robot, profile=prof, stochasticity=level, key=f"{g}|t{j}")
                 for g, th in gaits.items() for j, sd in enumerate(seeds)]
        self._say(f"real evaluation: {len(gaits)} gaits x {cfg.trials} paired trials")
        self._log.run(self.ex, tasks, "real evaluation", self.report)
        out = self.result(gaits, real_data, predicted)
        if cfg.baseline is not None:
            out["baseline"] = {"path": cfg.baseline, "command": load_baseline(cfg.baseline, cfg).get("command"),
                               "tests": compare_runs(out, load_baseline(cfg.baseline, cfg), seed=cfg.seed)}
            out["verdict"] += baseline_verdict(out["baseline"]["tests"])
        out["wall_s"] = clock.save()
        atomic_write_text(os.path.join(self.run_dir, "table1.json"), json.dumps(jsonable(out), indent=1))
        atomic_write_text(os.path.join(self.run_dir, "table.txt"), format_table(out) + "\n")
        return out

    def _vec(self, gait: str, what: str) -> np.ndarray:
        return np.array([float(self._episodes[f"{gait}|t{j}"][what]) for j in range(self.cfg.trials)])

    def result(self, gaits: dict, real_data: dict, predicted: dict | None = None) -> dict:
        cfg = self.cfg
        steps = sorted({int(g.split("|")[1]) for g in gaits if g != "theta0"})

        def pooled(keys):
            fit = np.concatenate([self._vec(k, "fitness") for k in keys])
            spd = np.concatenate([self._vec(k, "speed_cm_s") for k in keys])
            fell = np.concatenate([self._vec(k, "fell") for k in keys]).astype(bool)
            n = len(fit)
            return {"n": n, "speed_mean": float(spd.mean()), "speed_se": float(spd.std(ddof=1) / math.sqrt(n)),
                    "falls": int(fell.sum()), "falls_ci95": list(wilson_interval(int(fell.sum()), n)),
                    "fitness_mean": float(fit.mean()), "fitness_se": float(fit.std(ddof=1) / math.sqrt(n))}

        rows = [{"method": "theta0", "step": 0, **pooled(["theta0"]), "per_seed": []}]
        for m in cfg.methods:
            for st in steps:
                keys = [f"{m}|{st}|{s}" for s in range(cfg.seeds)]
                per = [{"seed": s, **pooled([k]), "predicted_fitness": (predicted or {}).get(k)}
                       for s, k in enumerate(keys)]
                pred = [p["predicted_fitness"] for p in per if p["predicted_fitness"] is not None]
                rows.append({"method": m, "step": st, **pooled(keys), "per_seed": per,
                             "predicted_fitness": float(np.mean(pred)) if pred else None})
        tests = []

        def paired(a_keys, b_keys):
            fa = np.concatenate([self._vec(k, "fitness") for k in a_keys])
            fb = np.concatenate([self._vec(k, "fitness") for k in b_keys])
            xa = np.concatenate([self._vec(k, "fell") for k in a_keys])
            xb = np.concatenate([self._vec(k, "fell") for k in b_keys])
            # the mean difference per optimization seed: the tests pair trials, so they say whether these
            # gaits differ; whether the methods do rests on how many seeds agree
            per = [float(np.mean(self._vec(ka, "fitness") - self._vec(kb, "fitness"))) for ka, kb in zip(a_keys, b_keys)]
            return {"fitness": paired_permutation_test(fa, fb, seed=cfg.seed), "falls": mcnemar_test(xa, xb),
                    "per_seed_diff": per, "seed_level": seed_level_test(per)}

        for st in steps:
            for a, b in comparisons(cfg.methods):
                tests.append({"step": st, "a": a, "b": b, **paired([f"{a}|{st}|{s}" for s in range(cfg.seeds)],
                                                                   [f"{b}|{st}|{s}" for s in range(cfg.seeds)])})
            for m in cfg.methods:
                tests.append({"step": st, "a": m, "b": "theta0", **paired([f"{m}|{st}|{s}" for s in range(cfg.seeds)],
                                                                          ["theta0"] * cfg.seeds)})
        # every gait's real trials (index j = trial seed j of the table), so a later run on the same trial
        # seeds can be paired with this one trial by trial
        trials = {g: {"fitness": [round(float(x), 4) for x in self._vec(g, "fitness")],
                      "fell": [int(x) for x in self._vec(g, "fell")]} for g in ["theta0", *sorted(set(gaits) - {"theta0"})]}
        return {"config": cfg.to_dict(), "rows": rows, "tests": tests, "real_data": real_data,
                "verdict": verdict(rows, tests), "trials": trials}


def load_baseline(path: str, cfg: Table1Config) -> dict:
    """An earlier Table I result (``table1.json``, or a README result file holding one under ``result``)
    that can be paired with a run of ``cfg``: the same real trial seeds (``seed``, ``trials``) and
    per-trial results (``trials``).

    Raises:
        FileNotFoundError: no such file. ValueError: not a Table I result, without per-trial results,
            or on other trial seeds (named).
    """
    with open(path) as f:
        try:
            doc = json.load(f)
        except json.JSONDecodeError as exc:
            raise ValueError(f"baseline {path!r} is not JSON: {exc}") from None
    res = doc.get("result", doc) if isinstance(doc, dict) else None
    if not isinstance(res, dict) or "rows" not in res or "config" not in res:
        raise ValueError(f"baseline {path!r} is not a Table I result (table1.json)")
    if "trials" not in res:
        raise ValueError(f"baseline {path!r} has no per-trial results (made before table1.json kept them)")
    bc = res["config"]
    if (bc.get("seed"), bc.get("trials")) != (cfg.seed, cfg.trials):
        raise ValueError(f"baseline {path!r} ran other real trials (seed {bc.get('seed')}, {bc.get('trials')} trials; "
                         f"this run: seed {cfg.seed}, {cfg.trials}): its rows cannot be paired with this run's")
    return {**res, "command": doc.get("command")}


def compare_runs(res: dict, base: dict, *, seed: int = 0) -> list[dict]:
    """Paired tests of this run's rows against a baseline run's (:func:`load_baseline`): for every
    (method, step) both runs have, the gaits of the optimization seeds both ran, each walked on the
    same real trial seeds; pairs = (seed, trial). A method of this run that the baseline lacks (a
    hybrid-only run against an SGAT-only one) is compared with each of the baseline's methods at the
    same step and seed instead (``baseline_method``); a method the baseline has also with the
    baseline's methods that :func:`comparisons` tests it against within a run (a ``<base>+ane`` method
    with its base and ANE, hybrid with SGAT and ANE: e.g. another noise level, or another numerical
    setting of the hybrid world, against the baseline's). ``mean_diff`` > 0: this run's gaits are fitter.

    Returns:
        ``[{"method", "step", "seeds", "fitness": permutation test, "falls": McNemar, "per_seed_diff":
        this run's mean fitness minus the baseline's per seed, "seed_level": the t-test over those
        (:func:`experiments.runtime.stats.seed_level_test`)}]``, with
        ``"baseline_method"`` where the baseline's method differs; θ0 is checked, not tested: the
        same gait on the same trials must give the same results.

    Raises:
        ValueError: θ0's real trials differ between the runs (not the same trials after all).
    """
    a, b = res["trials"], base["trials"]
    if a["theta0"] != b["theta0"]:
        raise ValueError("θ0's real trials differ from the baseline's: the runs did not walk the same trials")

    def parse(k: str) -> tuple[str, int, int]:
        m, st, s = k.split("|")
        return m, int(st), int(s)

    b_methods = sorted({parse(k)[0] for k in b if k != "theta0"})
    groups: dict[tuple, list[tuple[str, str]]] = {}
    for k in sorted((k for k in a if k != "theta0"), key=parse):
        m, st, s = parse(k)
        for mb in _baseline_partners(m, b_methods):
            if f"{mb}|{st}|{s}" in b:
                groups.setdefault((m, mb, st), []).append((k, f"{mb}|{st}|{s}"))
    out = []
    for (m, mb, st), pairs in groups.items():
        fa = np.concatenate([a[ka]["fitness"] for ka, _ in pairs])
        fb = np.concatenate([b[kb]["fitness"] for _, kb in pairs])
        xa = np.concatenate([a[ka]["fell"] for ka, _ in pairs])
        xb = np.concatenate([b[kb]["fell"] for _, kb in pairs])
        per = [float(np.mean(np.subtract(a[ka]["fitness"], b[kb]["fitness"]))) for ka, kb in pairs]
        out.append({"method": m, "step": st, "seeds": [parse(ka)[2] for ka, _ in pairs],
                    **({"baseline_method": mb} if mb != m else {}),
                    "fitness": paired_permutation_test(fa, fb, seed=seed), "falls": mcnemar_test(xa, xb),
                    "per_seed_diff": per, "seed_level": seed_level_test(per)})
    return out


def _baseline_partners(m: str, b_methods: list[str]) -> list[str]:
    """The baseline's methods a method ``m`` of this run is tested against (:func:`compare_runs`): its
    own, then those a run tests it against (:func:`comparisons`: e.g. hybrid against SGAT and ANE, a
    ``<base>+ane`` method against its base and ANE); every baseline method when it lacks ``m``."""
    if m not in b_methods:
        return list(b_methods)
    own = [b for a, b in comparisons([m, *b_methods]) if a == m]
    return list(dict.fromkeys([m, *own]))


def baseline_verdict(tests: list[dict], alpha: float = 0.05) -> list[str]:
    """One sentence per (method, step) compared with the baseline run."""
    out = []
    for t in tests:
        f, x = t["fitness"], t["falls"]
        name = f"step {t['step']}: {t['method'].upper()} of this run"
        theirs = f"the baseline's {t['baseline_method'].upper()}" if t.get("baseline_method") else "the baseline's"
        agree = seed_agreement(t, "this run's", theirs)
        if f["p_value"] < alpha:
            out.append(f"{name} {'beats' if f['mean_diff'] > 0 else 'is worse than'} {theirs} on fitness by "
                       f"{f['mean_diff']:+.1f} (paired permutation p = {f['p_value']:.3g}; falls {x['only_a']} vs "
                       f"{x['only_b']} discordant, McNemar p = {x['p_value']:.3g}{agree})")
        else:
            out.append(f"{name}: no significant difference from {theirs} (fitness {f['mean_diff']:+.1f} ± "
                       f"{f['se_diff']:.1f}, p = {f['p_value']:.2g}; McNemar p = {x['p_value']:.2g}{agree})")
    return out


def seed_agreement(test: dict, a: str | None = None, b: str | None = None) -> str:
    """``"; A fitter on k of n optimization seeds"`` for a test whose per-seed differences were kept
    (``per_seed_diff``, more than one seed), in the direction of its mean difference; else ``""``.
    ``a``, ``b``: the names of the two sides (default the test's ``a`` and ``b`` in capitals).
    The permutation test pairs trials, so it tells whether these gaits differ; a method-level claim
    also needs the seeds to agree (with 3 seeds a sign-flip test over seeds cannot go below p = 0.25),
    so the t-test over seeds follows where the test kept one (``seed_level``: its 95 % interval is
    where the difference of another seed's runs would lie around)."""
    per = test.get("per_seed_diff") or []
    if len(per) < 2:
        return ""
    up = test["fitness"]["mean_diff"] >= 0
    k = sum((d > 0) if up else (d < 0) for d in per)
    a, b = a or test["a"].upper(), b or test["b"].upper()
    return f"; {a if up else b} fitter on {k} of {len(per)} optimization seeds" + _seed_level_text(test, ", ")


def seed_level_interval(sl: dict) -> str:
    """A t-test over optimization seeds (a test's ``seed_level``) as ``"+5.0 [-2.1, +12.1]"``: the mean
    difference and its 95 % t-interval (the text, table and README cell share it)."""
    lo, hi = sl["ci"]
    return f"{sl['mean_diff']:+.1f} [{lo:+.1f}, {hi:+.1f}]"


def _seed_level_text(test: dict, sep: str) -> str:
    """The t-test over optimization seeds (``seed_level``; results saved before it existed have none) in words:
    ``"over seeds +5.0 [-2.1, +12.1], t-test p = 0.08"``; ``""`` without one."""
    sl = test.get("seed_level")
    return f"{sep}over seeds {seed_level_interval(sl)}, t-test p = {sl['p_value']:.2g}" if sl else ""


def verdict(rows: list[dict], tests: list[dict], alpha: float = 0.05) -> list[str]:
    """One sentence per tested comparison, in words, whichever way it falls (with :func:`seed_agreement`)."""
    out = []
    for t in tests:
        if t["b"] == "theta0":
            continue
        f, x = t["fitness"], t["falls"]
        d = f["mean_diff"]
        if f["p_value"] < alpha:
            word = "beats" if d > 0 else "is worse than"
            out.append(f"step {t['step']}: {t['a'].upper()} {word} {t['b'].upper()} on fitness by {d:+.1f} "
                       f"(paired permutation p = {f['p_value']:.3g}; falls {x['only_a']} vs {x['only_b']} discordant, "
                       f"McNemar p = {x['p_value']:.3g}{seed_agreement(t)})")
        else:
            out.append(f"step {t['step']}: no significant difference between {t['a'].upper()} and {t['b'].upper()} "
                       f"(fitness {d:+.1f} ± {f['se_diff']:.1f}, p = {f['p_value']:.2g}; McNemar p = {x['p_value']:.2g}"
                       f"{seed_agreement(t)})")
    return out


def _per_seed_text(test: dict) -> str:
    per = test.get("per_seed_diff") or []
    return ("  per seed " + " ".join(f"{d:+.1f}" for d in per) + _seed_level_text(test, "; ")) if per else ""


def format_table(res: dict) -> str:
    """Table I: a row per method and step, pooled over the optimization seeds."""
    c = res["config"]
    lines = [f"Table I: {c['seeds']} optimization seed(s) per method, every gait on the same {c['trials']} paired real "
             "trials; mean ± s.e.; falls with a Wilson 95 % interval",
             f"{'method':10s} {'step':>4s} {'n':>4s} {'speed [cm/s]':>15s} {'falls':>8s} {'95 % CI':>14s} "
             f"{'fitness':>14s} {'world said':>10s}", "-" * 88]
    for r in res["rows"]:
        name = "θ0" if r["method"] == "theta0" else r["method"].upper()
        step = "-" if r["method"] == "theta0" else str(r["step"])
        lo, hi = r["falls_ci95"]
        said = "" if r.get("predicted_fitness") is None else f"{r['predicted_fitness']:10.1f}"
        lines.append(f"{name:10s} {step:>4s} {r['n']:>4d} {r['speed_mean']:7.2f} ± {r['speed_se']:4.2f} "
                     f"{r['falls']:>4d}/{r['n']:<3d} [{lo:.2f}, {hi:.2f}] {r['fitness_mean']:7.2f} ± {r['fitness_se']:4.2f} "
                     f"{said}")
    lines.append("")
    lines.append("paired tests (pairs = seed x trial): fitness by permutation, falls by McNemar")
    for t in res["tests"]:
        f, x = t["fitness"], t["falls"]
        lines.append(f"  step {t['step']}: {t['a']:>10s} vs {t['b']:<10s} fitness {f['mean_diff']:+6.2f} ± {f['se_diff']:4.2f} "
                     f"(p {f['p_value']:.3g})  falls {x['only_a']:>2d} vs {x['only_b']:<2d} (p {x['p_value']:.3g})"
                     + _per_seed_text(t))
    if res.get("baseline"):
        lines += ["", f"against the baseline {res['baseline']['path']} (same gait seeds and trials; a = this run):"]
        for t in res["baseline"]["tests"]:
            f, x = t["fitness"], t["falls"]
            vs = f"{t['method']} vs {t['baseline_method']}" if t.get("baseline_method") else t["method"]
            lines.append(f"  step {t['step']}: {vs:>8s} fitness {f['mean_diff']:+6.2f} ± {f['se_diff']:4.2f} "
                         f"(p {f['p_value']:.3g})  falls {x['only_a']:>2d} vs {x['only_b']:<2d} (p {x['p_value']:.3g})"
                         + _per_seed_text(t))
    lines.append("")
    lines += [f"verdict: {v}" for v in res["verdict"]]
    return "\n".join(lines)
