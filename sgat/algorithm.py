"""Algorithm 1 of Desai et al., "Stochastic Grounded Action Transformation for Robot Learning in
Simulation", IROS 2020 (the GAT/SGAT loop of Hanna & Stone, AAAI 2017), once for every domain.

Each grounding step i:

1. **ground**: collect real data with the current policy π_i (and sim data), fit the forward model
   of the real world and the inverse model of the sim, build the action transformer g_i;
2. **improve**: improve the policy in the sim grounded by g_i (CMA-ES for the NAO walk, TRPO for
   the MuJoCo gym tasks, policy iteration for the tabular MDPs), giving a candidate π_{i+1};
3. **evaluate** (optional): measure the candidate in the real world, log it;

then π_{i+1} becomes the current policy. What collects, fits, improves and evaluates is passed in,
so the loop is the same for ``experiments.optimize.run`` (the NAO walk), ``experiments.gym.run``
(InvertedPendulum, HalfCheetah) and ``sgat.tabular`` (Cliff Walking).

The loop state is a plain dict (``progress``) updated after every stage and handed to ``save``: a run
killed at any point resumes by calling :func:`grounding_loop` again with the saved dict, and no
finished stage runs twice.
"""

from __future__ import annotations

from typing import Any, Callable

#: The stages of one grounding step, in order.
STAGES = ("ground", "improve", "evaluate")


def new_progress(policy: Any) -> dict:
    """The loop state before the first grounding step: step 1, stage ``ground``, policy π_0."""
    return {"step": 1, "stage": "ground", "policy": policy, "model": None, "candidate": None}


def grounding_loop(progress: dict, steps: int, *, ground: Callable[[int, Any], Any],
                   improve: Callable[[int, Any, Any, dict], Any],
                   evaluate: Callable[[int, Any, dict], None] | None = None,
                   stop: Callable[[int, dict], bool] | None = None,
                   save: Callable[[], None] | None = None) -> dict:
    """Run (or resume) grounding steps ``progress["step"]`` … ``steps``.

    Args:
        progress: loop state from :func:`new_progress` (or a saved one); updated in place: ``step``
            (1-based, ``steps + 1`` when done), ``stage`` (one of :data:`STAGES`), ``policy`` (π_i),
            ``model`` (what ``ground`` returned for this step), ``candidate`` (π_{i+1} once improved).
            Callers may keep their own keys in it (e.g. an optimizer's checkpoint).
        steps: number of grounding steps.
        ground: ``ground(i, π_i) -> model`` (the transformer, or a handle to it: what ``save`` can
            store).
        improve: ``improve(i, π_i, model, progress) -> π_{i+1}``.
        evaluate: ``evaluate(i, π_{i+1}, progress)``, e.g. real trials of the candidate.
        stop: ``stop(i, progress) -> bool`` after step i (e.g. the policy has converged).
        save: called after every stage (a checkpoint).

    Returns:
        ``progress``; the final policy is ``progress["policy"]``.

    Raises:
        ValueError: ``steps`` < 0, or a stage name not in :data:`STAGES`.
    """
    if steps < 0:
        raise ValueError(f"steps must be >= 0, got {steps}")
    save = save or (lambda: None)
    while progress["step"] <= steps:
        i = progress["step"]
        if progress["stage"] not in STAGES:
            raise ValueError(f"unknown stage {progress['stage']!r} in the loop state; expected one of {STAGES}")
        if progress["stage"] == "ground":
            progress["model"] = ground(i, progress["policy"])
            progress["stage"] = "improve"
            save()
        if progress["stage"] == "improve":
            progress["candidate"] = improve(i, progress["policy"], progress["model"], progress)
            progress["stage"] = "evaluate"
            save()
        if progress["stage"] == "evaluate":
            if evaluate is not None:
                evaluate(i, progress["candidate"], progress)
            progress.update(step=i + 1, stage="ground", policy=progress["candidate"], model=None, candidate=None)
            save()
        if stop is not None and stop(i, progress):
            break
    return progress


__all__ = ["STAGES", "grounding_loop", "new_progress"]
