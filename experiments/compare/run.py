"""Every training world of several fidelity runs in one ranking (``sgatwalk compare``).

A fidelity run (:mod:`experiments.fidelity.run`) measures a handful of worlds on one gait panel; a
variant study is a dozen runs on the same panel. This reads their results and ranks every world of
every run **per panel**: runs count as one panel only when they walked the same gaits on the same
real trials with the same outcome (the gait names, trial count, profile and every gait's real
fitness agree), so their worlds are scored against the same real fitness and their figures compare.
The same seed on another machine kind is another panel (the real trials differ in their last bits,
and falls amplify that).

Per world: its episodes per gait, Spearman ρ with the real fitness over the draws (median, worst,
best), median |bias| and the bias spread over the draws, the median Brier score, the median regret of
its pick, and for SGAT and hybrid worlds its ρ against its run's first SGAT world draw by draw (draw d
of both is fitted on the same real grounding walks: a paired comparison). With ``paired``, a world
that two runs of a panel measured under one name is also tested across the runs
(:func:`paired_across_runs`: the paired bootstrap of :func:`experiments.runtime.stats.paired_test` on
the real trials and episodes they share).
"""

from __future__ import annotations

import glob
import hashlib
import json
import math
import os
import statistics

import numpy as np

from experiments.fidelity.results import FidelityResult, check_result, is_fidelity_result
from experiments.runtime.rundir import distinct_suffixes
from experiments.runtime.stats import format_ci, p_text, paired_test, pick_regret

from experiments.compare import PLOT_ROWS  # noqa: E402 - one definition, beside the package docstring
#: How many decimals of every gait's real fitness decide whether two runs share a panel.
PANEL_DECIMALS = 9


def _read(path: str):
    try:
        with open(path) as f:
            return json.load(f)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON ({exc})") from None


def load_results(paths: list[str]) -> tuple[list[tuple[str, str, dict]], list[str]]:
    """Fidelity results from files and folders.

    Args:
        paths: each a fidelity run directory (its ``fidelity.json`` beside ``config.json``), a
            ``fidelity.json``, a saved README result (``{"command", "result"}``,
            ``docs/results/NAME.json``), or a folder of such results or of run directories (every
            ``*.json`` in it and every ``*/fidelity.json`` below it; other JSON files there are
            skipped).

    Returns:
        ``([(label, path, result)], [skipped paths])``; the label is the run directory's name, or the
        file's name without ``.json``; labels that two results share are lengthened by their parent
        folders until they differ.

    Raises:
        FileNotFoundError: a path that does not exist. ValueError: a file that is not JSON, a file named
        directly that is not a fidelity result, a fidelity result with a malformed world (named), a
        folder with none, or a result listed twice.
    """
    out, skipped, seen = [], [], set()

    def add(path: str, strict: bool) -> bool:
        doc = _read(path)
        res = doc.get("result") if isinstance(doc, dict) and "command" in doc and "result" in doc else doc
        if not is_fidelity_result(res):
            if strict:
                raise ValueError(f"{path}: not a fidelity result (needs 'real', 'worlds' and 'gaits'; "
                                 "sgatwalk fidelity writes fidelity.json)")
            skipped.append(path)
            return False
        check_result(res, path)
        real = os.path.realpath(path)
        if real in seen:
            raise ValueError(f"{path}: given twice")
        seen.add(real)
        out.append((path, res))
        return True

    for p in paths:
        if not os.path.exists(p):
            raise FileNotFoundError(f"{p}: no such file or directory")
        if os.path.isdir(p):
            own = os.path.join(p, "fidelity.json")
            if os.path.exists(own) and os.path.exists(os.path.join(p, "config.json")):  # a run directory
                add(own, True)
                continue
            found = [add(f, False) for f in sorted(glob.glob(os.path.join(p, "*.json")))]
            found += [add(f, True) for f in sorted(glob.glob(os.path.join(p, "*", "fidelity.json")))]
            if not any(found):
                raise ValueError(f"{p}: no fidelity results in this folder (fidelity.json of a run directory, "
                                 "or saved README results)")
        else:
            add(p, True)
    return [(lab, p, r) for lab, (p, r) in zip(_labels([p for p, _ in out]), out)], skipped


