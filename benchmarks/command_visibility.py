"""Can the inverse model see the command? How much of the exploration noise on a grounding step's sim
walks their states reveal, lead by lead, in the plain sim and in the identified sim side by side.

For every draw of a ``sgatwalk fidelity`` run directory and every set of grounding walks its grounded
worlds were fitted on (the walks of θ0 with exploration noise on the leg targets: in the plain sim
for ``gat`` and ``sgat``, in the identified sim for ``hybrid``; worlds that share their walks share a
row), the walks go through :func:`sgat.grounding.command_visibility`: per lead k the
cross-validated R² with which a linear map of the state history (the world's ``history`` frames)
and the state change ``s_{t+k} − s_t`` (the inputs of the linear inverse model) recovers the noise
on the applied leg targets. The paper's inverse model works at lead 1. Beside it, the actuation
latency the draw's diagnosis identified (``identified/d<d>/*/report.json``): a command takes effect
that much later in the identified sim. Below the draws, the median R² over them per lead.

Reads only the run directory (the walks it recorded and the reports its identification wrote): no
new simulation; it takes seconds. Prints a table, or one JSON object with ``--json`` (its ``"text"``
the table); progress goes to stderr.

Usage: ``python benchmarks/command_visibility.py --run runs/fidelity-seed0 [--leads 1 2 3 4 5] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def walk_sets(worlds: list[str]) -> dict:
    """The sets of grounding walks of a fidelity run's grounded worlds: ``{(sim, walks, noise, history):
    [world names]}``, ``sim`` ``"sim"`` (the plain sim) or ``"identified"`` (hybrid's). Worlds that do
    not parse (an older vocabulary) are named on stderr and left out."""
    from experiments.runtime.worlds import parse_world

    sets: dict = {}
    for text in worlds:
        try:
            spec = parse_world(text)
        except ValueError as exc:
            print(f"[command_visibility] world {text!r} left out: {exc}", file=sys.stderr, flush=True)
            continue
        if not spec.grounded:
            continue
        key = ("identified" if spec.needs_identification else "sim", int(spec.get("sim")), float(spec.get("explore")),
               int(spec.get("history")))
        sets.setdefault(key, []).append(spec.name)
    return sets


def walk_paths(run: str, key: tuple, seed: int, draw: int) -> list[str]:
    """The Parquet paths of a draw's grounding walks of one set (as ``experiments.fidelity.prepare``
    names them under ``data/``)."""
    from experiments.fidelity.config import GROUND_SIM
    from experiments.runtime.seeds import derive_seeds

    sim, n, noise, _ = key
    tag = f"{'ident' if sim == 'identified' else 'sim'}_d{draw}_n{noise:g}"
    return [os.path.join(run, "data", f"{tag}_{s}.parquet") for s in derive_seeds(seed, GROUND_SIM, draw, n=n)]


def build_parser() -> argparse.ArgumentParser:
    """The command line: the run directory, the leads, ``--json``."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="Reads a fidelity run directory only; takes seconds.")
    ap.add_argument("--run", required=True, help="a sgatwalk fidelity run directory (a NAO run with grounded worlds)")
    ap.add_argument("--leads", type=int, nargs="+", default=[1, 2, 3, 4, 5],
                    help="leads k [control steps] (default 1 2 3 4 5)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (its \"text\": the table)")
    return ap


def set_labels(sets: dict) -> dict:
    """{set key: its row label}: the sim's name (``sim`` or ``identified``) where one set walked in it,
    else also the walks, noise [rad] and history (e.g. ``sim 4x0.02rad h2``)."""
    kinds = [k[0] for k in sets]
    return {k: k[0] if kinds.count(k[0]) == 1 else f"{k[0]} {k[1]}x{k[2]:g}rad h{k[3]}" for k in sets}


def draw_row(run: str, cfg: dict, d: int, sets: dict, labels: dict, leads: list[int], layout) -> dict:
    """One draw's figures: ``latency_ms`` (the draw's identified actuation latency [ms], where its
    identification wrote reports) and, per set label whose walks are all there (2 or more),
    :func:`sgat.grounding.command_visibility`'s result at ``leads``; progress on stderr."""
    from envs import Recording
    from experiments.runtime.grounding import identified_latency, walk_spec
    from sgat.grounding import command_visibility

    row = {}
    reps = [os.path.join(run, "identified", f"d{d}", stage, "report.json") for stage in ("fixed", "floating")]
    reps = [r for r in reps if os.path.exists(r)]
    if reps:
        row["latency_ms"] = 1000 * identified_latency(reps)
    for key in sets:
        paths = walk_paths(run, key, int(cfg["seed"]), d)
        if len(paths) < 2 or not all(os.path.exists(p) for p in paths):
            continue
        row[labels[key]] = command_visibility([Recording.from_parquet(p) for p in paths], layout,
                                              walk_spec(key[3], "nao"), leads)
        print(f"[command_visibility] draw {d}, {labels[key]}: R² by lead "
              + ", ".join(f"{v:+.2f}" for v in row[labels[key]]["r2"]), file=sys.stderr, flush=True)
    return row


