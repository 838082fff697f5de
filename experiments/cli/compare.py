"""``sgatwalk compare``: every training world of several fidelity runs, ranked per gait panel.

Reads fidelity results (run directories of ``sgatwalk fidelity``, their ``fidelity.json``, saved
results ``docs/results/fidelity*.json``, or folders of these), groups them by gait panel
(runs share a panel only when they walked the same gaits on the same real trials with the same
outcome) and ranks every world of every run by its worst Spearman ρ over the draws. Per world: ρ
median [worst, best], median |bias| and bias spread, median Brier score, median regret of its pick,
and for a grounded variant its ρ minus its run's reference SGAT's, draw by draw (median, and on how
many draws it was higher). ``--plot`` draws the ranking (ρ over the draws per world, the ceiling
marked). ``--paired`` also tests every world that two runs of a panel measured under the same name
(e.g. the hybrid world before and after a change of the code): the later run's ρ minus the first's,
the mean over the draws, with a 90 % bootstrap interval and p over the shared real trials and
episodes (and over the gaits, for a new panel), as ``sgatwalk fidelity`` tests worlds of one run.

Examples::

    sgatwalk compare runs/fidelity-seed0 runs/fidelity-variants
    sgatwalk compare docs/results --kinds sgat,hybrid --top 10 --plot compare.png
    sgatwalk compare runs/fidelity-before runs/fidelity-after --kinds identified,hybrid --paired
"""

from __future__ import annotations

import argparse

from experiments.runtime.worlds import KINDS
import experiments.cli.argtypes as A


def _kinds(text: str) -> tuple[str, ...]:
    kinds = tuple(k.strip() for k in text.split(",") if k.strip())
    bad = [k for k in kinds if k not in KINDS]
    if bad or not kinds:
        raise argparse.ArgumentTypeError(f"unknown world kind(s) {', '.join(bad) or repr(text)}; choose from {', '.join(KINDS)}")
    return kinds


def register(sub) -> argparse.ArgumentParser:
    from experiments.compare import PLOT_ROWS

    p = sub.add_parser("compare", help="rank the training worlds of several fidelity runs per gait panel",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("results", nargs="+", type=A.in_path, metavar="RESULT",
                   help="fidelity run directories, fidelity.json files, saved README results, or folders of them")
    p.add_argument("--kinds", type=_kinds, metavar="KIND[,KIND...]",
                   help=f"keep only worlds of these kinds, a comma list of {', '.join(KINDS)} (default all)")
    p.add_argument("--top", type=A.count(1, 100000), help="keep the best N worlds of each panel (default all)")
    p.add_argument("--plot", type=A.out_file, metavar="PNG",
                   help=f"draw the ranking into this PNG (the best {PLOT_ROWS} worlds of each panel)")
    p.add_argument("--paired", action="store_true",
                   help="also test each world that two runs of a panel measured under the same name, paired on "
                        "their shared real trials and episodes (a bootstrap)")
    p.add_argument("--bootstrap", type=A.count(1, 1_000_000), default=1000, metavar="N",
                   help="bootstrap replicates of --paired (default 1000)")
    return p


def run(args) -> dict:
    from experiments.compare.run import compare, format_compare, load_results, plot

    with A.user_input():
        results, skipped = load_results(args.results)
    res = compare(results, kinds=args.kinds, top=args.top, paired=args.paired, n_boot=args.bootstrap)
    res["skipped"] = skipped
    if args.plot:
        plot(res, args.plot)
        res["plot"] = args.plot
    if not args.json:
        print(format_compare(res), flush=True)
        if skipped:
            print(f"skipped {len(skipped)} files that are not fidelity results", flush=True)
        if args.plot:
            print(f"figure: {args.plot}", flush=True)
    return res
