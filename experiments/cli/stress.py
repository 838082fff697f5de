"""``sgatwalk stress``: how far does each gait hold up as the terrain gets rougher?

Every (policy, level, trial) episode runs through the executor (process pool by default, Ray with
``--ray-address``). Trial j has one terrain seed and one episode seed shared by every policy and
every level (a paired comparison), and a level is the same heightfield in the sim and the real
world. Prints a table per policy and level -- fall rate with its 95 % Wilson interval, speed mean
± std of the trials that did not fall, mean distance before a fall -- and writes to ``--out``
(default ``runs/stress-<world>-<terrain>-seed<seed>``): ``trials.csv`` / ``trials.parquet``
(every episode; re-running the same command resumes where it stopped), ``summary.csv``,
``stress.png`` (fall rate and speed vs level, one line per policy), and with ``--rerun``
``rerun/<policy>.rrd`` (the worst trial of each level).

``--sweep EFFECT=lo:hi:n`` sweeps one real-world effect instead of the terrain (e.g.
``latency_s=0:0.04:5``, ``foot_friction=0.2:0.8:4``, ``mass_scale=0.9:1.2:4``).
"""

from __future__ import annotations

import argparse

from common.defaults import EPISODE_SECONDS
import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("stress", help="terrain (or effect) stress test of gaits: fall rate and speed per level",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--params", type=A.in_file, nargs="+", metavar="JSON", default=None,
                   help="gait parameter files, one policy each (label = file stem); default: θ0")
    p.add_argument("--world", default="real", choices=("real", "sim"), help="real (PyBullet, default) or sim (MuJoCo)")
    p.add_argument("--terrain", default=None, metavar="KIND",
                   help="lumpy (default), fractal, steps or slope; with --sweep: terrain under the sweep "
                        "(default: the profile's own random field)")
    p.add_argument("--amplitude", default=None, metavar="LEVELS",
                   help="terrain levels: start:stop:count, a comma list or one value; amplitude [m] "
                        "(grade for slope); default 0:0.04:9 (with --sweep and --terrain: one value, default 0.02)")
    p.add_argument("--trials", type=A.count(1, 100000), default=20, help="episodes per policy and level (default 20)")
    p.add_argument("--seed", type=A.seed, default=0, help="run seed: terrain and episode seeds of the trials")
    p.add_argument("--seconds", type=A.seconds, default=EPISODE_SECONDS, help="episode length [s] (default 7.5)")
    A.add_profile(p)
    p.add_argument("--sweep", default=None, metavar="EFFECT=lo:hi:n",
                   help="sweep one real-world effect instead of the terrain (real world only)")
    p.add_argument("--out", type=A.out_dir, default=None, metavar="DIR", help="run directory (default runs/stress-...)")
    p.add_argument("--rerun", action="store_true", help="write .rrd files of the worst trial per policy and level")
    A.add_executor(p)
    A.add_robot(p)
    return p


def run(args) -> dict:
    from experiments.runtime.progress import Reporter
    from experiments.stress.run import make_config, run_stress  # lazy: loads the engines

    terrain = args.terrain if (args.terrain is not None or args.sweep is not None) else "lumpy"
    with A.user_input():
        cfg = make_config(args.params, world=args.world, terrain=terrain, amplitude=args.amplitude,
                          trials=args.trials, seed=args.seed, profile=args.profile, sweep=args.sweep,
                          seconds=args.seconds, robot=args.robot, stochasticity=args.stochasticity)
    res = run_stress(cfg, args.out, workers=args.workers, ray_address=args.ray_address, rerun=args.rerun,
                     reporter=Reporter("stress"))
    if not args.json:
        print(res["table"])
        print(f"{res['episodes']} episodes ({res['ran']} run now, {res['resumed']} resumed); the run took "
              f"{res['wall_s']:.1f} s in all, on {res['workers']} {res['executor']} worker(s)")
        for k in ("trials_csv", "trials_parquet", "summary_csv", "png"):
            print(f"  {k}: {res['files'][k]}")
        for path in res["files"].get("rrd", []):
            print(f"  rrd: {path}")
    keys = ("policy", "level", "trials", "falls", "fall_rate", "fall_rate_ci95", "speed_cm_s_mean",
            "speed_cm_s_std", "distance_before_fall_m_mean")
    out = {"rows": [{k: r[k] for k in keys} for r in res["rows"]], "out": res["out"], "files": res["files"],
           "episodes": res["episodes"], "ran": res["ran"], "resumed": res["resumed"], "wall_s": res["wall_s"],
           "workers": res["workers"], "executor": res["executor"],
           "axis": res["config"]["axis"], "world": res["config"]["world"], "terrain": res["config"]["terrain"],
           "table": res["table"]}
    if "worst" in res:
        out["worst"] = res["worst"]
    return out
