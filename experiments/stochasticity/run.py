"""Does SGAT pull ahead of GAT as the real world's per-step randomness grows? (``sgatwalk stochasticity``)

The paper's hypothesis (Desai et al., IROS 2020, Sec. IV-V and Figs. 7-9) is that modelling the target's
stochasticity improves transfer, and that SGAT's advantage over GAT grows with it. The humanoid's real
world is random mostly per episode (every effect of the ``real`` profile is drawn at reset); the
per-step randomness of ``envs.effects.Stochasticity`` (servo torque noise per control step, foot
friction and contact softness per touchdown) is the axis the paper sweeps. At each level this runs:

* ``sgatwalk fidelity`` of the training worlds (how well each ranks gaits by real fitness, its bias and
  fall calibration, over independent draws of the real data), in ``fidelity-L<level>/``;
* at the lowest and the highest level, ``sgatwalk table1`` of SGAT, GAT, the plain sim and ANE (optimization
  seeds x paired real trials), in ``table1-L<level>/``, and CMA-ES in the real world itself (``--methods
  real``, the bound of what the walk engine reaches there), in ``real-L<level>/``;
* why the grounded gaits fall (:mod:`experiments.stochasticity.falls`): at the Table I levels, each
  SGAT and GAT gait walked ``check_episodes`` times in the grounded world it was optimized in, beside
  its real fall rate, in ``falls-L<level>/``; at every fidelity level, SGAT's forward-model σ against
  held-out real transitions (in the summary).

Every part is an ordinary run directory, resumed where it stopped; the summary (``study.json``,
``stochasticity.png``, ``table.txt``) is rewritten after each part, from the parts done so far.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass

import numpy as np

from common.files import atomic_write_text, jsonable
from experiments.runtime.progress import Reporter


@dataclass
class StudyConfig:
    """Settings of a stochasticity study.

    Attributes:
        levels: per-step randomness levels of the fidelity runs (``envs.effects.Stochasticity``).
        table1_levels: levels of the Table I runs (default: the lowest and the highest of ``levels``).
        worlds: training worlds of the fidelity runs; gaits, real_trials, data_seeds, episodes: theirs
            (``sgatwalk fidelity``).
        methods: Table I methods; seeds: optimization seeds; trials: paired real trials per gait.
        real_seeds: optimization seeds of CMA-ES in the real world (0: none).
        check_episodes: grounded-world episodes per Table I gait of the falls check (0: none).
        optimize: ``sgatwalk optimize`` settings of every optimization (e.g. ``{"generations": 15}``).
        seconds: episode length [s] of every part; seed: the run seed of every part.
    """

    levels: tuple = (0.0, 1.0, 2.0, 3.0)
    table1_levels: tuple | None = None
    worlds: tuple = ("sim", "ane", "gat", "sgat", "hybrid")
    gaits: int = 8
    real_trials: int = 10
    data_seeds: int = 3
    episodes: int = 4
    methods: tuple = ("sgat", "gat", "sim", "ane")
    seeds: int = 5
    trials: int = 30
    real_seeds: int = 3
    check_episodes: int = 20
    optimize: dict = dataclasses.field(default_factory=dict)
    seconds: float = 7.5
    seed: int = 0

    def __post_init__(self) -> None:
        self.levels = tuple(sorted({float(v) for v in self.levels}))
        if self.table1_levels is None and self.levels:
            self.table1_levels = (self.levels[0], self.levels[-1]) if len(self.levels) > 1 else self.levels
        self.table1_levels = tuple(sorted({float(v) for v in self.table1_levels or ()}))

    def validate(self) -> None:
        """Raises ValueError naming the bad setting (every part's own checks included)."""
        from experiments.table1.config import Table1Config

        if not self.levels and not self.table1_levels:
            raise ValueError("no level given (neither fidelity nor Table I levels)")
        for v in (*self.levels, *self.table1_levels):
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"levels must be numbers >= 0, got {v}")
        if self.real_seeds < 0:
            raise ValueError(f"real_seeds must be >= 0, got {self.real_seeds}")
        if self.check_episodes < 0:
            raise ValueError(f"check_episodes must be >= 0, got {self.check_episodes}")
        self.fidelity(self.levels[0] if self.levels else 0.0).validate()
        Table1Config(**self._table1(self.table1_levels[0] if self.table1_levels else 0.0)).validate()

    def fidelity(self, level: float):
        from experiments.fidelity.config import FidelityConfig

        return FidelityConfig(worlds=tuple(self.worlds), gaits=self.gaits, real_trials=self.real_trials,
                              data_seeds=self.data_seeds, episodes=self.episodes, stochasticity=level, seconds=self.seconds,
                              seed=self.seed)

    def _table1(self, level: float, methods=None, seeds=None) -> dict:
        opt = {**self.optimize, "seconds": self.seconds, **({"stochasticity": level} if level else {})}
        return {"methods": tuple(methods or self.methods), "seeds": seeds or self.seeds, "trials": self.trials,
                "seed": self.seed, "optimize": opt}

    def to_dict(self) -> dict:
        return jsonable(dataclasses.asdict(self))


