"""``sgatwalk visualize``: see rollouts in Rerun, sim beside real, on one timeline.

Inputs, one of:

* recordings: Parquet files written by ``sgatwalk stand --record``, ``walk``, ``optimize`` or a
  real robot's log in the same schema (``envs/recording.py``);
* a run directory (e.g. of ``sgatwalk optimize``): every ``*.parquet`` recording below it,
  recursively, labelled by the world in its metadata (other Parquet files are skipped);
* nothing: a live rollout of ``--robot`` (nao, g1, talos; default nao) in each world of
  ``--world`` (sim, real, grounded; grounded: the NAO only) driven by the walk engine with
  ``--params theta.json`` (default: the robot's initial gait parameters) or holding ``--pose``.

With recordings the robot comes from each recording's metadata (all of one robot per file); the
NAO is drawn from primitives, the G1 and Talos with their meshes (from example-robot-data).

Writes one ``.rrd`` (``--save``, default ``sgatwalk.rrd``; headless, no viewer needed; open it
with ``rerun sgatwalk.rrd``) or streams to a viewer (``--spawn``). ``--screenshot out.png`` also
renders the default layout headlessly (needs a GPU or Mesa's lavapipe Vulkan driver). The layout
and entity paths are described in ``experiments/viz/__init__.py``.
"""

from __future__ import annotations

import argparse
import experiments.cli.argtypes as A

from common.defaults import EPISODE_SECONDS

def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("visualize", help="show rollouts in Rerun (recordings, a run directory or a live rollout)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("inputs", type=A.in_path, nargs="*", metavar="PATH",
                   help="recordings (*.parquet) and/or directories searched recursively; none: live rollout")
    p.add_argument("--save", type=A.out_file, metavar="OUT.rrd", default=None,
                   help="write the Rerun file here (default: sgatwalk.rrd; the default mode, headless)")
    p.add_argument("--spawn", action="store_true", help="open the Rerun viewer instead of writing a file")
    p.add_argument("--screenshot", type=A.out_file, metavar="PNG", default=None,
                   help="also render the saved file headlessly to this PNG (needs a GPU or Mesa lavapipe)")
    p.add_argument("--screenshot-time", type=A.real(0.0, 3600.0), default=None, metavar="S",
                   help="time cursor for --screenshot [s] (default: middle of the longest rollout)")
    live = p.add_argument_group("live rollout (when no PATH is given)")
    live.add_argument("--world", default="sim,real", help="comma-separated worlds: sim, real, grounded (default sim,real)")
    live.add_argument("--params", type=A.in_file, metavar="THETA.json", default=None,
                      help="gait parameters for the walk engine (default: the robot's initial θ0)")
    live.add_argument("--pose", default=None,
                      help="hold this pose instead of walking (zero, stand, crouch; the NAO also deep_crouch)")
    live.add_argument("--seed", type=A.seed, default=0, help="episode seed (terrain, effects, noise; default 0)")
    live.add_argument("--seconds", type=A.seconds, default=EPISODE_SECONDS, help=f"rollout duration [s] (default {EPISODE_SECONDS:g})")
    A.add_profile(live)
    live.add_argument("--transformer", type=A.in_path, metavar="PATH", default=None,
                      help="action transformer for the grounded world (sgat), when available")
    live.add_argument("--record", type=A.out_file, metavar="PATH", default=None,
                      help="also write the live recordings as Parquet; '{world}' in PATH is replaced")
    A.add_robot(live)
    p.set_defaults(robot=None)  # None: not given (nao for a live rollout; refused with recordings)
    return p


def run(args) -> dict:
    from experiments.viz import find_recordings, log_rollouts_to_rrd, screenshot_rrd  # lazy: loads the engines; keeps sgatwalk --help fast

    from experiments.viz.live import LiveConfig, live_rollouts

    notes: list[str] = []
    skipped: list[str] = []
    terrains = None
    with A.user_input():
        if args.spawn and args.save:
            raise ValueError("give --save or --spawn, not both")
        if args.spawn and args.screenshot:
            raise ValueError("--screenshot renders a saved file; drop --spawn")
        if args.inputs:
            given = [a for a in ("params", "pose", "transformer", "record", "robot") if getattr(args, a)]
            if given:
                raise ValueError(f"--{given[0]} is for a live rollout; drop it or drop the recording paths")
            recs, skipped = find_recordings(args.inputs)
        else:
            cfg = LiveConfig(worlds=tuple(w.strip() for w in args.world.split(",") if w.strip()), robot=args.robot or "nao",
                             params=args.params, pose=args.pose, seed=args.seed, seconds=args.seconds,
                             profile=args.profile or "real", stochasticity=args.stochasticity,
                             transformer=args.transformer, record=args.record)
            gait = cfg.gait()
    if not args.inputs:
        recs, terrains, notes = live_rollouts(cfg, gait)
    path = None if args.spawn else (args.save or "sgatwalk.rrd")
    res = log_rollouts_to_rrd(recs, path, terrains=terrains, spawn=args.spawn)
    out = {
        "path": res["path"], "bytes": res["bytes"], "log_seconds": res["log_seconds"], "wall_s": res["seconds"],
        "entities": len(res["rows"]), "skipped": skipped, "notes": notes,
        "recordings": [{"label": lab, "world": r.meta.get("world"), "rows": len(r), "seconds": float(r.t[-1]),
                        "fell": r.fell, "fall_reason": r.meta.get("fall_reason"), "terrain": res["notes"][lab]}
                       for lab, r in zip(res["labels"], recs.values())],
    }
    if args.screenshot:
        t = args.screenshot_time
        if t is None:
            t = 0.5 * max(float(r.t[-1]) for r in recs.values())
        try:
            out["screenshot"] = screenshot_rrd(res["path"], args.screenshot, time_s=t)
        except RuntimeError as exc:
            out["screenshot_error"] = str(exc)
    if not args.json:
        for r in out["recordings"]:
            fell = f"fell: {r['fall_reason']}" if r["fell"] else "stayed up"
            print(f"/{r['label']:24s} {r['rows']:5d} rows  {r['seconds']:6.2f} s  {fell:20s} terrain: {r['terrain']}")
        for n in notes:
            print(n)
        if skipped:
            print(f"skipped {len(skipped)} Parquet file(s) without recording metadata: {', '.join(skipped[:3])}"
                  + (" ..." if len(skipped) > 3 else ""))
        if out["path"]:
            print(f"wrote {out['path']} ({out['bytes'] / 1e6:.1f} MB, {out['entities']} entities, logged in "
                  f"{out['log_seconds']:.2f} s); open it with:  rerun {out['path']}")
        else:
            print(f"streamed {out['entities']} entities to the Rerun viewer")
        if "screenshot" in out:
            print(f"screenshot: {out['screenshot']}")
        if "screenshot_error" in out:
            print(f"screenshot failed: {out['screenshot_error']}")
    return out
