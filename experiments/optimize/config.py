"""Settings of ``sgatwalk optimize``: the training worlds (methods), CMA-ES and the real trials."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from common.defaults import EPISODE_SECONDS
from experiments.runtime.worlds import WorldSpec, parse_world, parse_worlds

#: Seed purposes of an optimization run (:func:`experiments.runtime.seeds.derive_seeds` ``(seed, purpose, ...)``).
REAL_WALKS, SIM_WALKS, CMA_RANDN, GENERATION, SELECTION, EVALUATION, IDENTIFICATION = 1, 2, 3, 4, 5, 6, 8
#: The file a run's checkpoint is written to (replaced atomically after every generation).
STATE_FILE = "cma_state.pkl"
#: The robots whose physics ``sgatwalk diagnose`` identifies (the identified and hybrid worlds).
IDENTIFIED_ROBOTS = ("nao",)


def default_methods(robot: str = "nao") -> tuple[str, ...]:
    """The training worlds ``sgatwalk optimize`` runs when none are named: ``hybrid`` for the NAO (SGAT
    grounding on the identified sim: the fittest grounded world of Table I and the best ranked of the
    fidelity panel, docs/decisions.md), ``sgat`` for the other robots, whose physics the diagnosis does
    not identify."""
    return ("hybrid",) if robot in IDENTIFIED_ROBOTS else ("sgat",)


#: Option presets: ``quick`` is the defaults; ``paper`` the SGAT paper's budgets (population 150, 20
#: generations, 10 real and 10 sim walks per grounding step, 2 episodes per candidate).
PRESETS = {
    "quick": {},
    "paper": {"popsize": 150, "generations": 20, "seconds": 7.5, "grounding_steps": 2, "eval_trials": 10,
              "episodes_per_candidate": 2, "world_options": {"real": 10, "sim": 10}},
}


@dataclass
class OptimizeConfig:
    """Settings of one optimization run (written to ``config.yaml``).

    Attributes:
        methods: training worlds (``experiments.runtime.worlds`` texts, e.g. ``("hybrid",
            "sgat:alpha=0.3")``); each runs Algorithm 1 on the run's seeds.
        grounding_steps: grounding steps per method.
        popsize, generations, sigma0: CMA-ES population, generations per grounding step and initial
            step size on the [0, 1]-normalized parameters.
        trust_region: the search box ±r around θ_i (normalized; 1: off): the grounding models were
            fitted on θ_i's data and do not hold far from it.
        episodes_per_candidate: episodes per candidate and generation (common random numbers).
        select_episodes: episodes on which the CMA-ES mean, the best candidate and θ_i are compared.
        seconds: episode length [s] (the paper: 7.5).
        eval_trials: real trials of each θ_{i+1} (0: none).
        profile: the real world's effect profile.
        stochasticity: the real world's per-step randomness level (``envs.effects.Stochasticity``; 0: none).
        aggregate: fit each grounding step on the walks of every θ_j so far (the GARAT code) or on θ_i's only.
        seed: run seed; params: a θ0 file (None: the walk engine's θ0); robot: ``robots.get_robot`` name.
    """

    methods: tuple = default_methods()
    grounding_steps: int = 2
    popsize: int = 12
    generations: int = 30
    sigma0: float = 0.05
    trust_region: float = 0.15
    episodes_per_candidate: int = 1
    select_episodes: int = 8
    seconds: float = EPISODE_SECONDS
    eval_trials: int = 10
    profile: str = "real"
    stochasticity: float = 0.0
    aggregate: bool = True
    seed: int = 0
    params: str | None = None
    robot: str = "nao"

    def __post_init__(self) -> None:
        self.methods = tuple(s.name for s in parse_worlds(self.methods)) if self.methods else ()

    @property
    def specs(self) -> list[WorldSpec]:
        """The training worlds, parsed."""
        return [parse_world(m) for m in self.methods]

    def validate(self) -> None:
        """Raises ValueError naming the bad setting."""
        from robots import ROBOT_NAMES  # lazy: the robots package parses nothing at import

        if self.robot not in ROBOT_NAMES:
            raise ValueError(f"unknown robot {self.robot!r}; choose from {', '.join(ROBOT_NAMES)}")
        if not self.methods:
            raise ValueError("no method (training world) given")
        if self.robot not in IDENTIFIED_ROBOTS and any(s.needs_identification for s in self.specs):
            raise ValueError("the identified and hybrid worlds model the NAO only (sgatwalk diagnose identifies the NAO)")
        for name in ("grounding_steps", "popsize", "generations", "episodes_per_candidate", "select_episodes"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if int(self.eval_trials) < 0:
            raise ValueError(f"eval_trials must be >= 0 (0: no real evaluation), got {self.eval_trials}")
        if self.popsize < 2:
            raise ValueError("popsize must be >= 2")
        if not (0 < self.sigma0 <= 1):
            raise ValueError(f"sigma0 must be in (0, 1] (normalized parameters), got {self.sigma0}")
        if not (0 < self.trust_region <= 1):
            raise ValueError(f"trust_region must be in (0, 1] (normalized half-width), got {self.trust_region}")
        if not (self.seconds > 0 and math.isfinite(self.seconds)):
            raise ValueError(f"seconds must be positive, got {self.seconds}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        if not (math.isfinite(self.stochasticity) and self.stochasticity >= 0):
            raise ValueError(f"stochasticity must be a number >= 0, got {self.stochasticity}")

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["methods"] = list(self.methods)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> OptimizeConfig:
        """The config a saved run holds (:meth:`to_dict`).

        Raises:
            ValueError: settings this version does not know (a run directory of an earlier version).
        """
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"the run was saved with settings this version does not have ({', '.join(unknown)}); "
                             "start a new run")
        return cls(**{**d, "methods": tuple(d["methods"])})


def with_preset(preset: str, **settings) -> OptimizeConfig:
    """An :class:`OptimizeConfig` of ``preset`` (:data:`PRESETS`) with ``settings`` on top; the preset's
    ``world_options`` (the paper's walks per grounding step) go to every grounded method that does not
    set them.

    Raises:
        ValueError: an unknown preset, a bad world or setting.
    """
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; choose from {', '.join(PRESETS)}")
    p = dict(PRESETS[preset])
    opts = p.pop("world_options", {})
    robot = settings.get("robot", "nao")
    methods = settings.pop("methods", None) or default_methods(robot)
    specs = parse_worlds(methods)
    if opts:
        specs = [parse_world(":".join([s.name] + [f"{k}={v}" for k, v in opts.items() if k not in dict(s.options)]))
                 if s.grounded else s for s in specs]
    cfg = OptimizeConfig(**{**p, **settings, "methods": tuple(s.name for s in specs)})
    cfg.validate()
    return cfg


__all__ = ["CMA_RANDN", "EVALUATION", "GENERATION", "IDENTIFICATION", "IDENTIFIED_ROBOTS", "PRESETS", "REAL_WALKS",
           "SELECTION", "SIM_WALKS", "STATE_FILE", "OptimizeConfig", "default_methods", "with_preset"]
