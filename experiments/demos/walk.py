"""``sgatwalk walk``: one walk of the ZMP walk engine with a gait, in the sim, the real world or the
identified sim, and its fitness (the paper's reward)."""

from __future__ import annotations

import time
from dataclasses import dataclass

from common.defaults import EPISODE_SECONDS

WORLDS = ("sim", "real", "identified")


@dataclass(frozen=True)
class WalkConfig:
    """One walk: ``params`` (a θ file; None: θ0), ``world`` (sim, real or identified), ``report`` (the
    identified world's diagnosis reports), ``seconds``, ``seed``, ``profile`` (the real world's),
    ``terrain``/``amplitude`` (a heightfield; None: flat sim, the profile's random field in the real
    world), the command ``vx`` [m/s] (None: the gait's own speed), ``vy`` [m/s], ``wz`` [rad/s],
    ``robot``, ``record`` (a Parquet path) and ``stochasticity`` (the real world's per-step randomness
    level, ``envs.effects.Stochasticity``).

    Raises:
        ValueError: an unknown world, a profile or stochasticity outside the real world, an identified world without
            reports (or reports without it, or for a robot other than the NAO), an amplitude without a
            terrain.
    """

    params: str | None = None
    world: str = "sim"
    report: tuple = ()
    seconds: float = EPISODE_SECONDS
    seed: int = 0
    profile: str | None = None
    terrain: str | None = None
    amplitude: float | None = None
    vx: float | None = None
    vy: float = 0.0
    wz: float = 0.0
    robot: str = "nao"
    record: str | None = None
    stochasticity: float = 0.0

    def __post_init__(self) -> None:
        if self.world not in WORLDS:
            raise ValueError(f"unknown world {self.world!r}; choose from {', '.join(WORLDS)}")
        if self.world == "identified" and self.robot != "nao":
            raise ValueError("--world identified models the NAO only (sgatwalk diagnose identifies the NAO's physics)")
        if self.world != "real" and self.profile is not None:
            raise ValueError("--profile applies to the real world only (use --world real)")
        if self.world != "real" and self.stochasticity:
            raise ValueError("--stochasticity applies to the real world only (use --world real)")
        if (self.world == "identified") != bool(self.report):
            raise ValueError("--world identified needs --report REPORT_JSON (and --report needs --world identified)")
        if self.amplitude is not None and self.terrain is None:
            raise ValueError("--amplitude needs --terrain (e.g. --terrain lumpy --amplitude 0.01)")
        if self.terrain is not None:
            from terrain import check_amplitude

            check_amplitude(self.terrain, 0.02 if self.amplitude is None else self.amplitude)

    def gait(self):
        """The gait to walk (``walk_engine.GaitParams`` of the robot): the θ file's, or θ0.

        Raises:
            ValueError, FileNotFoundError: a malformed or missing θ file (named).
        """
        from robots import get_robot
        from walk_engine import params_for

        P = params_for(get_robot(self.robot))
        return P.load(self.params) if self.params else P.initial()

    def identified_terms(self):
        """The identified world's effects and ground RMS height from the reports (None for other worlds).

        Raises:
            ValueError, FileNotFoundError: a malformed or missing report (named).
        """
        if self.world != "identified":
            return None
        from sysid.identified import load_identified  # lazy: loads the engines

        return load_identified(list(self.report), confounded=False)


def walk(cfg: WalkConfig, gait=None, identified=None) -> dict:
    """Walk once (:func:`experiments.runtime.fitness.run_walk`).

    Returns:
        ``{"robot", "world", "seed", "speed_cm_s", "fitness", "fell", "fall_reason", "fall_time_s", "drift_m",
        "distance_m", "seconds", "steps", "profile", "terrain", "params", "wall_s", "recording" (a path, with
        ``record``)}``.

    Args:
        gait, identified: :meth:`WalkConfig.gait` and :meth:`WalkConfig.identified_terms` (read here
            when not given).
    """
    from experiments.runtime.fitness import run_walk  # lazy: loads the engines
    from robots import get_robot
    from terrain import check_amplitude, make
    from walk_engine import WalkCommand

    robot = get_robot(cfg.robot)
    params = gait if gait is not None else cfg.gait()
    terrain = None
    if cfg.terrain is not None:
        amp = check_amplitude(cfg.terrain, 0.02 if cfg.amplitude is None else cfg.amplitude)
        terrain = "flat" if cfg.terrain == "flat" else make(cfg.terrain, seed=cfg.seed, amplitude=amp)
    env = None
    if cfg.world == "identified":
        from sysid.identified import IdentifiedSimEnv  # lazy: loads the engines

        terms, rms = identified if identified is not None else cfg.identified_terms()
        env = IdentifiedSimEnv(terms, rms, terrain=None if terrain in (None, "flat") else terrain)
    t0 = time.perf_counter()
    rec, res = run_walk(params, world=cfg.world, seed=cfg.seed, seconds=cfg.seconds, profile=cfg.profile or "real",
                        terrain=terrain, command=WalkCommand(cfg.vx, cfg.vy, cfg.wz), env=env,
                        robot=robot if env is None else None, stochasticity=cfg.stochasticity)
    out = {"robot": cfg.robot, "world": cfg.world, "seed": cfg.seed, **res.to_dict(), "profile": rec.meta.get("profile"),
           "terrain": rec.meta["terrain"]["name"] if rec.meta.get("terrain") else "flat", "params": params.to_dict(),
           "stochasticity": cfg.stochasticity, "wall_s": time.perf_counter() - t0}
    if cfg.record:
        out["recording"] = rec.to_parquet(cfg.record)
    return out


def format_walk(out: dict) -> str:
    """The line ``sgatwalk walk`` prints, from its result."""
    fall = f"fell ({out['fall_reason']} at {out['fall_time_s']:.2f} s)" if out["fell"] else "did not fall"
    who = f"{out['robot']}, " if out.get("robot", "nao") != "nao" else ""
    level = f", stochasticity {out['stochasticity']:g}" if out.get("stochasticity") else ""
    return (f"{who}{out['world']} seed {out['seed']} [{out['terrain']}{', profile ' + out['profile'] if out['profile'] else ''}{level}]: "
            f"speed {out['speed_cm_s']:.2f} cm/s, {fall}, drift {100 * out['drift_m']:.1f} cm, "
            f"distance {100 * out['distance_m']:.1f} cm, fitness {out['fitness']:.2f}"
            + (f"  -> {out['recording']}" if out.get("recording") else ""))


__all__ = ["WalkConfig", "format_walk", "walk"]
