"""Settings of ``sgatwalk fidelity`` and the names of its gaits."""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass

from common.defaults import EPISODE_SECONDS
from experiments.runtime.rundir import distinct_suffixes
from experiments.runtime.worlds import WorldSpec, parse_worlds

#: The training worlds a run scores unless told otherwise: every kind but the real world itself.
DEFAULT_WORLDS = ("sim", "ane", "gat", "sgat", "identified", "hybrid")
#: Seed purposes (the first key after the run seed, :func:`experiments.runtime.seeds.derive_seeds`).
#: 18 drew the engine-gap calibration's seed before that became one constant; the numbers stay as they
#: are so that every stream keeps its values.
PANEL, REAL, GROUND_REAL, GROUND_SIM, WORLD, FIT, IDENT, DATA_GAITS, REAL_WORLD = 11, 12, 13, 14, 15, 16, 17, 19, 20
#: The phases of a run, in run order, whose wall time ``fidelity.json`` reports (``phases_s``).
PHASES = ("real trials", "excitation logs", "diagnoses", "grounding walks", "fits", "world episodes",
          "teacher forcing")


def param_gait_names(paths) -> list[str]:
    """Panel names of the θ files ``paths``: each file's name without its extension, or, where two
    files share it (``table1/opt_seed0/thetas/sgat_step1.json`` and ``.../opt_seed1/...``), the
    shortest trailing part of their paths that tells them apart (``opt_seed0/thetas/sgat_step1``).
    Names key the cached trials, so two gaits must never share one.

    Raises:
        ValueError: the same file given twice, or a name that clashes with ``theta0``/``boxNN``.
    """
    parts = [os.path.normpath(os.path.splitext(p)[0]).split(os.sep) for p in paths]
    real = [os.path.realpath(p) for p in paths]
    if len(set(real)) != len(real):
        raise ValueError(f"params: the same θ file is given twice: {sorted({p for p, r in zip(paths, real) if real.count(r) > 1})}")
    names = distinct_suffixes(parts)
    for name in names:
        if name == "theta0" or (name.startswith("box") and name[3:].isdigit()):
            raise ValueError(f"params: the gait name {name!r} clashes with the panel's own gaits; rename the file")
    return names


@dataclass
class FidelityConfig:
    """Settings of a fidelity run (written to ``config.json``).

    Attributes:
        worlds: training worlds (``experiments.runtime.worlds`` texts).
        gaits: gaits drawn uniformly in ±``box`` around θ0 in the normalized space CMA-ES searches,
            besides θ0; params: θ files added to the panel.
        real_trials: paired real trials per gait (trial j of every gait on the same seed).
        data_seeds: independent draws of the real data every learned world is fitted on.
        episodes: episodes per gait in a stochastic world (a deterministic one walks one).
        seconds: episode length [s]; profile: the real world's effect profile.
        stochasticity: the real world's per-step randomness level (``envs.effects.Stochasticity``; 0: none).
        identify_fixed_logs, identify_floating_logs, identify_seconds: excitation logs per
            identification (in the air, stepping) and their length [s].
        identify_budget_s: wall-clock budget of each diagnosis [s], a safety net; not part of the
            run's identity.
        bootstrap: bootstrap replicates of the intervals and paired tests.
        seed: the run seed (panel, trials, data draws); robot: ``robots.get_robot`` name.
    """

    #: Settings a run directory may be resumed with changed: more worlds, other episode counts, another
    #: bootstrap or identification budget reuse what was measured.
    RESUMABLE = ("worlds", "episodes", "bootstrap", "identify_budget_s")

    worlds: tuple = DEFAULT_WORLDS
    gaits: int = 15
    box: float = 0.15
    params: tuple = ()
    real_trials: int = 10
    data_seeds: int = 5
    episodes: int = 8
    seconds: float = EPISODE_SECONDS
    profile: str = "real"
    stochasticity: float = 0.0
    identify_fixed_logs: int = 3
    identify_floating_logs: int = 3
    identify_seconds: float = 6.0
    identify_budget_s: float = 180.0
    bootstrap: int = 1000
    seed: int = 0
    robot: str = "nao"

    def __post_init__(self) -> None:
        self.worlds = tuple(s.name for s in parse_worlds(self.worlds)) if self.worlds else ()
        self.params = tuple(self.params)

    def validate(self) -> list[WorldSpec]:
        """The parsed worlds; raises ValueError naming the bad setting."""
        from robots import ROBOT_NAMES

        if self.robot not in ROBOT_NAMES:
            raise ValueError(f"unknown robot {self.robot!r}; choose from {', '.join(ROBOT_NAMES)}")
        for name in ("real_trials", "data_seeds", "episodes", "bootstrap"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.real_trials < 2:
            raise ValueError("real_trials must be >= 2 (the ceiling needs a split-half reliability)")
        if self.gaits < 0:
            raise ValueError(f"gaits must be >= 0, got {self.gaits}")
        param_gait_names(self.params)  # raises on a repeated file or a clashing name
        if 1 + self.gaits + len(self.params) < 3:
            raise ValueError("the panel needs at least 3 gaits for a rank correlation")
        if not (0 < self.box <= 1):
            raise ValueError(f"box must be in (0, 1] (normalized half-width), got {self.box}")
        if not (self.seconds > 0 and math.isfinite(self.seconds)):
            raise ValueError(f"seconds must be positive, got {self.seconds}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        if not (math.isfinite(self.stochasticity) and self.stochasticity >= 0):
            raise ValueError(f"stochasticity must be a number >= 0, got {self.stochasticity}")
        if self.identify_fixed_logs < 2 or self.identify_floating_logs < 0:
            raise ValueError("identification needs >= 2 fixed-base logs (a held-out split) and >= 0 stepping logs")
        specs = parse_worlds(self.worlds)
        if self.robot != "nao" and any(s.needs_identification for s in specs):
            raise ValueError("the identified and hybrid worlds model the NAO only (sgatwalk diagnose identifies the NAO)")
        return specs

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["worlds"], d["params"] = list(self.worlds), list(self.params)
        return d

    @property
    def params_class(self):
        """The robot's :class:`walk_engine.GaitParams` class (``walk_engine.params_for``)."""
        from robots import get_robot
        from walk_engine import params_for

        return params_for(get_robot(self.robot))


__all__ = ["DEFAULT_WORLDS", "PHASES", "FidelityConfig", "param_gait_names"]