#: Grounded methods whose Table I gaits the falls check walks in their own training world.
CHECKED = ("sgat", "gat")


def _tag(level: float) -> str:
    return f"L{level:g}"


class Study:
    """Runs (or resumes) a stochasticity study in ``out`` with ``executor``; see the module docstring."""

    #: Settings a study directory may be resumed with changed: more levels add parts, more Table I
    #: methods are added to the Table I parts (what was done is reused).
    RESUMABLE = ("levels", "table1_levels", "methods")

    def __init__(self, cfg: StudyConfig, out: str, executor, *, reporter: Reporter | None = None):
        cfg.validate()
        self.cfg, self.out, self.ex = cfg, out, executor
        self.report = reporter or Reporter.quiet()
        os.makedirs(out, exist_ok=True)
        path = os.path.join(out, "study_config.json")
        if os.path.exists(path):
            with open(path) as f:
                old = json.load(f)
            fixed = {k: v for k, v in cfg.to_dict().items() if k not in self.RESUMABLE}
            # a setting the saved study does not name is one added since: it adds a part, changes none
            changed = sorted(k for k, v in fixed.items() if k in old and old[k] != v)
            if changed:
                raise ValueError(f"{out} holds a study with other settings ({', '.join(changed)}); "
                                 "use another --out (more levels or Table I methods may be added)")
        atomic_write_text(path, json.dumps(cfg.to_dict(), indent=1))

    def parts(self) -> list[tuple[str, str, float]]:
        """``[(kind, run directory, level)]`` in run order: Table I at the Table I levels (the study's
        question), then the real-world bound at those levels, then fidelity at every level, then the
        falls check of the Table I gaits of grounded methods."""
        cfg = self.cfg
        out = [("table1", os.path.join(self.out, f"table1-{_tag(v)}"), v) for v in cfg.table1_levels]
        if cfg.real_seeds:
            out += [("real", os.path.join(self.out, f"real-{_tag(v)}"), v) for v in cfg.table1_levels]
        out += [("fidelity", os.path.join(self.out, f"fidelity-{_tag(v)}"), v) for v in cfg.levels]
        if cfg.check_episodes and set(cfg.methods) & set(CHECKED):
            out += [("falls", os.path.join(self.out, f"falls-{_tag(v)}"), v) for v in cfg.table1_levels]
        return out

    def run(self) -> dict:
        """Run every part not finished yet, rewriting the summary after each; returns the summary."""
        from experiments.fidelity.run import Fidelity
        from experiments.table1.config import Table1Config
        from experiments.stochasticity.falls import grounded_falls
        from experiments.table1.run import Table1

        parts = self.parts()
        for i, (kind, run_dir, level) in enumerate(parts):
            done = self._done(kind, run_dir)
            self.report.say(f"part {i + 1}/{len(parts)}: {kind} at level {level:g} ({run_dir})"
                            + (" - done" if done else ""))
            if done:
                continue
            child = self.report.child(f"{kind} {_tag(level)}")
            if kind == "fidelity":
                Fidelity(self.cfg.fidelity(level), run_dir, self.ex, reporter=child).run()
            elif kind == "falls":
                grounded_falls(os.path.join(self.out, f"table1-{_tag(level)}"), run_dir, self.ex,
                               methods=CHECKED, episodes=self.cfg.check_episodes, seed=self.cfg.seed, reporter=child)
            else:
                kw = self.cfg._table1(level, ("real",), self.cfg.real_seeds) if kind == "real" else self.cfg._table1(level)
                Table1(Table1Config(**kw), run_dir, self.ex, reporter=child).run()
            self.write(summarize(self.out, self.cfg))
        res = summarize(self.out, self.cfg)
        self.write(res)
        return res

    def _done(self, kind: str, run_dir: str) -> bool:
        """Whether a part is finished: its result file exists and, for a Table I part, holds every
        method of the study (methods added since are run, resuming what was done)."""
        res = _load(os.path.join(run_dir, {"fidelity": "fidelity.json", "falls": "falls.json"}.get(kind, "table1.json")))
        if res is None:
            return False
        return kind != "table1" or set(self.cfg.methods) <= set(res["config"]["methods"])

    def write(self, res: dict) -> None:
        atomic_write_text(os.path.join(self.out, "study.json"), json.dumps(jsonable(res), indent=1))
        atomic_write_text(os.path.join(self.out, "table.txt"), format_table(res) + "\n")
        plot(res, os.path.join(self.out, "stochasticity.png"))


