"""``sgatwalk stand``: hold a pose in the sim and/or the real world and report.

The demo of the two worlds: the robot stands in a pose for some seconds on flat ground or on a
heightfield; per world, whether it fell, how far its CoM drifted, the mean foot forces and the
simulation speed, and optionally each rollout as a Parquet recording.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from experiments.runtime.rundir import record_path

WORLDS = ("sim", "real")


@dataclass(frozen=True)
class StandConfig:
    """What to hold, where: ``worlds`` (sim, real), ``pose`` (a pose of the robot), ``seconds``,
    ``seed``, ``profile`` (the real world's), ``terrain``/``amplitude`` (a heightfield for both worlds;
    None: flat sim, the profile's random field in the real world), ``fixed_base`` (hang the robot),
    ``robot``, ``record`` (a path; ``{world}`` in it is replaced) and ``stochasticity`` (the real world's
    per-step randomness level, ``envs.effects.Stochasticity``).

    Raises:
        ValueError: an unknown world or pose, an amplitude without a terrain.
    """

    worlds: tuple = WORLDS
    pose: str = "crouch"
    seconds: float = 10.0
    seed: int = 0
    profile: str = "real"
    terrain: str | None = None
    amplitude: float | None = None
    fixed_base: bool = False
    robot: str = "nao"
    record: str | None = None
    stochasticity: float = 0.0

    def __post_init__(self) -> None:
        from robots import get_robot

        from terrain import check_amplitude

        bad = [w for w in self.worlds if w not in WORLDS]
        if bad or not self.worlds:
            raise ValueError(f"unknown world {bad[0] if bad else '(none)'!r}; choose from sim, real")
        get_robot(self.robot).pose(self.pose)  # KeyError naming the known poses
        if self.stochasticity and "real" not in self.worlds:
            raise ValueError("--stochasticity applies to the real world only (add real to --world)")
        if self.amplitude is not None and self.terrain is None:
            raise ValueError("--amplitude needs --terrain (e.g. --terrain lumpy --amplitude 0.01)")
        if self.terrain is not None:
            check_amplitude(self.terrain, 0.01 if self.amplitude is None else self.amplitude)


def stand(cfg: StandConfig) -> dict:
    """Hold ``cfg.pose`` in each world (``envs.rollout`` with ``envs.HoldPose``).

    Returns:
        ``{"robot", "pose", "seed", "worlds": [{"world", "fell", "fall_reason", "fall_time_s", "seconds",
        "com_drift_m", "com_height_m", "foot_force_n" (mean L/R over the second half [N]), "terrain",
        "wall_s", "realtime_factor", "profile" (real), "recording" (a path, with ``record``)}]}``.
    """
    from envs import HoldPose, make_world, rollout  # lazy: loads the engines
    from robots import get_robot
    from terrain import check_amplitude, make

    robot = get_robot(cfg.robot)
    hf = None
    if cfg.terrain is not None:
        hf = make(cfg.terrain, seed=cfg.seed, amplitude=check_amplitude(cfg.terrain, 0.01 if cfg.amplitude is None else cfg.amplitude))
    results = []
    for w in cfg.worlds:
        kw = {"fixed_base": cfg.fixed_base, "robot": robot}
        if w == "real":
            kw.update(profile=cfg.profile, terrain=hf if hf is not None else "lumpy", stochasticity=cfg.stochasticity)
        else:
            kw.update(terrain=hf)
        env = make_world(w, **kw)
        t0 = time.perf_counter()
        rec = rollout(env, HoldPose(env.robot, cfg.pose), seed=cfg.seed, seconds=cfg.seconds)
        wall = time.perf_counter() - t0
        com, fsr = rec.group("gt.com"), rec.group("fsr")
        res = {"world": w, "fell": rec.fell, "fall_reason": rec.meta["fall_reason"], "fall_time_s": rec.meta["fall_time"],
               "seconds": float(len(rec) * env.control_dt), "com_drift_m": float(np.linalg.norm(com[-1, :2] - com[0, :2])),
               "com_height_m": float(com[-1, 2]), "foot_force_n": [float(v) for v in fsr[len(fsr) // 2:].mean(0)],
               "terrain": rec.meta["terrain"]["name"] if rec.meta["terrain"] else "flat",
               "wall_s": wall, "realtime_factor": float(len(rec) * env.control_dt / wall)}
        if w == "real":
            res["profile"] = env.profile.name
            res["stochasticity"] = cfg.stochasticity
        if cfg.record:
            res["recording"] = rec.to_parquet(record_path(cfg.record, w, len(cfg.worlds)))
        results.append(res)
        env.close()
    return {"robot": cfg.robot, "pose": cfg.pose, "seed": cfg.seed, "worlds": results}


def format_stand(results: list[dict]) -> str:
    """The table ``sgatwalk stand`` prints, from its per-world results (also from ``--json``; the
    real-time factor shows when the result has it, i.e. with ``--timings``)."""
    rt = all("realtime_factor" in r for r in results)
    lines = [f"{'world':6s} {'fell':5s} {'reason':10s} {'CoM drift':>10s} {'CoM z':>7s} {'feet L/R [N]':>14s} "
             f"{'terrain':22s}" + (f" {'x realtime':>10s}" if rt else "")]
    for r in results:
        lines.append(f"{r['world']:6s} {str(r['fell']):5s} {str(r['fall_reason'] or '-'):10s} "
                     f"{1000 * r['com_drift_m']:8.1f}mm {r['com_height_m']:7.3f} "
                     f"{r['foot_force_n'][0]:6.1f}/{r['foot_force_n'][1]:6.1f} {r['terrain']:22s}"
                     + (f" {r['realtime_factor']:10.1f}" if rt else "")
                     + (f"  -> {r['recording']}" if "recording" in r else ""))
    return "\n".join(lines)


__all__ = ["StandConfig", "format_stand", "stand"]
