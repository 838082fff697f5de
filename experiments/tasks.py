"""Picklable rollout tasks for the executors: one walk episode in a named world.

A task is a plain dict (so it pickles cheaply and travels to process-pool or Ray workers):

====================  =====================================================================
key                   meaning
====================  =====================================================================
``world``             ``"sim"`` (MuJoCo), ``"real"`` (PyBullet), ``"grounded"`` (MuJoCo wrapped
                      in ``sgat.GroundedEnv`` with the transformer saved in ``transformer``)
``theta``             the 16 gait parameters in SI units (list)
``seed``              the episode seed (terrain, effects, noise, SGAT sampling)
``seconds``           episode length [s] (the paper: 7.5)
``profile``           real-world effect profile name (real world only)
``action_noise``      std [rad] of Gaussian noise on the applied leg targets (sim data
                      collection with exploration noise, or the ANE baseline)
``transformer``       directory of a saved ``sgat.ActionTransformer`` (grounded world)
``record``            return the recording too (columns + metadata)
``meta``              extra metadata for the recording
====================  =====================================================================

Workers cache worlds and transformers per process, so a generation of CMA-ES builds each once.
Torch is kept to one thread in workers (``experiments.executors``).
"""

from __future__ import annotations

import os

import numpy as np

_WORLDS: dict = {}
_TRANSFORMERS: dict = {}


def _transformer(path: str):
    from sgat.transformer import ActionTransformer

    key = (path, os.path.getmtime(os.path.join(path, "transformer.json")))
    if key not in _TRANSFORMERS:
        _TRANSFORMERS.clear()
        _TRANSFORMERS[key] = ActionTransformer.load(path)
    return _TRANSFORMERS[key]


def _world(task: dict):
    from envs import NaoRealEnv, NaoSimEnv
    from envs.wrappers import ActionMismatch
    from sgat.transformer import GroundedEnv, GroundingSpec

    world = task["world"]
    key = (world, task.get("profile", "real"), task.get("terrain", "lumpy"))
    if key not in _WORLDS:
        if world == "real":
            _WORLDS[key] = NaoRealEnv(profile=task.get("profile", "real"), terrain=task.get("terrain", "lumpy"))
        elif world in ("sim", "grounded"):
            _WORLDS[key] = NaoSimEnv()
        else:
            raise ValueError(f"unknown world {world!r}; choose sim, real or grounded")
    env = _WORLDS[key]
    sigma = float(task.get("action_noise", 0.0) or 0.0)
    if sigma > 0:
        legs = GroundingSpec.for_nao(env).action_index
        env = ActionMismatch(env, noise_std=sigma, index=legs, seed=task["seed"])
    if world == "grounded":
        env = GroundedEnv(env, _transformer(task["transformer"]))
    return env


def run_episode(task: dict) -> dict:
    """Run one walk episode; returns the fitness metrics (and the recording if asked).

    Returns:
        dict with ``fitness``, ``speed_cm_s``, ``fell``, ``fall_reason``, ``fall_time_s``,
        ``drift_m``, ``distance_m``, ``seed``, and ``recording`` = (columns, meta) if
        ``task["record"]``. A NaN or exploding simulation counts as a fall ("unstable").
    """
    from experiments.fitness import run_walk
    from walk_engine import GaitParams

    env = _world(task)
    params = GaitParams.from_array(np.asarray(task["theta"], dtype=float))
    rec, res = run_walk(params, seed=int(task["seed"]), seconds=float(task.get("seconds", 7.5)), env=env)
    rec.meta.update({"world": task["world"], **task.get("meta", {})})
    out = res.to_dict()
    out["seed"] = int(task["seed"])
    if task.get("record"):
        out["recording"] = (rec.columns, rec.meta)
    return out