def _labels(paths: list[str]) -> list[str]:
    """A short name per result path: the run directory for a ``fidelity.json``, else the file name
    without ``.json``; lengthened by parent folders where two would be the same."""
    parts = []
    for p in paths:
        ps = os.path.abspath(p).split(os.sep)
        if ps[-1] == "fidelity.json":
            ps = ps[:-1]
        elif ps[-1].endswith(".json"):
            ps[-1] = ps[-1][:-5]
        parts.append(ps)
    return distinct_suffixes(parts)


def panel_key(res: dict) -> str:
    """Identity of a result's gait panel and real trials: SHA-256 (first 12 hex digits) of the gait
    names, the trial count, the real world's profile and every gait's real fitness (rounded to
    :data:`PANEL_DECIMALS`)."""
    cfg = res.get("config", {})
    ident = {"gaits": list(res["gaits"]), "trials": res["real"].get("trials"), "profile": cfg.get("profile", "real"),
             "fitness": [round(float(x), PANEL_DECIMALS) for x in res["real"]["fitness"]]}
    return hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()[:12]


def _median(v):
    return float(statistics.median(v)) if v else math.nan


def first_world(res: FidelityResult, kind: str) -> str | None:
    """The first world of ``kind`` that a fidelity result lists (its reference world of that kind), or None."""
    return next((n for n, w in res["worlds"].items() if w.get("kind", n.split(":")[0]) == kind), None)


def world_row(res: FidelityResult, name: str) -> dict:
    """One world of one result, the figures :func:`compare` ranks by (module docstring)."""
    w = res["worlds"][name]
    draws = w["draws"]
    rhos = [d["rho"] for d in draws if d["rho"] is not None and math.isfinite(d["rho"])]
    kind = w.get("kind", name.split(":")[0])
    row = {"world": name, "kind": kind, "draws": len(draws), "episodes": w.get("episodes"),
           "rho_median": _median(rhos), "rho_worst": min(rhos) if rhos else math.nan,
           "rho_best": max(rhos) if rhos else math.nan,
           "abs_bias_median": float(w["summary"]["abs_bias_median"]),
           "bias_spread": float(w["summary"]["bias"]["spread"]),
           "brier_median": _median([d["brier"] for d in draws]),
           "regret_median": _median([pick_regret(d["fitness"], res["real"]["fitness"]) for d in draws])}
    ref = first_world(res, "sgat")
    if kind in ("sgat", "hybrid") and ref and ref != name and len(res["worlds"][ref]["draws"]) == len(draws) > 1:
        pairs = [(d["rho"], e["rho"]) for d, e in zip(draws, res["worlds"][ref]["draws"])
                 if d["rho"] is not None and e["rho"] is not None]
        row["vs_sgat"] = {"reference": ref, "rho_diff_median": _median([a - b for a, b in pairs]),
                          "wins": sum(a > b for a, b in pairs), "pairs": len(pairs)}
    return row


def _measurement(name: str, world: dict) -> str:
    """A world's identity as a measurement: its name and every draw's fitness per gait (the same
    world read from two results that share a run directory is one row)."""
    draws = [[round(float(x), PANEL_DECIMALS) for x in d["fitness"]] for d in world["draws"]]
    return hashlib.sha256(json.dumps([name, draws]).encode()).hexdigest()