# ---------------------------------------------------------------- summary
def _load(path: str) -> dict | None:
    try:
        with open(path) as f:
            return json.load(f)
    except FileNotFoundError:
        return None


def _seed_interval(per_seed: list[float]) -> dict:
    """Mean and 95 % t-interval over optimization seeds (``experiments.runtime.stats.seed_level_test``)."""
    from experiments.runtime.stats import seed_level_test

    t = seed_level_test(per_seed)
    mean = float(np.mean(per_seed)) if per_seed else None
    return {"mean": mean, "ci95": t["ci"] if t else None, "p_value": t["p_value"] if t else None, "seeds": len(per_seed),
            "per_seed": [float(v) for v in per_seed]}


def trend_test(low: list[float], high: list[float]) -> dict | None:
    """Did ``a - b`` grow from one level to another? Welch's two-sample t-test of the per-seed contrasts
    at the high level against those at the low one (``scipy.stats.ttest_ind(equal_var=False)``; Welch
    1947), with the 95 % interval of the difference of means. The levels' optimization runs are
    independent (other worlds), so the test is unpaired.

    Args:
        low, high: per-optimization-seed contrasts at the two levels, shape (k,) each.

    Returns:
        ``{"diff", "ci95": [lo, hi], "p_value", "df"}``, or None with fewer than 2 seeds at a level or no
        spread at all.
    """
    from scipy import stats

    lo, hi = np.asarray(low, float), np.asarray(high, float)
    if len(lo) < 2 or len(hi) < 2 or (np.ptp(lo) == 0 and np.ptp(hi) == 0):
        return None
    r = stats.ttest_ind(hi, lo, equal_var=False)
    ci = r.confidence_interval(0.95)
    return {"diff": float(hi.mean() - lo.mean()), "ci95": [float(ci.low), float(ci.high)],
            "p_value": float(r.pvalue), "df": float(r.df)}


def table1_contrast(res: dict, a: str = "sgat", b: str = "gat") -> list[dict]:
    """``a`` - ``b`` per grounding step of a Table I result: real fitness and fall rate, each a mean over
    optimization seeds of the paired trial means with its 95 % t-interval over seeds."""
    trials = res["trials"]
    seeds = res["config"]["seeds"]
    steps = sorted({r["step"] for r in res["rows"] if r["method"] == a and r["step"] > 0})
    out = []
    for st in steps:
        ka, kb = [f"{a}|{st}|{s}" for s in range(seeds)], [f"{b}|{st}|{s}" for s in range(seeds)]
        if not all(k in trials for k in ka + kb):
            continue
        fit = [float(np.mean(np.subtract(trials[x]["fitness"], trials[y]["fitness"]))) for x, y in zip(ka, kb)]
        fall = [float(np.mean(np.subtract(trials[x]["fell"], trials[y]["fell"]))) for x, y in zip(ka, kb)]
        out.append({"step": st, "a": a, "b": b, "fitness": _seed_interval(fit), "fall_rate": _seed_interval(fall)})
    return out


