"""``sgatwalk optimize``: Algorithm 1 of the SGAT paper with CMA-ES over the 16 gait parameters.

Public API (what other experiments use): :class:`OptimizeConfig` (``config``), :class:`Optimizer`
(``run``, loads the engines), the result types of ``results``.
"""

from experiments.optimize.config import OptimizeConfig, default_methods, with_preset
from experiments.optimize.results import OptimizeResult, RealData, StepRow


def __getattr__(name: str):
    if name in ("Optimizer", "identify", "slug"):  # they load the engines and torch: only when asked for
        from experiments.optimize import run

        return getattr(run, name)
    raise AttributeError(f"module 'experiments.optimize' has no attribute {name!r}")


__all__ = ["OptimizeConfig", "OptimizeResult", "Optimizer", "RealData", "StepRow", "default_methods", "identify", "slug",
           "with_preset"]
