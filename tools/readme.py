"""Numbers in the README come from code: render saved results into it, and check that they agree.

A README block between ``<!-- results:NAME -->`` and ``<!-- /results:NAME -->`` is generated from
``docs/results/NAME.json``: the JSON a command printed with ``--json`` plus the command line that
made it (``{"command": "...", "result": {...}}``, written by :func:`save`). Renderers per NAME turn
the result into Markdown; the command is printed above the table, so every figure names its source.

Usage:

* ``python -m tools.readme run NAME -- optimize --methods sgat`` runs ``sgatwalk optimize
  --methods sgat --json`` and saves its JSON with the command line as ``docs/results/NAME.json``;
* ``python -m tools.readme`` rewrites README.md and the other :data:`DOCUMENTS` (the record of
  every fidelity and Table I run, ``docs/grounding_history.md``) from the saved results;
* ``python -m tools.readme --check`` exits 1 (naming the file and the blocks) when a document and
  the saved results disagree, or (naming them) when a relative link leads nowhere: an in-page anchor no
  heading or ``<a id>`` gives, a missing file, or an anchor another Markdown file does not give
  (``tests/test_readme.py`` runs it).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import re
import statistics
import sys

from common.files import atomic_write_text
from experiments.cli import main as cli_main
from experiments.cli.cliff import format_table
from experiments.cli.stand import format_stand
from experiments.fidelity.run import (episodes_rows, fidelity_targets, first_world, format_phases, group_rows, p_text,
                                  ranking_target, replay_totals)
from experiments.table1.run import seed_level_interval

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "docs", "results")
#: The Markdown documents whose results blocks are rendered and whose links are checked, relative to
#: the repository root: the README (commands, today's default runs, what they found) and the record of
#: every fidelity and Table I run behind it.
DOCUMENTS = ("README.md", os.path.join("docs", "grounding_history.md"))
_BLOCK = re.compile(r"(<!-- results:(?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- /results:(?P=name) -->)", re.S)


def save(name: str, command: str, result: dict, results_dir: str = RESULTS, machine: dict | None = None) -> str:
    """Write ``docs/results/NAME.json`` (atomically); returns its path. ``machine``: where and under
    what load it ran (cores, 1-minute load average before and after)."""
    path = os.path.join(results_dir, f"{name}.json")
    doc = {"command": command, "result": result, **({"machine": machine} if machine else {})}
    atomic_write_text(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return path


def save_benchmark(name: str, script: str, argv: list[str], result: dict, load_before: float) -> str:
    """A benchmark script's ``--save NAME``: :func:`save` with the command line that ran it (``python
    SCRIPT ARGS``, less ``--save NAME``) and the machine (cores, 1-minute load before and now)."""
    args, skip = [], False
    for a in argv:
        if skip or a == "--save" or a.startswith("--save="):
            skip = a == "--save"
            continue
        args.append(a)
    machine = {"cpus": os.cpu_count(), "load_before": load_before, "load_after": os.getloadavg()[0]}
    return save(name, " ".join(["python", script, *args]), result, machine=machine)


def finish_benchmark(result: dict, script: str, argv: list[str] | None, *, save_name: str | None, as_json: bool,
                     load_before: float) -> None:
    """A benchmark script's last step: :func:`save_benchmark` under ``save_name`` when given, then its
    result printed (one JSON object with ``as_json``, else its ``"text"``). ``argv`` None: ``sys.argv[1:]``."""
    if save_name:
        save_benchmark(save_name, script, list(argv if argv is not None else sys.argv[1:]), result, load_before)
    print(json.dumps(result) if as_json else result["text"], flush=True)


def _f(x, fmt="{:.2f}") -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else fmt.format(x)


def _episodes_table(res: dict) -> list[str]:
    """Fidelity against episodes per gait (``experiments.fidelity.run.episodes_rows``), one row per
    stochastic world, one column per count k: worst ρ [median], bias spread, targets met."""
    rows = episodes_rows(res)
    ks = sorted({r["episodes"] for r in rows})
    if len(ks) < 2:
        return []
    cell = {(r["world"], r["episodes"]): r for r in rows}
    out = ["", f"Against the number of episodes per gait (each stochastic world's first k episodes of every gait, "
               f"the seeds a run with `--episodes k` walks): worst ρ over the draws [median], bias spread over the "
               f"draws, and for "
               f"the SGAT, hybrid and oracle worlds the targets met (ranking target "
               f"{ranking_target(res['real']['ceiling']):.2f}, **bold** where met):", "",
           "| world | " + " | ".join(f"k = {k}" for k in ks) + " |", "|---|" + "---|" * len(ks)]
    for name in dict.fromkeys(r["world"] for r in rows):
        cells = []
        for k in ks:
            r = cell.get((name, k))
            if r is None:
                cells.append("–")
                continue
            rho = f"{_f(r['rho_worst'])} [{_f(r['rho_median'])}]"
            one_draw = res["worlds"][name]["summary"]["draws"] == 1  # a spread needs draws
            cells.append((f"**{rho}**" if r["ranking_met"] else rho)
                         + ("" if one_draw else f", spread {_f(r['bias_spread'], '{:.1f}')}")
                         + ("" if r["targets"] is None else f", {r['targets_met']}/{r['targets']}"))
        out.append(f"| `{name}` | " + " | ".join(cells) + " |")
    return out


def _groups_table(res: dict) -> list[str]:
    """Each world on the panel's gait groups (``experiments.fidelity.run.group_rows``: the drawn gaits, the
    given θ files, each file name): its bias per group, then its ranking and pick within the groups
    large enough to rank. None for a panel without θ files."""
    rows = group_rows(res)
    if not rows:
        return []
    worlds = list(dict.fromkeys(r["world"] for r in rows))
    groups = list(dict.fromkeys(r["group"] for r in rows))
    cell = {(r["group"], r["world"]): r for r in rows}

    def rng(s, fmt):
        return f"{fmt.format(s['median'])} [{fmt.format(s['min'])}, {fmt.format(s['max'])}]"

    out = ["", "Per group of gaits (drawn: θ0 and the gaits drawn around it; given: the θ files of `--params`, "
               "and each file name): the real mean fitness (± s.e. over the paired trials) and falls, and each "
               "world's bias on the group (world − real, the mean over its gaits; median [min, max] over the draws) "
               "and its mean absolute error (median over the draws):",
           "", "| group | gaits | real fitness | real falls | " + " | ".join(f"`{w}`" for w in worlds) + " |",
           "|---|---|---|---|" + "---|" * len(worlds)]
    for g in groups:
        r0 = cell[(g, worlds[0])]
        se = "" if r0["real_fitness_se"] is None else f" ± {r0['real_fitness_se']:.1f}"
        out.append(f"| {g} | {r0['gaits']} | {r0['real_fitness']:+.1f}{se} | {100 * r0['real_falls']:.0f} % | "
                   + " | ".join(f"{rng(cell[(g, w)]['bias'], '{:+.1f}')}, MAE {cell[(g, w)]['mae']['median']:.1f}"
                                for w in worlds) + " |")
    ranked = [g for g in groups if cell[(g, worlds[0])]["rho"] is not None]
    if ranked:
        out += ["", "Within the groups of at least 8 gaits: Spearman ρ with the real fitness and the regret of the "
                    "world's pick (the real fitness lost by taking the gait the world rates best instead of the "
                    "group's real best), median [min, max] over the draws; the group's ceiling of ρ from the real "
                    "trials' own noise beside its name:", "",
                "| group (ceiling) | " + " | ".join(f"`{w}`" for w in worlds) + " |", "|---|" + "---|" * len(worlds)]
        for g in ranked:
            c = cell[(g, worlds[0])]["real_ceiling"]
            out.append(f"| {g}{'' if c is None else f' ({c:.2f})'} | " + " | ".join(
                f"ρ {rng(cell[(g, w)]['rho'], '{:.2f}')}, regret {rng(cell[(g, w)]['pick_regret'], '{:.1f}')}"
                for w in worlds) + " |")
    return out


def _paired_cells(r: dict) -> str:
    """A paired comparison's Markdown cells: Δρ, this panel's interval and p, a new panel's, Δρ per draw."""
    def ci(c):
        return f"[{_f(c[0], '{:+.2f}')}, {_f(c[1], '{:+.2f}')}]"

    return (f"{_f(r['diff'], '{:+.2f}')} | {ci(r['ci_panel'])}, p {p_text(r['p_value_panel'], r['n_boot'])} | "
            f"{ci(r['ci'])}, p {p_text(r['p_value'], r['n_boot'])} | " + ", ".join(_f(x, '{:+.2f}') for x in r["per_draw"]))


