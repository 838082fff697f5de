"""What a fidelity run shows a person: the table (text), the paired tests, and the figures."""

from __future__ import annotations

import math

import numpy as np

from common.files import atomic_path
from experiments.fidelity.scoring import episodes_rows, gait_groups, group_rows, range_text, replay_totals
from experiments.runtime.stats import format_ci, p_text


def format_phases(phases: dict[str, float], min_s: float = 0.0) -> str:
    """``"real trials 138 s, diagnoses 375 s, ..."``: the phases of ``phases_s`` [s] that took at least
    ``min_s``, in run order (the text output's ``time:`` line and the README's)."""
    return ", ".join(f"{k} {v:.0f} s" for k, v in phases.items() if v >= min_s)


def format_paired(res: dict) -> list[str]:
    """The text lines of ``res["paired"]`` (none when the result has none)."""
    rows = res.get("paired") or []
    if not rows:
        return []

    lines = ["", "paired differences of rho (world - reference, the mean over the draws; 90% bootstrap intervals and "
             "two-sided p over the real trials and episodes on this panel, and over the gaits too, for a new panel):",
             f"  {'world - reference':40s} {'diff':>5s} {'this panel':>16s} {'p':>6s} {'a new panel':>16s} {'p':>6s}"]
    for r in rows:
        lines.append(f"  {r['world'] + ' - ' + r['reference']:40s} {r['diff']:+5.2f} {format_ci(r['ci_panel']):>16s} "
                     f"{p_text(r['p_value_panel'], r['n_boot']):>6s} {format_ci(r['ci']):>16s} {p_text(r['p_value'], r['n_boot']):>6s}")
    return lines


def format_table(res: dict) -> str:
    """The fidelity table: one row per world, figures as median [min, max] over the draws."""
    r = res["real"]
    lines = [f"{len(res['gaits'])} gaits x {r['trials']} paired real trials; real fitness "
             f"{min(r['fitness']):.1f} .. {max(r['fitness']):.1f}, falls {100 * float(np.mean(r['fall_rate'])):.0f} %",
             f"ceiling of rho from the real trials' noise: {r['ceiling']:.2f} (split-half reliability "
             f"{r['reliability']:.2f}); Brier of the constant base rate {r['brier_base_rate']:.3f}, of each gait's own "
             f"real frequency {r['brier_own_frequency']:.3f}",
             "",
             f"{'world':28s} {'draws':>5s} {'Spearman rho':>22s} {'worst 90% CI':>14s} {'MAE':>14s} "
             f"{'bias (world-real)':>24s} {'Brier':>22s} {'pick regret':>20s} {'own-noise ceiling':>18s}",
             "-" * 176]

    rng3 = range_text

    for name, w in res["worlds"].items():
        s = w["summary"]
        worst = min(w["draws"], key=lambda d: -np.inf if d["rho"] is None or not math.isfinite(d["rho"]) else d["rho"])
        ci = worst["rho_ci90"]
        ci_txt = "-" if ci[0] is None or not math.isfinite(ci[0]) else f"[{ci[0]:.2f}, {ci[1]:.2f}]"
        lines.append(f"{name:28s} {s['draws']:>5d} {rng3(s['rho']):>22s} {ci_txt:>14s} {s['mae']['median']:>14.1f} "
                     f"{s['bias']['median']:>+8.1f} (spread {s['bias']['spread']:4.1f}) {rng3(s['brier'], '{:.3f}'):>22s} "
                     f"{rng3(s['pick_regret'], '{:.1f}') if 'pick_regret' in s else '-':>20s} "
                     f"{_own(s):>18s}")
    forced = [(n, [d["replay"] for d in w["draws"]]) for n, w in res["worlds"].items()
              if w["draws"] and all("replay" in d for d in w["draws"])]
    if forced:
        lines += ["", "teacher-forced along each draw's grounding walks (their real next states in place of the forward "
                  "model; summed over the draws):"]
        for name, rp in forced:
            t = replay_totals(rp)
            lines.append(f"  {name:26s} sim fell on {t['fell_with_real']}/{t['real_fell']} walks that fell, "
                         f"{t['fell_without_real']}/{t['walks'] - t['real_fell']} that did not; leg joints "
                         f"{t['q_rms_rad']:.3f} rad RMS from the real walk (ungrounded {t['q_rms_plain_rad']:.3f})")
    lines += format_paired(res)
    lines += format_groups(res)
    lines += format_episodes(res)
    return "\n".join(lines)


def format_groups(res: dict) -> list[str]:
    """The text lines of :func:`group_rows` (none for a panel without θ files)."""
    rows = group_rows(res)
    if not rows:
        return []
    lines = ["", "per gait group (drawn: theta0 and the trust-region gaits; given: the --params files, and each file "
                 "name): median [min, max] over the draws (MAE: the median); rho /the group's ceiling from the real trials' noise",
             f"  {'group':30s} {'world':16s} {'gaits':>5s} {'real':>6s} {'world':>19s} {'bias':>20s} {'MAE':>6s} {'rho /ceiling':>25s} "
             f"{'pick regret':>17s}"]
    for r in rows:
        rho = range_text(r["rho"]) + ("" if r["real_ceiling"] is None else f" /{r['real_ceiling']:.2f}")
        lines.append(f"  {r['group']:30s} {r['world']:16s} {r['gaits']:>5d} {r['real_fitness']:>+6.1f} "
                     f"{range_text(r['fitness'], '{:+.1f}'):>19s} {range_text(r['bias'], '{:+.1f}'):>20s} {r['mae']['median']:>6.1f} {rho:>25s} "
                     f"{range_text(r['pick_regret'], '{:.1f}'):>17s}")
    return lines


