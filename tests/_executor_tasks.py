"""Picklable task functions for the executor tests (importable by worker processes)."""

import os

import numpy as np


def short_rollout(seed: int) -> list:
    """A seeded 0.3 s MuJoCo rollout with random leg targets; returns the final joint angles."""
    from envs import SimWorld

    env = SimWorld()
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    a0 = env.robot.pose("crouch", actuated=True)
    for _ in range(30):
        obs, *_ = env.step(a0 + rng.normal(0, 0.05, a0.shape))
    return obs[:24].tolist()


def crash_once(arg):
    """Kill the worker process the first time it runs for ``arg = (marker_path, value)``."""
    marker, value = arg
    if not os.path.exists(marker):
        open(marker, "w").close()
        os._exit(13)
    return value * 2


def always_crash(arg):
    os._exit(13)


def raise_once(arg):
    marker, value = arg
    if not os.path.exists(marker):
        open(marker, "w").close()
        raise RuntimeError("transient failure")
    return value + 1


def write_then_fail(job, executor):
    """A coarse job (``executor.jobs``) that writes its file, then raises if told to."""
    path, fail = job
    with open(path, "w") as f:
        f.write("started")
    if fail:
        raise ValueError(f"bad input in job {path[-5]}")
    return path