def _paired_table(res: dict) -> list[str]:
    """The paired comparisons of the worlds' rankings (``paired`` of a fidelity result, saved since the
    twenty-third round; none before)."""
    rows = res.get("paired") or []
    if not rows:
        return []
    lines = ["", "Paired: does a world rank the gaits better than another beyond the noise? ρ(world) − ρ(reference), "
             "the mean over the draws (draw d of every world learns from the same real data), with 90 % intervals "
             "and two-sided p-values from a paired bootstrap (`experiments.runtime.stats.paired_spearman_difference`): over "
             "the real trials and the episodes, on this panel's gaits; and over the gaits too, for a new panel of as "
             "many gaits from the same region:", "",
             "| world − reference | Δρ, mean over the draws | this panel: 90 % interval, p | a new panel: 90 % interval, p "
             "| Δρ per draw |", "|---|---|---|---|---|"]

    for r in rows:
        lines.append(f"| `{r['world']}` − `{r['reference']}` | {_paired_cells(r)} |")
    return lines


def _fidelity(res: dict) -> str:
    r = res["real"]
    # runs saved before the worlds' own-noise ceiling was measured have no column for it
    own = any("world_ceiling" in w["summary"] for w in res["worlds"].values())
    lines = [f"{len(res['gaits'])} gaits × {r['trials']} paired real trials (real fitness {min(r['fitness']):.1f} to "
             f"{max(r['fitness']):.1f}, {100 * sum(r['fall_rate']) / len(r['fall_rate']):.0f} % falls); ceiling of ρ "
             f"from the trials' own noise **{_f(r['ceiling'])}** (split-half reliability {_f(r['reliability'])}); Brier "
             f"score of a constant base rate {_f(r['brier_base_rate'], '{:.3f}')}, of each gait's own real fall "
             f"frequency {_f(r['brier_own_frequency'], '{:.3f}')} (the floor).", "",
             "| world | draws | Spearman ρ: median [worst, best] | worst draw's 90 % CI | MAE | bias (world − real): "
             "median, spread | Brier: median [min, max] | regret of its pick: median [worst] | real data per draw |"
             + (" ceiling of ρ from its own episode noise: median [worst] |" if own else ""),
             "|---|---|---|---|---|---|---|---|---|" + ("---|" if own else "")]
    for name, w in res["worlds"].items():
        s = w["summary"]
        worst = min(w["draws"], key=lambda d: math.inf if d["rho"] is None else d["rho"])
        ci = worst["rho_ci90"]
        d0 = w["draws"][0]
        data = []
        if d0["real_walks"]:
            data.append(f"{d0['real_walks']} walks ({d0['real_seconds']:.0f} s)")
        if d0["excitation_logs"]:
            data.append(f"{d0['excitation_logs']} excitation logs ({d0['excitation_seconds']:.0f} s)")
        if w.get("kind") == "oracle":
            data.append(f"it is the real world{' at its mean physics' if w.get('oracle_mean') else ''}"
                        f"{' built into the sim (MuJoCo)' if w.get('oracle_engine') == 'mujoco' else ''}"
                        f"{_mujoco_form(w)} ({w['episodes']} episodes per gait on fresh seeds)")
        lines.append(f"| `{name}` | {s['draws']} | {_f(s['rho']['median'])} [{_f(s['rho']['min'])}, {_f(s['rho']['max'])}] "
                     f"| [{_f(ci[0])}, {_f(ci[1])}] | {_f(s['mae']['median'], '{:.1f}')} | "
                     f"{_f(s['bias']['median'], '{:+.1f}')}, {_f(s['bias']['spread'], '{:.1f}')} | "
                     f"{_f(s['brier']['median'], '{:.3f}')} [{_f(s['brier']['min'], '{:.3f}')}, "
                     f"{_f(s['brier']['max'], '{:.3f}')}] | {_pick(res, w)} | {', '.join(data) or 'none'} |"
                     + (f" {_own_ceiling(s)} |" if own else ""))
    lines += _data_gait_falls(res)
    ref = first_world(res, "sgat")
    targets = fidelity_targets(res, ref) if ref else []
    if targets:
        lines += ["", f"SGAT (`{ref}`) against the targets of the grounding issue:", ""]
        lines += [f"* {'met' if ok else '**not met**'}: {t} — {v}" for t, ok, v in targets]
    variants = [n for n, w in res["worlds"].items() if n != ref and (w.get("kind") == "sgat" or (
        w.get("kind") == "hybrid" and (w.get("grounding") or {}).get("method") == "sgat"))]
    if targets and variants:
        hybrid = any(res["worlds"][n]["kind"] == "hybrid" for n in variants)
        lines += ["", "The SGAT variants" + (" (hybrid: SGAT grounding on the identified sim)" if hybrid else "")
                  + " against the same targets (✓ met, ✗ not met):", "",
                  "| world | " + " | ".join(t.replace("|", "\\|") for t, _, _ in targets) + " |",
                  "|---|" + "---|" * len(targets)]
        for n in variants:
            tv = fidelity_targets(res, n)
            lines.append(f"| `{n}` | " + " | ".join(
                ("✓" if ok else "✗") + ("" if "every draw" in t else f" {v.split(' (')[0]}") for t, ok, v in tv) + " |")
    lines += _episodes_table(res)
    lines += _paired_table(res)
    lines += _groups_table(res)
    for oracle in [n for n, w in res["worlds"].items() if w.get("kind") == "oracle"] if targets else []:
        w = res["worlds"][oracle]
        parts = [f"{'met' if ok else '**not met**'}: {t}" + ("" if "every draw" in t else f" — {v.split(' (')[0]}")
                 for t, ok, v in fidelity_targets(res, oracle)]
        what = "at its mean physics, every effect at the middle of its range" if w.get("oracle_mean") else "itself"
        if w.get("oracle_engine") == "mujoco":
            what += ", built into the sim (MuJoCo) by the identified sim's effect models" + _mujoco_form(w)
        lines += ["", f"For scale, `{oracle}` (the real world {what}, {w['episodes']} episodes per "
                  "gait on fresh seeds) against the same targets: " + "; ".join(parts) + "."]
    if res.get("wall_s") is not None:
        ph = format_phases(res.get("phases_s") or {}, min_s=0.5)
        lines += ["", f"The run took {res['wall_s'] / 60:.1f} min" + (f": {ph}." if ph else ".")]
    return "\n".join(lines)


