"""What a fidelity run gives (``fidelity.json``), as typed structures other modules read.

``sgatwalk compare`` ranks the worlds of several saved results; the docs render them. These
``TypedDict`` types say what each entry holds (figures per draw, their summary over the draws, the
real trials' figures, the paired tests); :func:`load_result` reads and checks one file.
"""

from __future__ import annotations

import json
from typing import TypedDict


class OverDraws(TypedDict):
    """One figure over a world's draws."""

    median: float
    min: float
    max: float
    spread: float


class DrawScores(TypedDict, total=False):
    """One draw of a world against the real trials (``experiments.fidelity.scoring.draw_metrics``)."""

    draw: int
    fitness: list[float]          # the world's mean fitness per gait
    fall_rate: list[float]        # the world's fall frequency per gait
    fitness_episodes: list[list[float]]  # (gaits, episodes)
    rho: float                    # Spearman ρ with the real fitness
    mae: float                    # mean absolute error [fitness points]
    bias: float                   # mean(world − real) [fitness points]
    brier: float                  # Brier score of the fall frequencies against the real falls
    pick_regret: float            # real fitness lost by taking the world's best gait
    rho_ci90: list[float]         # 90 % bootstrap interval of ρ over the real trials
    world_ceiling: float | None   # the ceiling of ρ the world's own episode noise allows


class WorldScores(TypedDict, total=False):
    """One training world of a run."""

    kind: str
    episodes: int
    deterministic: bool
    draws: list[DrawScores]
    summary: dict                 # {"rho", "mae", "bias", "brier", "pick_regret": OverDraws, "abs_bias_median", "draws"}
    grounding: dict | None
    by_episodes: dict


class RealScores(TypedDict, total=False):
    """The real trials of a run's panel."""

    fitness: list[float]          # mean per gait
    fitness_se: list[float]
    fall_rate: list[float]
    trials: int
    fitness_trials: list[list[float]]  # (gaits, trials)
    reliability: float            # split-half reliability of the gaits' means
    ceiling: float                # the ceiling of ρ that the trials' noise allows


class PairedTest(TypedDict):
    """ρ(world) − ρ(reference), paired over the draws (``experiments.runtime.stats.paired_test``)."""

    world: str
    reference: str
    diff: float
    per_draw: list[float]
    ci: list[float]
    p_value: float
    ci_panel: list[float]
    p_value_panel: float
    n_boot: int


class FidelityResult(TypedDict, total=False):
    """A run's ``fidelity.json``."""

    config: dict
    gaits: list[str]
    real: RealScores
    worlds: dict[str, WorldScores]
    paired: list[PairedTest]
    groups: list[dict]
    wall_s: float
    phases_s: dict


def is_fidelity_result(doc) -> bool:
    """Whether a JSON document is a fidelity result (it has real trials, worlds and gaits)."""
    return isinstance(doc, dict) and isinstance(doc.get("real"), dict) and "fitness" in doc["real"] \
        and isinstance(doc.get("worlds"), dict) and "gaits" in doc


def check_result(res: FidelityResult, path: str) -> None:
    """Raise ValueError naming ``path`` and the world where a fidelity result lacks what a ranking reads."""
    n = len(res["real"]["fitness"])
    for key in ("fall_rate", "ceiling"):
        if key not in res["real"]:
            raise ValueError(f"{path}: the real trials have no {key!r}")
    for name, w in res["worlds"].items():
        draws = w.get("draws") if isinstance(w, dict) else None
        if not draws or not isinstance(w.get("summary"), dict):
            raise ValueError(f"{path}: world {name!r} has no draws or summary")
        for d in draws:
            if not all(k in d for k in ("rho", "brier", "fitness")) or len(d["fitness"]) != n:
                raise ValueError(f"{path}: world {name!r}: a draw without rho, brier or one fitness per gait")


def load_result(path: str) -> FidelityResult | None:
    """The fidelity result in a JSON file (a run's ``fidelity.json`` or a saved result
    ``{"command", "result", ...}`` of ``docs/results/``), checked; None for another JSON document.

    Raises:
        ValueError: not JSON, or a fidelity result that lacks what a ranking reads (named).
    """
    try:
        with open(path) as f:
            doc = json.load(f)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON ({exc})") from None
    res = doc.get("result") if isinstance(doc, dict) and "command" in doc and "result" in doc else doc
    if not is_fidelity_result(res):
        return None
    check_result(res, path)
    return res


__all__ = ["DrawScores", "FidelityResult", "OverDraws", "PairedTest", "RealScores", "WorldScores", "check_result",
           "is_fidelity_result", "load_result"]