def compare(results: list[tuple[str, str, dict]], kinds: tuple[str, ...] | None = None, top: int | None = None,
            paired: bool = False, n_boot: int = 1000) -> dict:
    """Rank every world of ``results`` (:func:`load_results`) per panel.

    Args:
        results: ``[(label, path, fidelity result)]``.
        kinds: keep only worlds of these kinds (None: all).
        top: keep the first ``top`` rows of each panel (None: all).
        paired: also test, per panel, every world that two or more runs measured differently under
            the same name (:func:`paired_across_runs`; ``n_boot`` bootstrap replicates).

    Returns:
        ``{"panels": [{"key", "seed", "gaits", "trials", "profile", "ceiling", "real_fitness_mean",
        "real_fall_rate", "runs": [labels], "worlds": n, "rows": [world_row + "run", "runs"]}]}``,
        panels in the order their first run was given; rows by worst ρ over the draws (best first),
        then by median ρ. A world that several results carry with the same fitness on every draw
        (runs that share a run directory) is one row: ``run`` is the first result, ``runs`` all.
        With ``paired``, each panel also has ``"paired"``: :func:`paired_across_runs`'s rows.

    Raises:
        ValueError: ``top`` < 1 or ``n_boot`` < 1.
    """
    if top is not None and top < 1:
        raise ValueError(f"top must be >= 1, got {top}")
    if n_boot < 1:
        raise ValueError(f"n_boot must be >= 1, got {n_boot}")
    panels: dict[str, dict] = {}
    for label, path, res in results:
        key = panel_key(res)
        cfg = res.get("config", {})
        p = panels.setdefault(key, {
            "key": key, "seed": cfg.get("seed"), "gaits": len(res["gaits"]), "trials": res["real"].get("trials"),
            "profile": cfg.get("profile", "real"), "ceiling": res["real"].get("ceiling"),
            "real_fitness_mean": float(sum(res["real"]["fitness"]) / len(res["real"]["fitness"])),
            "real_fall_rate": float(sum(res["real"]["fall_rate"]) / len(res["real"]["fall_rate"])),
            "runs": [], "rows": []})
        p["runs"].append(label)
        for n, w in res["worlds"].items():
            if kinds is not None and w.get("kind", n.split(":")[0]) not in kinds:
                continue
            sig = _measurement(n, w)
            same = next((r for r in p["rows"] if r["_sig"] == sig), None)
            if same is not None:  # one measurement that several runs carry (a shared run directory)
                same["runs"].append(label)
                continue
            p["rows"].append({"run": label, "runs": [label], **world_row(res, n), "_sig": sig, "_src": (res, n)})

    def order(r):
        bad = -math.inf
        return (-(r["rho_worst"] if math.isfinite(r["rho_worst"]) else bad),
                -(r["rho_median"] if math.isfinite(r["rho_median"]) else bad), r["run"], r["world"])

    out = []
    for p in panels.values():
        if paired:
            p["paired"] = paired_across_runs(p["rows"], n_boot=n_boot)
        for r in p["rows"]:
            del r["_sig"], r["_src"]
        p["rows"].sort(key=order)
        p["worlds"] = len(p["rows"])
        if top is not None:
            p["rows"] = p["rows"][:top]
        out.append(p)
    return {"panels": out}


def paired_across_runs(rows: list[dict], *, n_boot: int = 1000, seed: int = 0) -> list[dict]:
    """Paired tests of one world measured by two runs of a panel: what changed between the runs (the
    code, a setting) moved its ranking by how much, beyond the noise?

    For every world name that two or more rows of the panel carry (in the runs' order), each later
    row is tested against the first: the mean over the draws of ρ_row − ρ_first with a 90 %
    interval and two-sided p from :func:`experiments.runtime.stats.paired_test` (this panel's gaits kept:
    ``ci_panel``, ``p_value_panel``; the gaits resampled too, for a new panel: ``ci``, ``p_value``). It pairs what the design pairs only where the runs share it: the same real trials
    (every trial's fitness equal, not only the gaits' means), the same episode seeds (a fidelity
    run's are keyed by its seed alone) and draw d of both fitted on the same real data (the runs'
    seeds). A pair whose real trials differ, or that lacks per-episode fitness, is listed with
    ``"skipped"`` saying why.

    Args:
        rows: a panel's rows of :func:`compare`, each with ``_src`` = (result, world name).
        n_boot: bootstrap replicates; seed: of the resampling.

    Returns:
        ``[{"world", "run", "reference_run", "diff", "per_draw", "ci", "p_value", "ci_panel",
        "p_value_panel", "n_boot"}]`` or ``[{"world", "run", "reference_run", "skipped"}]``.
    """
    groups: dict[str, list[dict]] = {}
    for r in rows:
        groups.setdefault(r["world"], []).append(r)
    out = []
    for name, rs in groups.items():
        ref = rs[0]
        ref_res, ref_name = ref["_src"]
        for r in rs[1:]:
            res, n = r["_src"]
            row = {"world": name, "run": r["run"], "reference_run": ref["run"]}
            ta, tb = res["real"].get("fitness_trials"), ref_res["real"].get("fitness_trials")
            have = all("fitness_episodes" in d for x, m in ((res, n), (ref_res, ref_name)) for d in x["worlds"][m]["draws"])
            if ta is None or tb is None or not have:
                out.append({**row, "skipped": "no per-episode fitness"})
                continue
            if not np.array_equal(ta, tb):
                out.append({**row, "skipped": "the runs' real trials differ trial by trial"})
                continue
            ea = np.array([d["fitness_episodes"] for d in res["worlds"][n]["draws"]])
            eb = np.array([d["fitness_episodes"] for d in ref_res["worlds"][ref_name]["draws"]])
            if len(ea) != len(eb) and 1 not in (len(ea), len(eb)):
                out.append({**row, "skipped": f"{len(ea)} draws against {len(eb)}"})
                continue
            out.append({**row, **paired_test(ea, eb, ta, n_boot=n_boot, seed=seed)})
    return out