def _data_gait_falls(res: dict) -> list[str]:
    """How often θ0, the gait of the grounding walks, falls: in the real trials, in the grounding walks
    themselves and in each world fitted on them (an in-sample check; runs saved since the eighth
    fidelity round record the walks' falls)."""
    fitted = {n: w for n, w in res["worlds"].items()
              if w.get("data_gaits") == 1 and all("real_walk_falls" in d for d in w["draws"])}
    if not fitted or res["gaits"][0] != "theta0":
        return []
    d0 = next(iter(fitted.values()))["draws"]
    walked = [(d["real_walks"], d["real_walk_falls"]) for d in d0]
    # worlds fitted on other walks (e.g. ``real=8``) are left out of the comparison with these
    fitted = {n: w for n, w in fitted.items() if [(d["real_walks"], d["real_walk_falls"]) for d in w["draws"]] == walked}
    falls = [d["real_walk_falls"] for d in d0]
    walks = sum(d["real_walks"] for d in d0)

    def rate(name, w):
        v = [100 * d["fall_rate"][0] for d in w["draws"]]
        return f"`{name}` {statistics.median(v):.0f} % [{min(v):.0f}, {max(v):.0f}]"
    parts = [rate(n, w) for n, w in fitted.items()]
    return ["", f"θ0, the gait of the grounding walks, falls in {100 * res['real']['fall_rate'][0]:.0f} % of its real "
            f"trials and in {sum(falls)} of the {walks} grounding walks ({min(falls)}–{max(falls)} of "
            f"{d0[0]['real_walks']} per draw); the worlds fitted on those walks fall on it in (median [min, max] over "
            "the draws): " + ", ".join(parts) + "." + _teacher_forcing(fitted)]