def summarize(out: str, cfg: StudyConfig) -> dict:
    """What the parts in ``out`` found so far: per level, every fidelity world's scores over the draws and
    SGAT's forward-model calibration (:func:`experiments.stochasticity.falls.forward_calibration`); at the
    Table I levels, the rows, SGAT - GAT (fitness, falls), the real-world bound and the grounded worlds'
    fall rates of the gaits (:func:`experiments.stochasticity.falls.grounded_falls`)."""
    levels = []
    for v in sorted(set(cfg.levels) | set(cfg.table1_levels)):
        entry: dict = {"level": v}
        fid = _load(os.path.join(out, f"fidelity-{_tag(v)}", "fidelity.json"))
        if fid:
            entry["real_fall_rate"] = float(np.mean(fid["real"]["fall_rate"]))
            entry["fidelity"] = {w: {k: d["summary"][k] for k in ("rho", "bias", "brier")}
                                 for w, d in fid["worlds"].items()}
            # θ0, the gait every grounding walk uses: its fall rate in each world (mean over draws) and real
            entry["theta0_fall_rate"] = {"real": float(fid["real"]["fall_rate"][0]), **{
                w: float(np.mean([dr["fall_rate"][0] for dr in d["draws"]])) for w, d in fid["worlds"].items()
                if d.get("draws") and "fall_rate" in d["draws"][0]}}
        t1 = _load(os.path.join(out, f"table1-{_tag(v)}", "table1.json"))
        if t1:
            entry["table1"] = [{k: r[k] for k in ("method", "step", "n", "fitness_mean", "fitness_se", "falls", "falls_ci95")}
                               for r in t1["rows"]]
            entry["sgat_minus_gat"] = table1_contrast(t1)
            if "ane" in t1["config"].get("methods", ()):
                entry["sgat_minus_ane"] = table1_contrast(t1, "sgat", "ane")
        gf = _load(os.path.join(out, f"falls-{_tag(v)}", "falls.json"))
        if gf:
            entry["grounded_falls"] = {m: {k: r[k] for k in ("grounded", "real")} for m, r in gf["methods"].items()}
        if fid and "sgat" in fid["worlds"] and len(fid["worlds"]["sgat"].get("draws", [])) >= 2:
            from experiments.stochasticity.falls import forward_calibration

            c = forward_calibration(os.path.join(out, f"fidelity-{_tag(v)}"))
            entry["forward_calibration"] = {k: c[k] for k in ("median_z_std", "overconfident_share", "worst",
                                                              "mixture_median_z_std", "in_sample_median_z_std",
                                                              "transitions")}
        rb = _load(os.path.join(out, f"real-{_tag(v)}", "table1.json"))
        if rb:
            entry["real_bound"] = [{k: r[k] for k in ("method", "step", "n", "fitness_mean", "fitness_se", "falls", "falls_ci95")}
                                   for r in rb["rows"] if r["method"] == "real"]
        if len(entry) > 1:
            levels.append(entry)
    return {"config": cfg.to_dict(), "levels": levels, "verdict": verdict(levels)}


def verdict(levels: list[dict]) -> list[str]:
    """One sentence per Table I level on SGAT - GAT at the last grounding step, and one on the trend."""
    lines, last = [], []
    for e in levels:
        c = (e.get("sgat_minus_gat") or [None])[-1]
        if c is None:
            continue
        f, x = c["fitness"], c["fall_rate"]
        ci = f["ci95"]
        where = ("above" if ci and ci[0] > 0 else "below" if ci and ci[1] < 0 else "not apart from")
        lines.append(f"level {e['level']:g}: SGAT's step-{c['step']} gaits are {where} GAT's in real fitness "
                     f"({f['mean']:+.2f}" + (f", 95 % CI [{ci[0]:+.2f}, {ci[1]:+.2f}] over {f['seeds']} seeds)" if ci else ")")
                     + f"; fall rate {100 * x['mean']:+.0f} points")
        last.append((e["level"], f))
    if len(last) >= 2:
        (l0, f0), (l1, f1) = last[0], last[-1]
        t = trend_test(f0["per_seed"], f1["per_seed"])
        if t is None:
            lines.append(f"from level {l0:g} to {l1:g} SGAT - GAT moved {f1['mean'] - f0['mean']:+.2f} fitness points "
                         "(too few seeds to test)")
        else:
            grew = t["p_value"] < 0.05
            lines.append(f"from level {l0:g} to {l1:g} SGAT - GAT moved {t['diff']:+.2f} fitness points, 95 % CI "
                         f"[{t['ci95'][0]:+.2f}, {t['ci95'][1]:+.2f}], Welch p = {t['p_value']:.2g}: "
                         + (("SGAT pulls ahead as the randomness grows" if t["diff"] > 0 else "SGAT falls behind as the randomness grows")
                            if grew else "no trend shown at these seeds"))
    return lines