def panel_title(p: dict, rho: str = "rho", times: str = "x") -> str:
    """One line naming a panel: seed, gaits, trials, profile, real outcome, ceiling, runs (``rho`` and
    ``times``: how to write ρ and ×)."""
    return (f"seed {p['seed']}, {p['gaits']} gaits {times} {p['trials']} real trials, profile {p['profile']}: real fitness "
            f"{p['real_fitness_mean']:+.2f} on average, {100 * p['real_fall_rate']:.0f} % falls, ceiling of {rho} "
            f"{p['ceiling']:.2f} (panel {p['key']}; {len(p['runs'])} run{'s' if len(p['runs']) != 1 else ''}, "
            f"{p['worlds']} worlds)")


def _vs(r: dict) -> str:
    v = r.get("vs_sgat")
    return "-" if not v else f"{v['rho_diff_median']:+.2f} ({v['wins']}/{v['pairs']})"


def _episodes(r: dict) -> str:
    """A row's episodes per gait, '-' for results saved before the field."""
    return "-" if r.get("episodes") is None else str(r["episodes"])


def format_compare(res: dict) -> str:
    """The ranking as text: one table per panel."""
    lines = []
    for p in res["panels"]:
        lines += [panel_title(p),
                  f"  {'world':40s} {'run (+ others with the same draws)':33s} {'draws':>5s} {'ep.':>4s} {'rho median [worst, best]':>26s} {'|bias|':>6s} "
                  f"{'spread':>6s} {'Brier':>6s} {'regret':>6s} {'rho - sgat (wins)':>18s}"]
        for r in p["rows"]:
            run = r["run"] + (f" (+{len(r['runs']) - 1})" if len(r["runs"]) > 1 else "")
            lines.append(f"  {r['world']:40s} {run:33s} {r['draws']:>5d} {_episodes(r):>4s} "
                         f"{r['rho_median']:>8.2f} [{r['rho_worst']:5.2f}, {r['rho_best']:5.2f}] "
                         f"{r['abs_bias_median']:>6.1f} {r['bias_spread']:>6.1f} {r['brier_median']:>6.3f} "
                         f"{r['regret_median']:>6.1f} {_vs(r):>18s}")
        if len(p["rows"]) < p["worlds"]:
            lines.append(f"  ... {p['worlds'] - len(p['rows'])} more")
        lines += _format_paired(p.get("paired") or [])
        lines.append("")
    return "\n".join(lines).rstrip()