def measure(run: str, cfg: dict, sets: dict, leads: list[int]) -> tuple[dict, dict]:
    """The visibility of every draw's sets of walks in the run directory ``run`` (its ``config.json``
    read as ``cfg``; ``sets`` from :func:`walk_sets`).

    Returns:
        ({"run", "leads", "control_dt_ms", "sets": {label: {"sim", "walks", "explore_rad", "history",
        "worlds"}}, "draws": {draw: :func:`draw_row`'s row, for draws with a set measured}},
        :func:`set_labels`' labels).
    """
    from common.defaults import CONTROL_DT
    from envs import ObservationLayout
    from robots import get_robot

    labels = set_labels(sets)
    layout = ObservationLayout(get_robot("nao"))
    out = {"run": os.path.basename(os.path.normpath(run)), "leads": leads, "control_dt_ms": 1000 * CONTROL_DT,
           "sets": {labels[k]: {"sim": k[0], "walks": k[1], "explore_rad": k[2], "history": k[3], "worlds": w}
                    for k, w in sets.items()},
           "draws": {}}
    for d in range(int(cfg["data_seeds"])):
        row = draw_row(run, cfg, d, sets, labels, leads, layout)
        if any(lab in row for lab in labels.values()):
            out["draws"][str(d)] = row
    return out, labels


def summarize(draws: dict, labels: dict, leads: list[int]) -> dict:
    """Per set label measured in some draw: {"draws", "median_r2" (per lead, over the draws),
    "best_lead_of_median", "lead1_r2_max" (R² of the first lead, best draw), "best_r2_min" (the best
    lead's R², worst draw)}."""
    summary = {}
    for lab in labels.values():
        got = [row[lab] for row in draws.values() if lab in row]
        if not got:
            continue
        med = [statistics.median(g["r2"][i] for g in got) for i in range(len(leads))]
        summary[lab] = {"draws": len(got), "median_r2": med,
                        "best_lead_of_median": leads[max(range(len(med)), key=med.__getitem__)],
                        "lead1_r2_max": max(g["r2"][0] for g in got), "best_r2_min": min(max(g["r2"]) for g in got)}
    return summary


def table(out: dict, labels: dict, leads: list[int]) -> str:
    """The printed table of :func:`measure`'s figures with ``out["summary"]`` (:func:`summarize`): the
    sets, a row per draw and set (latency, R² per lead, best lead), a median row per set."""
    lines = [f"{out['run']}: grounding walks of θ0 per draw, cross-validated R² of their exploration noise on the leg "
             f"targets from the state history and s_(t+k) - s_t, by lead k [control steps of {out['control_dt_ms']:g} ms]",
             *(f"  {lab}: {s['walks']} walks in the {'identified' if s['sim'] == 'identified' else 'plain'} sim, noise "
               f"{s['explore_rad']:g} rad, history {s['history']} (worlds {', '.join(s['worlds'])})"
               for lab, s in out["sets"].items()),
             f"{'draw':>6s} {'walks':>22s} {'latency':>9s}  " + " ".join(f"{'k = ' + str(k):>7s}" for k in leads)
             + "  best k"]
    for d, row in out["draws"].items():
        for key, lab in labels.items():
            if lab not in row:
                continue
            lat = row.get("latency_ms") if key[0] == "identified" else None
            lat_s = "none" if key[0] == "sim" else "–" if lat is None else f"{lat:.1f} ms"
            lines.append(f"{d:>6s} {lab:>22s} {lat_s:>9s}  " + " ".join(f"{v:+7.2f}" for v in row[lab]["r2"])
                         + f"  {row[lab]['best_lead']:>6d}")
    for lab, summ in out["summary"].items():
        lines.append(f"{'median':>6s} {lab:>22s} {'':>9s}  " + " ".join(f"{v:+7.2f}" for v in summ["median_r2"])
                     + f"  {summ['best_lead_of_median']:>6d}")
    lines.append("R² near 0 or below: the state change at that lead says nothing of the command (a linear inverse "
                 "model there returns the commands it saw for similar states)")
    return "\n".join(lines)


def main(argv=None) -> int:
    """Parse the command line, measure the run directory's walks, print the table (or JSON with
    ``--json``); returns 0. Errors in the options or the run directory exit through ``argparse``
    (status 2)."""
    ap = build_parser()
    args = ap.parse_args(argv)
    if min(args.leads) < 1:
        ap.error("--leads must be >= 1")
    cfg_path = os.path.join(args.run, "config.json")
    if not os.path.exists(cfg_path):
        ap.error(f"{args.run!r} is not a fidelity run directory (no config.json)")
    with open(cfg_path) as f:
        cfg = json.load(f)
    if cfg.get("robot", "nao") != "nao":
        ap.error("the walks' layout is the NAO's: run it on a NAO fidelity run")
    sets = walk_sets(list(cfg.get("worlds", [])))
    if not sets:
        ap.error(f"{args.run!r}: no grounded world (gat, sgat, hybrid) in its config")
    out, labels = measure(args.run, cfg, sets, args.leads)
    if not out["draws"]:
        ap.error(f"no complete set of grounding walks (2 or more per draw) found in {args.run!r}/data")
    out["summary"] = summarize(out["draws"], labels, args.leads)
    out["text"] = table(out, labels, args.leads)
    print(json.dumps(out) if args.json else out["text"], flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
