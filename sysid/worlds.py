"""Recording excitation logs of one robot: the same physical effects in every log, fresh noise.

The real world draws its effects anew at every episode reset (``envs.effects.RealProfile``); a
robot diagnosed from several logs must keep the same effects across them. :class:`FrozenProfile`
is a profile whose every draw returns one fixed :class:`envs.effects.EffectDraw` (sensor noise
still comes from each episode's seed); :func:`record_excitation` records the protocol of
:mod:`sysid.excitation` with it.
"""

from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from envs.effects import EffectDraw, RealProfile, get_profile


@dataclass(frozen=True)
class FrozenProfile(RealProfile):
    """A profile whose :meth:`draw` always returns ``frozen`` (a copy)."""

    frozen: Any = None

    def draw(self, rng, n_joints, n_links) -> EffectDraw:  # noqa: D102 - see class docstring
        return copy.deepcopy(self.frozen)


def freeze(profile, seed: int, robot) -> FrozenProfile:
    """Draw ``profile``'s effects once from ``seed`` and freeze them."""
    p = get_profile(profile)
    d = p.draw(np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0]), len(robot.joint_names),
               len(robot.links))
    return FrozenProfile(name=p.name, frozen=d)


def identity_draw(robot, profile_name: str = "custom", **values) -> EffectDraw:
    """An :class:`EffectDraw` at identity with ``values`` overriding fields (arrays per joint/link)."""
    p = get_profile("none").draw(np.random.default_rng(0), len(robot.joint_names), len(robot.links))
    p.profile = profile_name
    for k, v in values.items():
        if not hasattr(p, k):
            raise ValueError(f"unknown effect field {k!r}")
        cur = getattr(p, k)
        setattr(p, k, np.asarray(v, dtype=float) if isinstance(cur, np.ndarray) else float(v))
    return p


def record_excitation(env, out_dir: str, *, n_logs: int = 4, seconds: float = 8.0, seed: int = 0,
                      scale: float = 1.0, pose: str = "crouch", prefix: str = "excite", progress=None,
                      terrain=None, segments=None, shares: dict | None = None) -> list[str]:
    """Record ``n_logs`` protocol logs (trajectory seeds ``seed + i``) in ``env``; returns the paths.

    ``terrain``: None (the world's own ground) or a callable ``i -> Heightfield | None`` giving the
    ground of log ``i`` (e.g. :func:`rough_ground`). ``segments``: the protocol's segments
    (:func:`sysid.excitation.protocol`; None: its default); ``shares``: segment -> share of the log
    (e.g. a D-optimal design; None: the protocol's).

    Raises:
        ValueError: non-positive ``n_logs``; what :func:`sysid.excitation.protocol` raises.
    """
    from envs.rollout import CommandLog, rollout
    from sysid.excitation import protocol

    if n_logs < 1:
        raise ValueError(f"need at least one log, got {n_logs}")
    base = env.unwrapped
    os.makedirs(out_dir, exist_ok=True)
    paths = []
    for i in range(n_logs):
        cmd = protocol(base.robot, seconds, seed=seed + i, control_dt=base.control_dt, pose=pose,
                       fixed_base=base.fixed_base, scale=scale, shares=shares,
                       **({} if segments is None else {"segments": segments}))
        opts = {"pose": pose}
        if terrain is not None:
            opts["terrain"] = terrain(i)
        rec = rollout(env, CommandLog(cmd), seed=seed + i, seconds=seconds, options=opts,
                      meta={"source": "sgatwalk excite (sysid.excitation.protocol)", "excitation_seed": seed + i,
                            **({"excitation_shares": dict(shares)} if shares else {})})
        p = rec.to_parquet(os.path.join(out_dir, f"{prefix}_{i:03d}.parquet"))
        paths.append(p)
        if progress:
            progress(f"{p}: {len(rec)} rows" + (f", fell at {rec.meta['fall_time']:.2f} s" if rec.fell else ""))
    return paths


def rough_ground(amplitude: float, seed: int = 0):
    """Ground for excitation logs on uneven terrain: log ``i`` gets a fresh lumpy heightfield of
    ``amplitude`` [m] (bumps of 8 cm radius) **without** the flat start pad of the walking
    terrains, so the feet stand and step on bumps (a 2 x 2 m patch: the robot steps in place).

    Returns:
        A callable ``i -> terrain.Heightfield`` (None when ``amplitude`` is 0).

    Raises:
        ValueError: negative amplitude.
    """
    from terrain import lumpy

    if amplitude < 0:
        raise ValueError(f"terrain amplitude must be >= 0, got {amplitude}")

    def make(i: int):
        if amplitude == 0:
            return None
        return lumpy(np.random.default_rng([seed, i, 7]), amplitude=amplitude, size=(2.0, 2.0), start_radius=0.0)
    return make