def _format_paired(rows: list[dict]) -> list[str]:
    """The text lines of a panel's ``paired`` rows (none when it has none)."""
    if not rows:
        return []
    lines = ["  the same world in two runs, paired (run - reference run, the mean of rho's difference over the draws; 90% "
             "bootstrap intervals and two-sided p over the real trials and episodes on this panel, and over the gaits "
             "too, for a new panel):",
             f"    {'world':28s} {'run - reference run':44s} {'diff':>5s} {'this panel':>16s} {'p':>6s} {'a new panel':>16s} {'p':>6s}"]
    for r in rows:
        pair = f"{r['run']} - {r['reference_run']}"
        if "skipped" in r:
            lines.append(f"    {r['world']:28s} {pair:44s} skipped: {r['skipped']}")
            continue
        lines.append(f"    {r['world']:28s} {pair:44s} {r['diff']:+5.2f} {format_ci(r['ci_panel']):>16s} "
                     f"{p_text(r['p_value_panel'], r['n_boot']):>6s} {format_ci(r['ci']):>16s} {p_text(r['p_value'], r['n_boot']):>6s}")
    return lines


#: Colour per world kind in :func:`plot` (matplotlib's tab10).
_KIND_COLOURS = {"sim": "tab:gray", "ane": "tab:brown", "gat": "tab:orange", "sgat": "tab:blue",
                 "identified": "tab:green", "hybrid": "tab:purple", "real": "black"}


def plot(res: dict, path: str, *, max_rows: int = PLOT_ROWS) -> None:
    """One panel per gait panel: each world's ρ over its draws (line from worst to best, dot at the
    median), best worst-draw first, coloured by kind, with the real trials' ceiling (dashed). At most
    ``max_rows`` worlds per panel are drawn (the best; the title says how many were left out).

    Raises:
        ValueError: no rows to draw.
    """
    import matplotlib  # lazy: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib
    from common.files import atomic_path

    panels = [p for p in res["panels"] if p["rows"]]
    if not panels:
        raise ValueError("nothing to plot: no worlds")
    heights = [min(len(p["rows"]), max_rows) for p in panels]
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, sum(0.2 * h + 1.0 for h in heights)), squeeze=False,
                             height_ratios=[0.2 * h + 1.0 for h in heights], layout="constrained")
    for ax, p, h in zip(axes[:, 0], panels, heights):
        rows = p["rows"][:h]
        y = list(range(h))[::-1]
        for yi, r in zip(y, rows):
            c = _KIND_COLOURS.get(r["kind"], "tab:cyan")
            ax.plot([r["rho_worst"], r["rho_best"]], [yi, yi], color=c, lw=2, alpha=0.7)
            ax.plot([r["rho_median"]], [yi], "o", color=c, ms=4)
        ax.axvline(p["ceiling"], color="0.3", ls="--", lw=1, label=f"ceiling {p['ceiling']:.2f}")
        ax.set_yticks(y, [f"{r['world']}  ({r['run']}" + (f" +{len(r['runs']) - 1}" if len(r["runs"]) > 1 else "")
                          + (f"; {r['episodes']} ep." if r.get("episodes") not in (None, 1) else "") + ")"
                          for r in rows], fontsize=6)
        ax.set_ylim(-0.7, h - 0.3)
        ax.set_xlim(min(0.0, min(r["rho_worst"] for r in rows if math.isfinite(r["rho_worst"])) if any(
            math.isfinite(r["rho_worst"]) for r in rows) else 0.0) - 0.05, 1.0)
        ax.set_xlabel("Spearman ρ with real fitness over the draws (worst to best; dot: median)", fontsize=8)
        more = p["worlds"] - h
        ax.set_title(f"seed {p['seed']}, {p['gaits']} gaits × {p['trials']} real trials, profile {p['profile']} (panel "
                     f"{p['key']}): {p['worlds']} worlds" + (f", the best {h} drawn" if more else ""), fontsize=8)
        from matplotlib.lines import Line2D  # lazy: matplotlib

        kinds = list(dict.fromkeys(r["kind"] for r in rows))
        handles = ax.get_legend_handles_labels()[0] + [
            Line2D([], [], color=_KIND_COLOURS.get(k, "tab:cyan"), marker="o", ms=4, lw=2, label=k) for k in kinds]
        ax.legend(handles=handles, fontsize=6, loc="lower right")
        ax.grid(axis="x", alpha=0.3)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


__all__ = ["PLOT_ROWS", "compare", "format_compare", "load_results", "paired_across_runs", "panel_key", "panel_title", "plot",
           "world_row"]