def format_episodes(res: dict) -> list[str]:
    """The text lines of :func:`experiments.fidelity.scoring.episodes_rows` (none for a result without ``by_episodes``)."""
    rows = episodes_rows(res)
    if not rows:
        return []
    lines = ["", "against episodes per gait (the first k of every gait's episodes, the seeds of a run with --episodes k):",
             f"  {'world':26s} {'k':>3s} {'rho worst [median]':>19s} {'|bias|':>7s} {'spread':>7s} {'Brier':>6s}"]
    for r in rows:
        lines.append(f"  {r['world']:26s} {r['episodes']:>3d} {r['rho_worst']:>8.2f} [{r['rho_median']:.2f}]     "
                     f"{r['abs_bias_median']:>7.1f} {r['bias_spread']:>7.1f} {r['brier_median']:>6.3f}")
    return lines


def _own(summary: dict) -> str:
    """A world's own-noise ceiling of ρ as 'median [worst]' over its draws, '-' where not measured."""
    c = summary.get("world_ceiling")
    return "-" if c is None else f"{c['median']:.2f} [{c['min']:.2f}]"


def plot(res: dict, path: str) -> None:
    """Predicted against real fitness, one panel per world, one colour per draw; a panel with θ files
    (:func:`gait_groups`) draws the given gaits as triangles, the drawn ones as dots."""
    import matplotlib  # lazy: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib

    worlds = list(res["worlds"].items())
    n = len(worlds)
    cols = min(3, n)
    rows = int(math.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.8 * rows), squeeze=False,
                             layout="constrained")  # leaves room for the suptitle (tight_layout does not)
    real = np.array(res["real"]["fitness"])
    se = np.array(res["real"]["fitness_se"])
    lo = min(real.min(), min(min(d["fitness"]) for _, w in worlds for d in w["draws"])) - 2
    hi = max(real.max(), max(max(d["fitness"]) for _, w in worlds for d in w["draws"])) + 2
    given = np.zeros(len(real), dtype=bool)
    given[gait_groups(res).get("given", [])] = True
    for ax, (name, w) in zip(axes.ravel(), worlds):
        ax.plot([lo, hi], [lo, hi], color="0.6", lw=1, ls="--")
        for d in w["draws"]:
            f = np.asarray(d["fitness"], dtype=float)
            line = ax.errorbar(real[~given], f[~given], xerr=se[~given], fmt="o", ms=3.5, lw=0.6, alpha=0.8,
                               label=f"draw {d['draw']}: ρ {d['rho']:.2f}"
                               if d["rho"] is not None and math.isfinite(d["rho"]) else f"draw {d['draw']}")
            if given.any():
                ax.errorbar(real[given], f[given], xerr=se[given], fmt="^", ms=4.5, lw=0.6, alpha=0.8,
                            color=line[0].get_color())
        if given.any():  # the marker key, in the legend below the draws
            ax.plot([], [], "^", color="0.3", ms=4.5, label="given θ files")
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("real fitness (mean ± s.e.)")
        ax.set_ylabel("training-world fitness")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6, loc="upper left")
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    fig.suptitle(f"fidelity: {len(real)} gaits, fitness = speed [cm/s] − 15 per fall; ceiling ρ "
                 f"{res['real']['ceiling']:.2f}", fontsize=10)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def plot_episodes(res: dict, path: str) -> None:
    """Fidelity against episodes per gait (:func:`experiments.fidelity.scoring.episodes_rows`): worst
    (solid) and median (dashed) ρ over the draws with the ceiling the real trials' noise allows, and the
    bias spread over the draws, one line per stochastic world; the deterministic worlds as horizontal
    lines."""
    import matplotlib  # lazy: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib

    rows = episodes_rows(res)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.2), layout="constrained")
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    worlds = list(dict.fromkeys(r["world"] for r in rows))
    for i, name in enumerate(worlds):
        rs = [r for r in rows if r["world"] == name]
        k = [r["episodes"] for r in rs]
        c = colors[i % len(colors)]
        a1.plot(k, [r["rho_worst"] for r in rs], "o-", color=c, label=name)
        a1.plot(k, [r["rho_median"] for r in rs], "o--", color=c, alpha=0.5, ms=3)
        if res["worlds"][name]["summary"]["draws"] > 1:  # a spread needs draws
            a2.plot(k, [r["bias_spread"] for r in rs], "o-", color=c)
    for j, (name, w) in enumerate((n, w) for n, w in res["worlds"].items() if w.get("episodes") == 1):
        c = colors[(len(worlds) + j) % len(colors)]
        a1.axhline(w["summary"]["rho"]["min"], color=c, lw=1, ls=":", label=f"{name} (deterministic, worst draw)")
        if w["summary"]["draws"] > 1:
            a2.axhline(w["summary"]["bias"]["spread"], color=c, lw=1, ls=":")
    a1.axhline(res["real"]["ceiling"], color="0.5", lw=1, ls="-.", label="ceiling (real trials' noise)")
    for ax in (a1, a2):
        ax.set_xscale("log", base=2)
        ax.set_xticks(sorted({r["episodes"] for r in rows}), [str(x) for x in sorted({r["episodes"] for r in rows})])
        ax.set_xlabel("episodes per gait in the training world")
        ax.grid(alpha=0.3)
    a1.set_ylabel("Spearman ρ with real fitness\n(solid: worst draw, dashed: median)")
    a2.set_ylabel("bias spread over the draws [fitness points]")
    fig.legend(*a1.get_legend_handles_labels(), loc="outside right upper", fontsize=7)  # one legend, both panels
    fig.suptitle(f"fidelity against episodes per gait: {len(res['gaits'])} gaits × {res['real']['trials']} real trials",
                 fontsize=10)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