#: Fidelity scores the summary shows (``sgatwalk fidelity``'s): key, what it is.
FIDELITY_SCORES = (("rho", "Spearman rho of the world's gait fitness with the real one"),
                   ("bias", "bias (world - real fitness, over the panel's gaits)"),
                   ("brier", "Brier score of the world's fall probability against real falls (0 best)"))


def format_table(res: dict) -> str:
    """The summary as text: fidelity per world and level, then Table I's SGAT - GAT and the bound."""
    lines = ["per-step stochasticity study", ""]
    worlds = sorted({w for e in res["levels"] for w in e.get("fidelity", {})})
    for key, what in FIDELITY_SCORES:
        if not worlds:
            break
        lines.append(f"fidelity: {what}, median [min, max] over draws of the real data")
        lines.append(f"{'level':>5} {'real falls':>10} " + " ".join(f"{w:>20}" for w in worlds))
        for e in res["levels"]:
            if "fidelity" in e:
                cells = []
                for w in worlds:
                    r = e["fidelity"].get(w, {}).get(key)
                    cells.append(f"{r['median']:+.2f} [{r['min']:+.2f}, {r['max']:+.2f}]" if r else "-")
                lines.append(f"{e['level']:>5g} {100 * e['real_fall_rate']:>9.0f}% " + " ".join(f"{c:>20}" for c in cells))
        lines.append("")
    t1 = [e for e in res["levels"] if e.get("table1")]
    if t1:
        lines.append("Table I: real fitness (mean ± s.e. over seeds x trials) and falls")
        lines.append(f"{'level':>5} {'method':>8} {'step':>4} {'fitness':>14} {'falls':>9}")
        for e in t1:
            for r in e["table1"]:
                lines.append(f"{e['level']:>5g} {r['method']:>8} {r['step']:>4} "
                             f"{r['fitness_mean']:>+7.2f} ± {r['fitness_se']:<4.2f} {r['falls']:>4}/{r['n']:<4}")
        lines.append("")
    for e in res["levels"]:
        for c in e.get("sgat_minus_gat", []) + e.get("sgat_minus_ane", []):
            f, x = c["fitness"], c["fall_rate"]
            ci = f"[{f['ci95'][0]:+.2f}, {f['ci95'][1]:+.2f}]" if f["ci95"] else "-"
            xci = f"[{100 * x['ci95'][0]:+.0f}, {100 * x['ci95'][1]:+.0f}]" if x["ci95"] else "-"
            p = f", p = {f['p_value']:.2g}" if f.get("p_value") is not None else ""
            lines.append(f"level {e['level']:g} step {c['step']}: SGAT - {c['b'].upper()} fitness {f['mean']:+.2f} {ci}{p}, "
                         f"fall rate {100 * x['mean']:+.0f} points {xci} (95 % over {f['seeds']} seeds)")
        for r in e.get("real_bound", []):
            lines.append(f"level {e['level']:g}: CMA-ES in the real world, step {r['step']}: fitness "
                         f"{r['fitness_mean']:.2f} ± {r['fitness_se']:.2f}, falls {r['falls']}/{r['n']}")
    checks = [e for e in res["levels"] if e.get("grounded_falls") or e.get("forward_calibration")]
    if checks:
        lines += ["", "why the grounded gaits fall: fall rate of the last step's gaits in their own grounded world "
                      "and in the real one (95 % Wilson interval)"]
        for e in checks:
            for m, r in e.get("grounded_falls", {}).items():
                g, x = r["grounded"], r["real"]
                lines.append(f"level {e['level']:g} {m:>5}: grounded {g['falls']:>3}/{g['n']:<3} "
                             f"[{100 * g['ci95'][0]:.0f}, {100 * g['ci95'][1]:.0f}] %, fitness {g['fitness_mean']:+.2f}; "
                             f"real {x['falls']:>3}/{x['n']:<3} [{100 * x['ci95'][0]:.0f}, {100 * x['ci95'][1]:.0f}] %, "
                             f"fitness {x['fitness_mean']:+.2f}")
        lines.append("SGAT forward model on held-out real transitions: spread of z = (ds - mu) / sigma per state "
                     "dimension (1: calibrated, above 1: sigma too small)")
        for e in checks:
            c = e.get("forward_calibration")
            if c:
                worst = ", ".join(f"{n} {z:.2f}" for n, z in c["worst"])
                lines.append(f"level {e['level']:g}: median {c['median_z_std']:.2f} (own data {c['in_sample_median_z_std']:.2f}, "
                             f"members' mixture {c['mixture_median_z_std']:.2f}), over 1.5 in "
                             f"{100 * c['overconfident_share']:.0f} % of dimensions; worst {worst}")
    lines += [""] + res["verdict"]
    return "\n".join(lines)