def _teacher_forcing(fitted: dict) -> str:
    """The teacher-forced replays of the grounding walks (runs saved since the ninth fidelity round),
    one clause per set of inverse models (worlds that differ only in their forward model share one)."""
    groups: dict = {}
    for n, w in fitted.items():
        if all("replay" in d for d in w["draws"]):
            key = json.dumps([d["replay"] for d in w["draws"]], sort_keys=True)
            groups.setdefault(key, []).append(n)
    if not groups:
        return ""
    clauses = []
    for key, names in groups.items():
        t = replay_totals(json.loads(key))
        clauses.append(f"on {t['fell_with_real']} of the {t['real_fell']} walks that fell and on "
                       f"{t['fell_without_real']} of the {t['walks'] - t['real_fell']} that did not with the "
                       f"inverse models of {', '.join(f'`{n}`' for n in names)} (leg joints "
                       f"{t['q_rms_rad']:.3f} rad RMS from the real walk's, ungrounded {t['q_rms_plain_rad']:.3f})")
    return (" Teacher-forced along the same walks (each walk's recorded next states in place of the forward model, "
            "asked of the world's own inverse models at its α: a forward model exactly right for that walk; after "
            "the walk ends the sim runs ungrounded), the sim falls " + "; ".join(clauses) + ".")


def _own_ceiling(s: dict) -> str:
    c = s.get("world_ceiling")
    return "– (deterministic)" if c is None else f"{_f(c['median'])} [{_f(c['min'])}]"


def _mujoco_form(w: dict) -> str:
    """The settings of a MuJoCo mean-physics oracle's form, as words (``""`` where it has none)."""
    parts = ([f"a ground contact of {1000 * w['oracle_compliance']:g} ms"] if w.get("oracle_compliance") else []) \
        + (["no backlash terms"] if w.get("oracle_backlash") is False else [])
    drop = w.get("oracle_drop") or []
    return (f" with {' and '.join(parts)}" if parts else "") \
        + (f"{',' if parts else ''} without {', '.join(f.replace('_', ' ') for f in drop)}" if drop else "")


def _pick(res: dict, w: dict) -> str:
    """The regret of a world's pick, median [worst] over its draws (computed from the saved fitness
    for runs saved before the figure existed)."""
    from experiments.runtime.stats import pick_regret  # lazy: scipy

    v = [pick_regret(d["fitness"], res["real"]["fitness"]) for d in w["draws"]]
    return f"{_f(float(statistics.median(v)), '{:.1f}')} [{_f(max(v), '{:.1f}')}]"


def _optimize(res: dict) -> str:
    lines = ["```text", res["table"], "```", ""]
    if res.get("wall_s"):
        lines.append(f"The run took {res['wall_s'] / 60:.1f} min.")
    gens = [g for g in res.get("generation_s") or [] if g.get("expected_s") is not None]
    if gens:
        lines.append("CMA-ES generations, measured (median [min, max]) against the estimate the run printed before them "
                     "(a trial batch timed in the training world, none falling): " + "; ".join(
                         f"{g['method'].upper()} step {g['step']} {g['median_s']:.1f} s [{g['min_s']:.1f}, {g['max_s']:.1f}] "
                         f"against ~{g['expected_s']:.1f} s" for g in gens) + ".")
    rd = res.get("real_data") or {}
    if rd:
        lines.append("Real data per method: " + "; ".join(
            f"{m.upper()} {d['walks']} walks ({d['walk_seconds']:.0f} s)"
            + (f" + {d['excitation_logs']} excitation logs ({d['excitation_seconds']:.0f} s)" if d["excitation_logs"] else "")
            for m, d in rd.items()) + ".")
    return "\n".join(lines)


def _compare_row_name(r: dict) -> str:
    return f"`{r['world']}` ({r['run']})"


