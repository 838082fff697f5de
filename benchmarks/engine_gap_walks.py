"""Where the engines part: the real world's mean physics walked in PyBullet and in MuJoCo on the very
same lumpy ground, gait by gait.

The mean-physics yardstick of ``sgatwalk fidelity`` (``oracle:mean=1:engine=mujoco``: the real
world's effects at the middle of their ranges, built into the MuJoCo sim by the identified sim's
effect models, ``experiments.runtime.tasks.mean_physics_report``) ranks a panel's gaits worse than the same
physics in PyBullet (``oracle:mean=1``); the thirtieth round's fidelity runs swap the grounds between
the two (``ground=real`` / ``ground=model``) and find the ground model costs nothing. This splits the
rest. A panel of gaits (``sgatwalk fidelity``'s: θ0 and ``--gaits`` drawn in the ±0.15 box around it,
``experiments.fidelity.run.drawn_panel``) walks ``--episodes`` episodes each, on seeds shared by every
world, per profile:

* ``pybullet``: the real world at the profile's mean physics (``PROFILE:mean``, its sensor noise
  included), on its lumpy ground of each seed (``envs.bullet_world.real_ground``);
* MuJoCo, the identified sim (``sysid.identified.IdentifiedSimEnv``) built from the profile's
  mean-physics report, on the *same* lumpy fields (the task's ``ground``): ``as yardstick`` (the report
  as it is: the sim's 10 ms ground contact, ``envs.mujoco_world.GROUND_TIMECONST``, and backlash as a
  series play hinge on every joint, ``sysid.model``), ``stiff ground`` (the contact time constant at
  MuJoCo's 2-step floor, 4 ms: what the diagnosis identifies as ``ground_compliance`` on every
  stepping log of the real world), ``no play hinges`` (the backlash terms left out) and both.

Per MuJoCo world against PyBullet: Spearman ρ of the per-gait mean fitness (a 90 % bootstrap interval
over the paired episode seeds), the mean absolute difference and the bias of those means (MuJoCo −
PyBullet), and how often an episode falls in one engine and not the other. The reference: the split-
half reliability of PyBullet's own per-gait means (its sensor noise alone decides some falls), stepped
up to the full episode count (Spearman–Brown), the ρ another set of PyBullet episodes would reach.
Profiles: ``real-ground`` (the lumpy ground and no other effect: the engines' contacts alone; the
report's effect terms are identities, the play hinges zero-width), ``real-flat`` (every other effect,
on flat ground: the effect models alone) and ``real`` (every effect).

Prints a table or, with ``--json``, one JSON object; ``--save NAME`` also writes
``docs/results/NAME.json`` for the README (with the load average).

Usage: ``python benchmarks/engine_gap_walks.py [--seed 0] [--gaits 15] [--episodes 8] [--save benchenginegap-walks]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

#: The MuJoCo variants: name -> (contact time constant [s] or None for the sim's, keep the backlash terms).
VARIANTS = {"as yardstick": (None, True), "stiff ground": (0.004, True), "no play hinges": (None, False),
            "stiff ground, no play hinges": (0.004, False)}
PROFILES = ("real-ground", "real-flat", "real")


def mujoco_report(profile: str, timeconst: float | None, backlash: bool) -> dict:
    """The profile's mean-physics report (``experiments.runtime.tasks.mean_physics_report``) with the ground's
    contact time constant set (``ground_compliance``) and/or the backlash terms left out."""
    from experiments.runtime.tasks import mean_physics_report

    rep = mean_physics_report(profile, ground_compliance=timeconst, drop=() if backlash else ("backlash",))
    return {**rep, "effects": []}  # the ground is the task's: the real world's own fields


def agreement(mj: np.ndarray, pb: np.ndarray, fell_mj: np.ndarray, fell_pb: np.ndarray, *, n_boot: int = 1000,
              seed: int = 0) -> dict:
    """A MuJoCo world against PyBullet on paired episodes, fitness and falls (G gaits, E episodes each):
    ρ of the per-gait means with a 90 % percentile interval from resampling the episode seeds (the
    same columns of both), mean absolute difference and bias (MuJoCo − PyBullet) of the means, and the
    share of episodes that fall in exactly one engine."""
    from experiments.runtime.stats import spearman

    rng = np.random.default_rng(seed)
    E = mj.shape[1]
    boots = []
    for _ in range(n_boot):
        c = rng.integers(0, E, E)
        boots.append(spearman(mj[:, c].mean(1), pb[:, c].mean(1)))
    lo, hi = np.nanpercentile(boots, [5, 95])
    d = mj.mean(1) - pb.mean(1)
    return {"rho": spearman(mj.mean(1), pb.mean(1)), "ci": [float(lo), float(hi)], "mae": float(np.abs(d).mean()),
            "bias": float(d.mean()), "falls_differ": float(np.mean(fell_mj != fell_pb)),
            "falls": float(fell_mj.mean())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0, help="panel seed (sgatwalk fidelity --seed; default 0)")
    ap.add_argument("--gaits", type=int, default=15, help="gaits drawn around θ0 (default 15)")
    ap.add_argument("--episodes", type=int, default=8, help="episodes per gait and world, shared seeds (default 8)")
    ap.add_argument("--profiles", nargs="+", default=list(PROFILES), choices=PROFILES, help="real-world profiles")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--save", metavar="NAME", help="also write docs/results/NAME.json")
    args = ap.parse_args(argv)
    if args.seed < 0 or args.gaits < 2 or args.episodes < 2:
        ap.error("--seed must be >= 0, --gaits >= 2 and --episodes >= 2")
    from envs.effects import get_profile
    from experiments.runtime.batch import map_episodes
    from experiments.runtime.executors import make_executor
    from experiments.fidelity.run import drawn_panel
    from tools.readme import finish_benchmark
    from experiments.runtime.stats import split_half_reliability
    from experiments.runtime.tasks import mean_profile
    from walk_engine import GaitParams

    load0 = os.getloadavg()[0]
    t_start = time.perf_counter()
    gaits = drawn_panel(GaitParams, args.seed, args.gaits, 0.15)
    seeds = [int(s) for s in np.random.SeedSequence([args.seed, 0xE6A9]).generate_state(args.episodes)]
    G, E = len(gaits), args.episodes
    out = {"seed": args.seed, "gaits": G, "episodes": E, "profiles": {}}
    ex = make_executor()
    with tempfile.TemporaryDirectory(prefix="engine_gap_") as tmp:
        for profile in args.profiles:
            amp = float(mean_profile(get_profile(profile)).terrain_amplitude[0])
            ground = ["real", amp]
            worlds = {"pybullet": {"world": "real", "profile": f"{profile}:mean", "ground": ground}}
            for name, (tc, backlash) in VARIANTS.items():
                path = os.path.join(tmp, profile, name.replace(" ", "_").replace(",", ""), "report.json")
                os.makedirs(os.path.dirname(path))
                with open(path, "w") as f:
                    json.dump(mujoco_report(profile, tc, backlash), f)
                worlds[name] = {"world": "identified", "identified": [path], "ground": ground}
            fit, fell = {}, {}
            for name, base in worlds.items():
                t0 = time.perf_counter()
                tasks = [{**base, "theta": g["theta"], "seed": s, "seconds": 7.5} for g in gaits for s in seeds]
                res = map_episodes(ex, tasks)
                fit[name] = np.array([r["fitness"] for r in res]).reshape(G, E)
                fell[name] = np.array([bool(r["fell"]) for r in res]).reshape(G, E)
                print(f"[engine_gap_walks {time.perf_counter() - t_start:6.0f} s] {profile}: {name} "
                      f"({len(tasks)} episodes, {time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
            pb, pbf = fit["pybullet"], fell["pybullet"]
            rel = split_half_reliability(pb)
            out["profiles"][profile] = {
                "amplitude_m": amp, "pybullet_falls": float(pbf.mean()), "pybullet_fitness": float(pb.mean()),
                "pybullet_reliability": rel["reliability"],
                "worlds": {n: agreement(fit[n], pb, fell[n], pbf, seed=args.seed) for n in VARIANTS}}
    ex.close()
    rows = [f"seed-{args.seed} panel: {G} gaits x {E} episodes on shared seeds and the same lumpy fields; MuJoCo "
            f"(the identified sim with the profile's mean physics) against PyBullet (the real world at its mean)",
            "rho of the per-gait mean fitness (90% CI over the episode seeds), MAE and bias (MuJoCo - PyBullet) of the "
            "means, MuJoCo's falls and the episodes that fall in one engine only"]
    for profile, p in out["profiles"].items():
        ground = f"lumpy ground of {1000 * p['amplitude_m']:.0f} mm" if p["amplitude_m"] > 0 else "flat ground"
        rows += ["", f"{profile} ({ground}; PyBullet falls "
                     f"{100 * p['pybullet_falls']:.0f} %, its own {E}-episode reliability {p['pybullet_reliability']:.2f})",
                 f"  {'MuJoCo world':30s} {'rho':>5s} {'90% CI':>14s} {'MAE':>5s} {'bias':>6s} {'falls':>6s} {'differ':>7s}"]
        for n, a in p["worlds"].items():
            rows.append(f"  {n:30s} {a['rho']:5.2f} [{a['ci'][0]:5.2f}, {a['ci'][1]:5.2f}] {a['mae']:5.2f} "
                        f"{a['bias']:+6.2f} {100 * a['falls']:5.0f}% {100 * a['falls_differ']:6.0f}%")
    out["wall_s"] = time.perf_counter() - t_start
    out["text"] = "\n".join(rows)
    finish_benchmark(out, "benchmarks/engine_gap_walks.py", argv, save_name=args.save, as_json=args.json,
                     load_before=load0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