def plot(res: dict, path: str) -> None:
    """Left: each fidelity world's ρ and Brier score (median, min-max over draws) against the level (left
    out when the study has no fidelity runs); right: SGAT - GAT real fitness and fall rate (percentage points) at the
    last step, 95 % intervals over seeds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    worlds = sorted({w for e in res["levels"] for w in e.get("fidelity", {})})
    if worlds:
        fig, (a1, a3, a2) = plt.subplots(1, 3, figsize=(15, 4))
    else:  # a study of Table I runs only: no fidelity panels
        fig, a2 = plt.subplots(1, 1, figsize=(6, 4))
    for ax, key, ylabel, title in ((a1, "rho", "Spearman ρ with real fitness", "ranking (higher is better)"),
                                   (a3, "brier", "Brier score of the fall probability", "fall calibration (lower is better)")
                                   ) if worlds else ():
        for k, w in enumerate(worlds):
            pts = [(e["level"], e["fidelity"][w][key]) for e in res["levels"] if w in e.get("fidelity", {})]
            x = np.array([p[0] for p in pts]) + 0.04 * (k - len(worlds) / 2)
            med = np.array([p[1]["median"] for p in pts])
            err = np.array([[m - p[1]["min"], p[1]["max"] - m] for m, p in zip(med, pts)]).T
            ax.errorbar(x, med, yerr=err, marker="o", capsize=3, label=w)
        ax.set(xlabel="per-step stochasticity level", ylabel=ylabel, title=f"fidelity per world: {title}")
        ax.axhline(0, color="0.7", lw=0.8)
        ax.legend(fontsize=8)
    pts = [(e["level"], e["sgat_minus_gat"][-1]) for e in res["levels"] if e.get("sgat_minus_gat")]
    for key, scale, color, label in (("fitness", 1.0, "C0", "fitness"), ("fall_rate", 100.0, "C3", "fall rate [points]")):
        xs = [p[0] for p in pts]
        ms = [scale * p[1][key]["mean"] for p in pts]
        lo = [scale * (p[1][key]["mean"] - p[1][key]["ci95"][0]) if p[1][key]["ci95"] else 0 for p in pts]
        hi = [scale * (p[1][key]["ci95"][1] - p[1][key]["mean"]) if p[1][key]["ci95"] else 0 for p in pts]
        a2.errorbar(np.array(xs) + (0.05 if key == "fall_rate" else 0), ms, yerr=[lo, hi], marker="o", capsize=4,
                    color=color, label=label)
    a2.axhline(0, color="0.5", lw=0.8)
    a2.set(xlabel="per-step stochasticity level", ylabel="SGAT − GAT (95 % CI over seeds)", title="Table I, last step")
    if pts:
        a2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


__all__ = ["Study", "StudyConfig", "format_table", "plot", "summarize", "table1_contrast", "verdict"]
