"""Live rollouts for ``sgatwalk visualize``: one walk (or held pose) per world, recorded for Rerun."""

from __future__ import annotations

from dataclasses import dataclass

from common.defaults import EPISODE_SECONDS

#: The worlds a live rollout can show; ``grounded`` is the sim grounded by a saved action transformer.
LIVE_WORLDS = ("sim", "real", "grounded")


@dataclass(frozen=True)
class LiveConfig:
    """What to roll out: ``worlds`` (of :data:`LIVE_WORLDS`), ``robot``, ``params`` (a θ file; None: θ0)
    or ``pose`` (hold it instead of walking), ``seed``, ``seconds``, ``profile`` (the real world's),
    ``transformer`` (the grounded world's, a directory of ``sgatwalk optimize``'s ``models/``),
    ``record`` (write the recordings as Parquet; ``{world}`` in it is replaced), ``stochasticity`` (the real
    world's per-step randomness level, ``envs.effects.Stochasticity``).

    Raises:
        ValueError: no world, an unknown or repeated world, a grounded world without a transformer or
            for a robot other than the NAO, an unknown pose, both params and a pose.
    """

    worlds: tuple = ("sim", "real")
    robot: str = "nao"
    params: str | None = None
    pose: str | None = None
    seed: int = 0
    seconds: float = EPISODE_SECONDS
    profile: str = "real"
    transformer: str | None = None
    record: str | None = None
    stochasticity: float = 0.0

    def __post_init__(self) -> None:
        from robots import get_robot

        if not self.worlds:
            raise ValueError(f"--world is empty; choose from {', '.join(LIVE_WORLDS)}")
        bad = [w for w in self.worlds if w not in LIVE_WORLDS]
        if bad:
            raise ValueError(f"unknown world {bad[0]!r}; choose from {', '.join(LIVE_WORLDS)}")
        if len(set(self.worlds)) != len(self.worlds):
            raise ValueError(f"--world lists a world twice: {','.join(self.worlds)}")
        if "grounded" in self.worlds and self.robot != "nao":
            raise ValueError(f"world 'grounded' is the NAO's only (its action transformers are fitted on the NAO); "
                             f"drop it from --world for --robot {self.robot}")
        if self.stochasticity and "real" not in self.worlds:
            raise ValueError("--stochasticity applies to the real world only (add real to --world)")
        if "grounded" in self.worlds and self.transformer is None:
            raise ValueError("world 'grounded' needs --transformer DIR (e.g. RUN_DIR/models/sgat_step1 of 'sgatwalk optimize')")
        robot = get_robot(self.robot)
        if self.pose is not None and self.pose not in robot.poses:
            raise ValueError(f"unknown pose {self.pose!r} for --robot {self.robot}; choose from {', '.join(robot.poses)}")
        if self.pose is not None and self.params:
            raise ValueError("give either --params (walk) or --pose (stand), not both")

    def gait(self):
        """The gait to walk (None when holding a pose).

        Raises:
            ValueError, FileNotFoundError: a malformed or missing θ file.
        """
        if self.pose is not None:
            return None
        from robots import get_robot
        from walk_engine import params_for

        P = params_for(get_robot(self.robot))
        return P.load(self.params) if self.params else P.initial()


def live_rollouts(cfg: LiveConfig, gait=None) -> tuple[dict, dict, list[str]]:
    """One rollout per world (every world built before any rollout runs).

    Args:
        gait: :meth:`LiveConfig.gait` (read here when not given).

    Returns:
        (label -> ``envs.Recording``, label -> the terrain it walked, notes: one line per file written).
    """
    from envs import HoldPose, make_world, rollout  # lazy: loads the engines
    from experiments.runtime.rundir import record_path
    from experiments.runtime.worlds import load_transformer
    from experiments.viz import plan_from_engine
    from robots import get_robot
    from sgat.transformer import GroundedEnv  # lazy: sgat loads torch
    from walk_engine import WalkEngine

    robot = get_robot(cfg.robot)
    params = gait if gait is not None else cfg.gait()
    envs = {}
    try:
        for w in cfg.worlds:
            if w == "real":
                envs[w] = make_world("real", robot=robot, profile=cfg.profile, stochasticity=cfg.stochasticity)
            elif w == "sim":
                envs[w] = make_world("sim", robot=robot)
            else:
                envs[w] = GroundedEnv(make_world("sim", robot=robot), load_transformer(cfg.transformer))
        recs, terrains, notes = {}, {}, []
        for w, env in envs.items():
            meta = {"world": w}
            if params is not None:
                ctrl = WalkEngine(robot, params)
                meta["params"] = params.to_dict()
            else:
                ctrl = HoldPose(robot, cfg.pose)
            rec = rollout(env, ctrl, seed=cfg.seed, seconds=cfg.seconds, meta=meta)
            if hasattr(ctrl, "diagnostics"):
                rec = plan_from_engine(rec, ctrl.diagnostics())
            recs[w], terrains[w] = rec, env.unwrapped.terrain
            if cfg.record:
                notes.append(f"{w}: recording -> {rec.to_parquet(record_path(cfg.record, w, len(cfg.worlds)))}")
    finally:
        for env in envs.values():
            env.close()
    return recs, terrains, notes


__all__ = ["LIVE_WORLDS", "LiveConfig", "live_rollouts"]
