"""``sgatwalk cliff``: GAT vs SGAT on Cliff Walking over a noise sweep (the SGAT paper, Fig. 7).

For each noise level of the "real" Cliff Walking (the agent slips with that probability), both
methods ground the deterministic sim on real data and improve the policy by policy iteration in the
grounded sim until it stops changing; the real return of each method's policy, of the sim's own
policy and of the optimal one is printed per level. Writes cliff.csv, cliff.png (returns against
noise) and cliff_paths.png (the greedy paths where SGAT gains most over GAT) to --out.
"""

from __future__ import annotations

import argparse

import experiments.cli.argtypes as A
from experiments.runtime.progress import Reporter


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``cliff`` subcommand and its options to ``subparsers``."""
    p = subparsers.add_parser(
        "cliff",
        help="GAT vs SGAT on Cliff Walking over a noise sweep (paper Fig. 7)",
        description=(
            "Reproduce the Cliff Walking experiment of the SGAT paper (Sec. IV.A, Fig. 7): for "
            "each 'real' noise value, ground the deterministic simulator with GAT and with "
            "SGAT (tabular models, policy iteration), evaluate both policies and the optimum "
            "of the real MDP on the real MDP, print a table and write CSV and PNG files."
        ),
    )
    p.add_argument("--noise", default="0:1:11",
                   help="noise values: 'start:stop:count' (linspace) or a comma list of "
                        "probabilities in [0, 1] (default 0:1:11)")
    p.add_argument("--episodes", type=A.count(1, 10_000_000), default=10_000,
                   help="evaluation episodes per policy and noise value (default 10000, "
                        "as in the paper)")
    p.add_argument("--seed", type=A.seed, default=0, help="random seed (default 0)")
    p.add_argument("--out", type=A.out_dir, default="runs/cliff",
                   help="output directory for cliff.csv, cliff.png, cliff_paths.png "
                        "(default runs/cliff)")
    p.add_argument("--real-episodes", type=A.count(1, 10_000_000), default=10_000,
                   help="real episodes collected per grounding step (default 10000; the paper "
                        "does not say)")
    p.add_argument("--explore", type=A.fraction, default=0.1,
                   help="epsilon of the epsilon-greedy policy that collects real data "
                        "(default 0.1)")
    p.add_argument("--max-grounding-steps", type=A.count(1, 10000), default=30,
                   help="cap on grounding steps (default 30)")
    p.add_argument("--patience", type=A.count(1, 10000), default=2,
                   help="stop grounding after this many steps without a policy change "
                        "(default 2)")
    p.add_argument("--max-steps", type=A.count(1, 1_000_000), default=1000,
                   help="step cap per episode, real data and evaluation (default 1000)")
    return p


def run(args: argparse.Namespace) -> dict:
    from experiments.cliff.run import format_table, parse_noise, run_cliff

    with A.user_input():
        noises = parse_noise(args.noise)
    res, rows = run_cliff(noises, args.out, episodes=args.episodes, seed=args.seed, real_episodes=args.real_episodes,
                          explore=args.explore, patience=args.patience, max_grounding_steps=args.max_grounding_steps,
                          max_steps=args.max_steps, reporter=Reporter("cliff"))
    if not args.json:
        print(format_table(rows, args.episodes, args.seed))
        print(f"sweep took {res['elapsed_s']:.1f} s; wrote {', '.join(res['files'].values())}")
    return res
