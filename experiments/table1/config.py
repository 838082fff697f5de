"""Settings of ``sgatwalk table1``."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from experiments.runtime.worlds import parse_worlds

#: Seed purpose of the real trial seeds (:func:`experiments.runtime.seeds.derive_seeds` ``(seed, EVAL)``).
EVAL = 31


@dataclass
class Table1Config:
    """Settings of a Table I run (written to ``config.json``)."""

    #: Settings a run directory may be resumed with changed: more seeds or methods reuse what was done.
    RESUMABLE = ("seeds", "baseline", "methods")

    methods: tuple = ("sgat", "gat", "sim", "ane", "hybrid")
    seeds: int = 3
    trials: int = 30
    seed: int = 0
    optimize: dict = dataclasses.field(default_factory=dict)  # OptimizeConfig overrides (e.g. popsize)
    baseline: str | None = None  # an earlier run's table1.json to pair every row with (compare_runs)

    def __post_init__(self) -> None:
        self.methods = tuple(s.name for s in parse_worlds(self.methods)) if self.methods else ()

    def validate(self) -> None:
        """Raises ValueError naming the bad setting (the baseline's file is checked by
        :func:`experiments.table1.run.load_baseline`)."""
        from experiments.optimize import OptimizeConfig  # the config imports no engine

        if not self.methods:
            raise ValueError("no method (training world) given")
        if self.seeds < 1 or self.trials < 2:
            raise ValueError(f"need >= 1 optimization seed and >= 2 trials, got {self.seeds}, {self.trials}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        OptimizeConfig(**{**self.optimize, "methods": tuple(self.methods)}).validate()

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["methods"] = list(self.methods)
        return d


__all__ = ["EVAL", "Table1Config"]