def _compare(res: dict) -> str:
    """``sgatwalk compare``: per panel a summary line and every world in a folded table."""
    from experiments.compare.run import panel_title  # lazy: only this block needs it

    lines = []
    for p in res["panels"]:
        rows = p["rows"]
        ranked = [r for r in rows if r["ranking_target_met"]]
        full = [r for r in rows if r["targets"] and r["targets_met"] == len(r["targets"])]
        best = rows[0]
        name = _compare_row_name
        lines += [f"**{panel_title(p, rho='ρ', times='×')}**: best worst-draw ρ {best['rho_worst']:.2f}, {name(best)}; worst ρ at the "
                  f"target ({ranking_target(p['ceiling']):.2f}): " + (", ".join(name(r) for r in ranked) or "none")
                  + "; SGAT or hybrid worlds that meet every target: " + (", ".join(name(r) for r in full) or "none") + ".",
                  "", f"<details><summary>all {p['worlds']} worlds of this panel</summary>", "",
                  "| world | run (+ results with the same draws) | draws × episodes per gait | ρ: median [worst, best] | median \\|bias\\| "
                  "| bias spread | Brier (median) | regret (median) | worst ρ at the target | SGAT targets met "
                  "| ρ − its run's SGAT: median (draws higher) |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            run = r["run"] + (f" (+{len(r['runs']) - 1})" if len(r["runs"]) > 1 else "")
            v = r.get("vs_sgat")
            eps = "" if r.get("episodes") is None else f" × {r['episodes']}"
            lines.append(f"| `{r['world']}` | {run} | {r['draws']}{eps} | {_f(r['rho_median'])} [{_f(r['rho_worst'])}, "
                         f"{_f(r['rho_best'])}] | {_f(r['abs_bias_median'], '{:.1f}')} | {_f(r['bias_spread'], '{:.1f}')} "
                         f"| {_f(r['brier_median'], '{:.3f}')} | {_f(r['regret_median'], '{:.1f}')} | "
                         f"{'✓' if r['ranking_target_met'] else '✗'} | "
                         + (f"{r['targets_met']}/{len(r['targets'])}" if r["targets"] else "–") + " | "
                         + (f"{v['rho_diff_median']:+.2f} ({v['wins']}/{v['pairs']})" if v else "–") + " |")
        lines += ["", "</details>", ""]
        lines += _compare_paired(p.get("paired") or [])
    if res.get("plot"):
        lines.append(f"![every world's ρ over its draws, per panel]({res['plot']})")
    return "\n".join(lines).rstrip()


def _compare_paired(rows: list[dict]) -> list[str]:
    """A panel's ``paired`` rows of ``sgatwalk compare --paired`` (the same world in two runs), as a table."""
    if not rows:
        return []
    lines = ["The same world in two runs of this panel, paired: ρ(run) − ρ(reference run), the mean over the draws, with "
             "90 % intervals and two-sided p from a bootstrap over the shared real trials and episodes on this panel's "
             "gaits, and over the gaits too for a new panel (`experiments.compare.run.paired_across_runs`):", "",
             "| world | run − reference run | Δρ, mean over the draws | this panel: 90 % interval, p "
             "| a new panel: 90 % interval, p | Δρ per draw |", "|---|---|---|---|---|---|"]

    for r in rows:
        pair = f"{r['run']} − {r['reference_run']}"
        if "skipped" in r:
            lines.append(f"| `{r['world']}` | {pair} | – | not paired: {r['skipped']} | – | – |")
            continue
        lines.append(f"| `{r['world']}` | {pair} | {_paired_cells(r)} |")
    return lines + [""]


def _per_seed_cell(test: dict, seed_level: bool = False) -> str:
    """A Table I test's fitness difference per optimization seed, as a Markdown cell; with
    ``seed_level`` a second cell, the t-test over the seeds (mean [95 % interval], p)."""
    cell = " " + ", ".join(f"{d:+.1f}" for d in test["per_seed_diff"]) + " |"
    if seed_level:
        sl = test.get("seed_level")
        cell += f" {seed_level_interval(sl)} (p = {sl['p_value']:.2g}) |" if sl else " – |"
    return cell


def _test_header(first: str, per_seed: bool, seed_level: bool) -> list[str]:
    """The header rows of a Table I test table: ``first`` (its columns up to the falls) and, as the
    result holds them, the per-seed differences and the t-test over seeds."""
    extra = (" per optimization seed |" if per_seed else "") + (" over seeds: mean [95 % t-interval] (p) |"
                                                                 if seed_level else "")
    return [first + extra, "|---|---|---|---|" + "---|" * (per_seed + seed_level)]


def _table1(res: dict) -> str:
    c = res["config"]
    lines = [f"{c['seeds']} optimization seeds per method; every gait on the same {c['trials']} paired real trials "
             "(mean ± s.e. over seeds × trials; falls with a Wilson 95 % interval).", "",
             "| method | step | n | speed [cm/s] | falls | falls 95 % CI | fitness | fitness the training world gave it |",
             "|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        name = "θ0" if r["method"] == "theta0" else r["method"].upper()
        step = "–" if r["method"] == "theta0" else str(r["step"])
        lo, hi = r["falls_ci95"]
        said = "–" if r.get("predicted_fitness") is None else f"{r['predicted_fitness']:.1f}"
        lines.append(f"| {name} | {step} | {r['n']} | {r['speed_mean']:.2f} ± {r['speed_se']:.2f} | {r['falls']}/{r['n']} "
                     f"| [{lo:.2f}, {hi:.2f}] | {r['fitness_mean']:.2f} ± {r['fitness_se']:.2f} | {said} |")
    per_seed = all(t.get("per_seed_diff") for t in res["tests"])  # saved since the seventeenth round
    sl = per_seed and all("seed_level" in t for t in res["tests"])  # saved since the eighteenth round
    lines += [""] + _test_header("| step | comparison | fitness difference (paired permutation p) | falls: only a / only b "
                                 "(McNemar p) |", per_seed, sl)
    for t in res["tests"]:
        f, x = t["fitness"], t["falls"]
        lines.append(f"| {t['step']} | {t['a'].upper()} vs {'θ0' if t['b'] == 'theta0' else t['b'].upper()} | "
                     f"{f['mean_diff']:+.2f} ± {f['se_diff']:.2f} (p = {f['p_value']:.2g}) | {x['only_a']} / {x['only_b']} "
                     f"(p = {x['p_value']:.2g}) |" + (_per_seed_cell(t, sl) if per_seed else ""))
    if res.get("baseline"):
        b = res["baseline"]
        bper = all(t.get("per_seed_diff") for t in b["tests"])  # saved since the seventeenth round
        bsl = bper and all("seed_level" in t for t in b["tests"])
        lines += ["", f"Against the baseline run (`{b.get('command') or b['path']}`; the same optimization seeds and "
                  "real trials, pairs = seed × trial; a difference > 0: this run's gaits are fitter):", ""]
        lines += _test_header("| step | method | fitness difference (paired permutation p) | falls: only this run / only "
                              "the baseline (McNemar p) |", bper, bsl)
        for t in b["tests"]:
            f, x = t["fitness"], t["falls"]
            vs = f" vs the baseline's {t['baseline_method'].upper()}" if t.get("baseline_method") else ""
            lines.append(f"| {t['step']} | {t['method'].upper()}{vs} | {f['mean_diff']:+.2f} ± {f['se_diff']:.2f} "
                         f"(p = {f['p_value']:.2g}) | {x['only_a']} / {x['only_b']} (p = {x['p_value']:.2g}) |"
                         + (_per_seed_cell(t, bsl) if bper else ""))
    if res["verdict"]:
        lines += ["", "Verdict, as the command prints it:", ""] + [f"* {v}" for v in res["verdict"]]
    if res.get("wall_s"):
        lines += ["", f"The run took {res['wall_s'] / 60:.0f} min."]
    return "\n".join(lines)


def _walk(res: dict) -> str:
    from experiments.cli.walk import format_walk  # lazy: loads the engines

    out = f"```\n{format_walk(res)}\n```"
    if res.get("robot", "nao") != "nao":  # another robot's θ0 is scaled from the NAO's: show what it is
        p = res["params"]
        out += (f"\n\nIts θ0: step period {p['step_period']:.3f} s, step length {100 * p['step_length']:.1f} cm "
                f"(speed {100 * p['step_length'] / p['step_period']:.1f} cm/s planned), feet spacing "
                f"{100 * p['feet_spacing']:.1f} cm, CoM height {100 * p['com_height']:.1f} cm, step height "
                f"{100 * p['step_height']:.1f} cm, CoM/ZMP offsets {100 * p['com_x_offset']:.1f}/"
                f"{100 * p['zmp_offset_x']:.1f} cm, gyro gains {p['gyro_ankle_pitch_gain']:.3f}/"
                f"{p['gyro_ankle_roll_gain']:.3f}/{p['gyro_hip_roll_gain']:.3f} s.")
    return out


def _stress(res: dict) -> str:
    return (f"```text\n{res['table']}\n{res['episodes']} episodes\n```\n\n"
            + (f"The run took {res['wall_s'] / 60:.1f} min on {res['workers']} worker(s)." if res.get("wall_s") else ""))


def _cliff(res: dict) -> str:
    took = f"The sweep took {res['elapsed_s']:.1f} s." if res.get("elapsed_s") else ""
    return f"```text\n{format_table(res['rows'], res['episodes'], res['seed'])}\n```\n\n{took}"


def _stand(res: dict) -> str:
    return f"```text\n{format_stand(res['worlds'])}\n```"


def _gym(res: dict) -> str:
    took = f"The sweep took {res['wall_s'] / 60:.1f} min." if res.get("wall_s") else ""
    return f"```text\n{res['table']}\n```\n\n{took}"


def _bench(res: dict) -> str:
    """``benchmarks/bench_generation.py``: its table, and what a paper-scale optimization costs."""
    from experiments.optimize.run import PRESETS  # lazy: loads torch and the engines

    g = res["worlds"]["grounded"]
    p = PRESETS["paper"]
    gens = p["grounding_steps"] * p["generations"]
    per_gen = g["generation_s_on_workers"] * p["popsize"] * p["episodes_per_candidate"] / res["popsize"]
    return (f"```text\n{res['table']}\n```\n\nSo a paper-scale CMA-ES generation in the grounded sim ({res['popsize']} "
            f"candidates × 1 episode) takes about **{g['generation_s_on_workers']:.0f} s on {res['workers']} idle cores** "
            f"(physics limit {g['physics_limit_s_on_workers']:.0f} s; before batching, one episode at a time, "
            f"{g['single_episode_ms'] * res['popsize'] / 1000 / res['workers']:.0f} s). `sgatwalk optimize --preset paper` "
            f"({p['grounding_steps']} grounding steps × {p['generations']} generations × {p['popsize']} candidates × "
            f"{p['episodes_per_candidate']} episodes of {p['seconds']} s) runs {gens} such generations of "
            f"{p['popsize'] * p['episodes_per_candidate']} episodes per grounded method: about {gens * per_gen / 60:.0f} min "
            f"of CMA-ES per method on {res['workers']} cores, plus its real and sim walks and the model fits.")


def _diagnose(res: dict) -> str:
    """``sgatwalk diagnose --json``: the report it prints, the localisation table cut to its worst rows."""
    from sysid.report import format_report

    out, rows = [], None
    for line in format_report(res).splitlines():
        if line.startswith("LOCALISATION"):
            rows = 0
        elif rows is not None and line.startswith("  ") and not line.lstrip().startswith("channel"):
            rows += 1
            if rows == 4:
                out.append("  ...")
            if rows >= 4:
                continue
        elif rows is not None and not line.startswith("  "):
            rows = None
        out.append(line)
    return "```text\n" + "\n".join(out) + "\n```"



def _excite(res: dict) -> str:
    """``sgatwalk excite --design d-optimal --design-only --json``: the design as the command prints it."""
    from sysid.design import format_design

    return "```text\n" + format_design(res["design"]) + "\n```"


def _benchenvs(res: dict) -> str:
    """``benchmarks/bench_envs.py``: its table, and what a 7.5 s episode costs in each world."""
    cases = res["cases"]
    r = [c["env_over_bare"] for c in cases.values()]
    ep = 7.5 * res["control_hz"]
    sim = [ep / c["env_steps_per_s"] for k, c in cases.items() if k.startswith("sim")]
    real = [ep / c["env_steps_per_s"] for k, c in cases.items() if k.startswith("real")]
    return (f"```text\n{res['text']}\n```\n\nSo env.step runs at {min(r):.2f}–{max(r):.2f} of the bare engine's speed, "
            f"and a 7.5 s episode ({ep:.0f} control steps) costs {min(sim):.1f}–{max(sim):.1f} s in the sim and "
            f"{min(real):.1f}–{max(real):.1f} s in the real world.")


def _benchwalk(res: dict) -> str:
    """``benchmarks/bench_walk.py``: the JSON it prints, and its two headline figures."""
    target = "met" if res["step_us_median"] <= 100 else "missed"
    return (f"```text\n{res['text']}\n```\n\nSo `WalkEngine.step` takes {res['step_us_median']:.0f} µs (median; "
            f"target ≤ 100 µs {target}), and a {res['episode_s']} s walking rollout costs {res['rollout_over_bare']:.1f}× "
            f"the bare `mj_step` time of the same {res['physics_steps']} physics steps.")


def _benchtext(res: dict) -> str:
    """A benchmark whose printed lines say it all (``bench_grounding.py``, ``bench_rerun.py``, ``bench_ground.py``)."""
    return f"```text\n{res['text']}\n```"

def _blind(res: dict) -> str:
    """``benchmarks/sysid_blind.py --save``: the headline figures against the issue's targets."""
    m = res["metrics"]

    def fr(x, target=""):
        if not x["n"]:
            return "–"
        return f"{x['rate']:.0%} ({x['k']}/{x['n']})" + (f" | {target}" if target else "")

    world = {"sim": "MuJoCo sim-as-real", "real": "PyBullet real"}[res["world"]]
    lines = [f"{world}, {'floating' if res['floating'] else 'fixed'} base, {res['excitation']} excitation; "
             f"{m['single']} single-effect trials ({res['seeds']} seeds per class, base seed {res['seed0']}) and "
             f"{m['two']} two-effect trials; {res['logs']} logs × {res['seconds']:g} s each, "
             f"{res['encoder_noise_mrad']:g} mrad encoder noise"
             + (f" (engine-gap calibration on {res['calibration_noise_mrad']:g} mrad logs)"
                if res.get("calibration_noise_mrad", res["encoder_noise_mrad"]) != res["encoder_noise_mrad"] else "")
             + (f"; extra classes {', '.join(res['extra_classes'])}" if res.get("extra_classes") else "")
             + (f"; `sgatwalk diagnose --families {res['diagnose_families']}`" if res.get("diagnose_families") else "")
             + ".", "",
             "| figure | value | target |", "|---|---|---|",
             *([f"| family top-1, detectable effects (a channel ≥ 1.22× its floor before fitting) | "
                f"{fr(m['top1_detectable'], '≥ 90 %')} |",
                f"| family top-1, every trial with an effect | {fr(m['top1'])} | |"] if "top1_detectable" in m else
               [f"| family top-1 (trials with an effect) | {fr(m['top1'], '≥ 90 % on detectable effects')} |"]),
             f"| false positives on clean logs | {fr(m['none_fp'], '≤ 5 %')} |",
             f"| trials with a spurious \"Found\" term | {fr(m['spurious'], '≤ 10 %')} |",
             f"| 95 % interval coverage (every reported term, uncertain ones included) | {fr(m['coverage'], '≥ 85 %')} |",
             f"| precision / recall of terms (family + joint or link) | {fr(m['precision'])} / {fr(m['recall'])} | |",
             f"| median parameter error (non-latency terms found) | {_f(m['param_err_median'], '{:.1%}')} | |",
             f"| median latency error | {_f(m['latency_err_ms'], '{:.2f} ms')} | |",
             f"| two effects: both found | {fr(m['both_found'])} | |",
             *([f"| terms reported as uncertain / compensating: of them true terms | {fr(m['uncertain'])} | |"]
               if "uncertain" in m else []),
             *([f"| {c}: top-1, median parameter error | {fr(v['top1'])}, {_f(v['param_err_median'], '{:.1%}')} | "
                f"{'≥ 80 %, ≤ 25 %' if res['floating'] and c != 'none' else ''} |"
                for c, v in m.get("per_class", {}).items()] if res["floating"] else []),
             f"| diagnose runtime (median) | {_f(m['runtime_s'], '{:.1f} s')} | |"]
    return "\n".join(lines)


RENDERERS = {"excite": _excite, "blind": _blind, "bench": _bench, "diagnose": _diagnose, "gym": _gym, "stand": _stand, "cliff": _cliff, "fidelity": _fidelity, "compare": _compare, "table1": _table1, "optimize": _optimize, "walk": _walk, "stress": _stress,
             "benchenvs": _benchenvs, "benchwalk": _benchwalk, "benchgrounding": _benchtext, "benchrerun": _benchtext,
             "benchlatency": _benchtext, "benchground": _benchtext, "benchoverhead": _benchtext,
             "benchdiagnose": _benchtext, "benchroughness": _benchtext, "benchvisibility": _benchtext,
             "benchenginegap": _benchtext}


def _external(target: str) -> bool:
    """Whether a Markdown link target leaves the repository (``scheme://...`` or ``mailto:``)."""
    return "://" in target or target.startswith("mailto:")


def _relink(body: str, doc_dir: str) -> str:
    """``body`` (Markdown whose relative links are relative to the repository root, as renderers write
    them, e.g. a result's ``plot``) with those links made relative to ``doc_dir``, the folder of the
    document it goes into. In-page anchors and web links stay as they are."""
    if os.path.abspath(doc_dir) == ROOT:
        return body

    def fix(m: re.Match) -> str:
        target = m.group(1)
        if target.startswith("#") or _external(target):
            return m.group(0)
        return "](" + os.path.relpath(os.path.join(ROOT, target), doc_dir).replace(os.sep, "/") + ")"

    return _LINK.sub(fix, body)


def render(text: str, results_dir: str = RESULTS, doc_dir: str = ROOT) -> str:
    """``text`` with every results block regenerated from ``results_dir``; ``doc_dir``: the folder of
    the document ``text`` is (relative links in the blocks are written relative to it).

    Raises:
        FileNotFoundError: a block whose results file is missing. KeyError: no renderer for a block.
    """
    def block(m: re.Match) -> str:
        name = m.group("name")
        kind = name.split("-")[0]
        if kind not in RENDERERS:
            raise KeyError(f"README block {name!r}: no renderer (known: {', '.join(RENDERERS)})")
        path = os.path.join(results_dir, f"{name}.json")
        if not os.path.exists(path):
            raise FileNotFoundError(f"README block {name!r} needs {path}")
        with open(path) as f:
            doc = json.load(f)
        body = f"```console\n$ {doc['command']}\n```\n\n{RENDERERS[kind](doc['result'])}\n"
        mach = doc.get("machine")
        if mach:
            body += (f"\n<sub>Saved by a run on {mach['cpus']} cores; 1-minute load average {mach['load_before']:.1f} at "
                     f"its start, {mach['load_after']:.1f} at its end (for a resumed run: of its last invocation).</sub>\n")
        for key in ("relabelled", "note"):  # a later relabelling; how the run was made (a shared run directory)
            if doc.get(key):
                body += f"\n<sub>{doc[key]}</sub>\n"
        return m.group(1) + _relink(body, doc_dir) + m.group(4)

    return _BLOCK.sub(block, text)


def run_and_save(name: str, args: list[str]) -> str:
    """Run ``sgatwalk ARGS --json --timings`` in this process and save its result as ``docs/results/NAME.json``."""
    machine = {"cpus": os.cpu_count(), "load_before": os.getloadavg()[0]}
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = cli_main([*args, "--json", "--timings"])
    if rc != 0:
        raise SystemExit(f"sgatwalk {' '.join(args)} failed with exit status {rc}")
    result = json.loads(buf.getvalue().strip().splitlines()[-1])
    machine["load_after"] = os.getloadavg()[0]
    return save(name, "sgatwalk " + " ".join(args), result, machine=machine)


_FENCE = re.compile(r"^(```|~~~)")
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
_ANCHOR_TAG = re.compile(r'<a\s+(?:id|name)="([^"]+)"')
_LINK = re.compile(r"\]\(([^)\s]+)\)")


def github_slug(heading: str) -> str:
    """The anchor GitHub gives a Markdown heading: lower case, every character but letters, digits,
    ``-``, ``_`` and spaces dropped (backticks, punctuation, dashes such as "—"), spaces turned into
    ``-`` (GitHub Flavored Markdown, "Section links"; its ``github-slugger`` package)."""
    s = heading.strip().lower()
    s = "".join(c for c in s if c.isalnum() or c in "-_ ")
    return s.replace(" ", "-")


def anchors(text: str) -> set[str]:
    """Every in-page anchor of a Markdown text: heading slugs (repeats get ``-1``, ``-2``, ... as on
    GitHub) and explicit ``<a id="...">`` tags; headings inside code fences do not count."""
    out, seen, fenced = set(), {}, False
    for line in text.splitlines():
        if _FENCE.match(line):
            fenced = not fenced
            continue
        if fenced:
            continue
        out.update(_ANCHOR_TAG.findall(line))
        m = _HEADING.match(line)
        if m:
            slug = github_slug(m.group(2))
            n = seen.get(slug, 0)
            seen[slug] = n + 1
            out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def broken_links(text: str, root: str = ROOT) -> list[str]:
    """Relative links of a Markdown text that lead nowhere: ``(#anchor)`` without that anchor in the text
    (:func:`anchors`), ``(path)`` / ``(path#anchor)`` without the file under ``root`` (the folder of the
    text's file), and ``(file.md#anchor)`` where that Markdown file gives no such anchor. Web links
    (``scheme://``) and ``mailto:`` are not checked. Returns the link targets, in order, once each."""
    have = anchors(text)
    other: dict[str, set[str]] = {}
    bad: list[str] = []
    for target in _LINK.findall(text):
        if _external(target) or target in bad:
            continue
        path, _, frag = target.partition("#")
        full = os.path.join(root, path)
        if (not path and frag not in have) or (path and not os.path.exists(full)):
            bad.append(target)
        elif path and frag and path.endswith(".md"):
            if full not in other:
                with open(full) as f:
                    other[full] = anchors(f.read())
            if frag not in other[full]:
                bad.append(target)
    return bad


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["run"]:
        if len(argv) < 3 or "--" not in argv:
            print("usage: python -m tools.readme run NAME -- SGATWALK_ARGS...", file=sys.stderr)
            return 2
        k = argv.index("--")
        print(run_and_save(argv[1], argv[k + 1:]))
        return 0
    ap = argparse.ArgumentParser(description="render docs/results/*.json into README.md and the other documents")
    ap.add_argument("--check", action="store_true",
                    help="exit 1 if a document differs from the rendering or links to what is not there")
    ap.add_argument("--readme", default=None,
                    help="one Markdown file to render or check (default: every document of DOCUMENTS)")
    args = ap.parse_args(argv)
    paths = [args.readme] if args.readme else [os.path.join(ROOT, d) for d in DOCUMENTS]
    rc = 0
    for path in paths:
        with open(path) as f:
            text = f.read()
        doc_dir = os.path.dirname(os.path.abspath(path))
        new = render(text, doc_dir=doc_dir)
        name = os.path.relpath(path, ROOT) if not args.readme else path
        if args.check:
            if new != text:
                names = [m.group("name") for m in _BLOCK.finditer(text)
                         if render(m.group(0), doc_dir=doc_dir) != m.group(0)]
                print(f"{name} is stale in block(s): {', '.join(names) or '?'}; run python -m tools.readme",
                      file=sys.stderr)
                rc = 1
            bad = broken_links(text, doc_dir)
            if bad:
                print(f"{name} links to what is not there: {', '.join(bad)}", file=sys.stderr)
                rc = 1
        elif new != text:
            atomic_write_text(path, new)
    return rc


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
