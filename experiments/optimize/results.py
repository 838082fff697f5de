"""What an optimization run gives: its Table I rows and the real data each method learned from.

The types here are what other experiments read of an optimization (``sgatwalk table1`` runs one per
optimization seed) and what ``sgatwalk optimize --json`` prints.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class StepRow:
    """One row of the paper's Table I: a method's gait after a grounding step, in the real world.

    Attributes:
        method: the training world (``experiments.runtime.worlds`` text) or ``"theta0"``.
        step: the grounding step (0 for θ0).
        trials: real trials walked (0: no real evaluation).
        speed_mean, speed_std: forward speed over the trials [cm/s] (mean, standard deviation).
        falls: trials that ended in a fall.
        fitness_mean: mean fitness (speed − 15 per fall).
        theta: the gait, 16 values in SI units (None for θ0's row).
        select_scores: the training world's fitness of the three candidates θ_{i+1} was chosen from
            (``mean``, ``best``, ``incumbent``), or None.
        episodes: the trials one by one (``seed``, ``speed_cm_s``, ``fell``, ``fall_reason``, ``fitness``).
    """

    method: str
    step: int
    trials: int = 0
    speed_mean: float | None = None
    speed_std: float | None = None
    falls: int | None = None
    fitness_mean: float | None = None
    theta: list | None = None
    select_scores: dict | None = None
    episodes: list = field(default_factory=list)

    @classmethod
    def from_dict(cls, d: dict) -> StepRow:
        return cls(**{k: d[k] for k in cls.__dataclass_fields__ if k in d})


@dataclass(frozen=True)
class RealData:
    """The real data one method learned from: grounding walks (count, seconds of recording) and the
    identification's excitation logs (count, seconds)."""

    walks: int
    walk_seconds: float
    excitation_logs: int
    excitation_seconds: float


@dataclass(frozen=True)
class GenerationTimes:
    """A method's CMA-ES generations at one grounding step: measured wall time (median and range [s])
    beside the estimate made before them (None where none was kept)."""

    method: str
    step: int
    generations: int
    median_s: float
    min_s: float
    max_s: float
    expected_s: float | None


@dataclass(frozen=True)
class OptimizeResult:
    """An optimization run's outcome.

    Attributes:
        run_dir: its directory.
        robot: the robot it optimized.
        theta0: the initial gait (SI).
        rows: Table I, θ0 first (:class:`StepRow`).
        best: the row with the highest real fitness (None without real trials).
        real_data: per method, :class:`RealData`.
        table: Table I as text.
        generation_s: CMA-ES generation times (:class:`GenerationTimes`).
        wall_s: the run's wall time [s] (this invocation).
    """

    run_dir: str
    robot: str
    theta0: list
    rows: list
    best: StepRow | None
    real_data: dict
    table: str
    generation_s: list
    wall_s: float = 0.0


__all__ = ["GenerationTimes", "OptimizeResult", "RealData", "StepRow"]
