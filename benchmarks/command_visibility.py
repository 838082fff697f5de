"""Can the inverse model see the command? The exploration noise a grounding step's sim walks reveal, per lead.

For every draw of a ``sgatwalk fidelity`` run directory, the grounding walks of θ0 with exploration
noise on which the inverse models ``f_sim^-1`` were fitted, in the plain sim (the worlds ``gat`` and
``sgat``) and in the identified sim (``hybrid``), go through
:func:`sgat.grounding.command_visibility`: per lead k the cross-validated R² with which a linear map
of the state history and the state change ``s_{t+k} − s_t`` (the inputs of the linear inverse model)
recovers the noise on the applied leg targets. The paper's inverse model works at lead 1. Beside it,
the actuation latency the draw's diagnosis identified (``identified/d<d>/*/report.json``), in
control steps: a command takes effect that much later in the identified sim.

Reads only the run directory (the walks it recorded and the reports its identification wrote): no
new simulation. Prints a table (or one JSON object with ``--json``); ``--save NAME`` also writes
``docs/results/NAME.json`` for the README.

Usage: ``python benchmarks/command_visibility.py --run runs/fidelity-seed0 [--walks 4] [--save NAME]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

#: The sim walks' tag of each world kind in a fidelity run's ``data/`` (plain sim; identified sim without
#: the confounded contact terms, the default hybrid's), before ``_d<draw>_n<noise>``.
TAGS = {"sim": "sim", "identified": "identx"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", required=True, help="a sgatwalk fidelity run directory")
    ap.add_argument("--walks", type=int, default=4,
                    help="grounding walks per draw and sim (default 4: what the default worlds are fitted on; a "
                         "run with e.g. the world sgat:sim=16 has 16)")
    ap.add_argument("--leads", type=int, nargs="+", default=[1, 2, 3, 4, 5], help="leads k [control steps]")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--save", metavar="NAME", help="also write docs/results/NAME.json")
    args = ap.parse_args(argv)
    if args.walks < 2:
        ap.error("--walks must be >= 2 (the fit is cross-validated over walks)")
    from common.defaults import CONTROL_DT
    from envs import ObservationLayout, Recording
    from experiments.fidelity.run import _GROUND_SIM, _seeds
    from experiments.runtime.grounding import DEFAULT_HISTORY, EXPLORATION_NOISE, identified_latency, nao_spec
    from tools.readme import finish_benchmark
    from robots import get_robot
    from sgat.grounding import command_visibility

    load0 = os.getloadavg()[0]
    cfg_path = os.path.join(args.run, "config.json")
    if not os.path.exists(cfg_path):
        ap.error(f"{args.run!r} is not a fidelity run directory (no config.json)")
    with open(cfg_path) as f:
        cfg = json.load(f)
    if cfg.get("robot", "nao") != "nao":
        ap.error("the walks' layout is the NAO's: run it on a NAO fidelity run")
    spec, layout = nao_spec("legs", DEFAULT_HISTORY, "nao"), ObservationLayout(get_robot("nao"))
    out = {"run": os.path.basename(os.path.normpath(args.run)), "walks": args.walks, "leads": args.leads,
           "control_dt_ms": 1000 * CONTROL_DT, "draws": {}}
    for d in range(int(cfg["data_seeds"])):
        seeds = _seeds(int(cfg["seed"]), _GROUND_SIM, d, n=args.walks)
        row = {}
        reps = [os.path.join(args.run, "identified", f"d{d}", stage, "report.json") for stage in ("fixed", "floating")]
        reps = [r for r in reps if os.path.exists(r)]
        if reps:
            row["latency_ms"] = 1000 * identified_latency(reps)
        for kind, tag in TAGS.items():
            paths = [os.path.join(args.run, "data", f"{tag}_d{d}_n{EXPLORATION_NOISE:g}_{s}.parquet") for s in seeds]
            if not all(os.path.exists(p) for p in paths):
                continue
            row[kind] = command_visibility([Recording.from_parquet(p) for p in paths], layout, spec, args.leads)
            print(f"[command_visibility] draw {d}, {kind} sim: R² by lead "
                  + ", ".join(f"{v:+.2f}" for v in row[kind]["r2"]), file=sys.stderr, flush=True)
        if "sim" in row or "identified" in row:
            out["draws"][str(d)] = row
    if not out["draws"]:
        ap.error(f"no grounding walks of {args.walks} per draw found in {args.run!r}/data")
    lines = [f"{out['run']}: {args.walks} grounding walks of θ0 per draw and sim (exploration noise "
             f"{EXPLORATION_NOISE:g} rad on the leg targets), cross-validated R² of that noise from the state history "
             f"and s_(t+k) - s_t, by lead k [control steps of {out['control_dt_ms']:g} ms]",
             f"{'draw':>4s} {'sim':>10s} {'latency':>9s}  " + " ".join(f"{'k = ' + str(k):>7s}" for k in args.leads)
             + "  best k"]
    for d, row in out["draws"].items():
        for kind in TAGS:
            if kind not in row:
                continue
            lat = row.get("latency_ms") if kind == "identified" else None
            lat_s = "none" if kind == "sim" else "–" if lat is None else f"{lat:.1f} ms"
            lines.append(f"{d:>4s} {kind:>10s} {lat_s:>9s}  " + " ".join(f"{v:+7.2f}" for v in row[kind]["r2"])
                         + f"  {row[kind]['best_lead']:>6d}")
    for kind in TAGS:
        got = [row[kind] for row in out["draws"].values() if kind in row]
        if got:
            out[f"{kind}_lead1_r2_max"] = max(g["r2"][0] for g in got)
            out[f"{kind}_best_r2_min"] = min(max(g["r2"]) for g in got)
    lines.append("R² near 0 or below: the state change at that lead says nothing of the command (a linear inverse "
                 "model there returns the commands it saw for similar states)")
    out["text"] = "\n".join(lines)
    finish_benchmark(out, "benchmarks/command_visibility.py", argv, save_name=args.save, as_json=args.json,
                     load_before=load0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
