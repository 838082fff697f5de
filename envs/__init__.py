"""The two worlds as gymnasium environments: MuJoCo "sim" and PyBullet "real" (of any humanoid
``robots.RobotModel``); their effects, rollouts and recordings.

The worlds load on first use (PEP 562), so that importing the package (the effect profiles, the
recordings) loads no physics engine.
"""

from __future__ import annotations

import importlib

# light (NumPy, the robot model): loaded with the package, so that ``envs.rollout`` is the function
# even after the module of the same name is imported
from envs.effects import EFFECTS, PROFILES, EffectDraw, RealProfile, get_profile
from envs.recording import Recording, RecordingError
from envs.rollout import CommandLog, HoldPose, rollout

_WHERE = {
    "HumanoidEnv": "envs.base", "ObservationLayout": "envs.base", "NaoEnv": "envs.base",
    "RealWorld": "envs.bullet_world", "NaoRealEnv": "envs.bullet_world",
    "SimWorld": "envs.mujoco_world", "NaoSimEnv": "envs.mujoco_world",
}

__all__ = sorted(_WHERE) + ["CommandLog", "EFFECTS", "EffectDraw", "HoldPose", "PROFILES", "RealProfile", "Recording",
                            "RecordingError", "get_profile", "make_world", "rollout"]


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(importlib.import_module(_WHERE[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'envs' has no attribute {name!r}")


def make_world(world: str, **kwargs):
    """``"sim"`` -> :class:`envs.mujoco_world.SimWorld`, ``"real"`` -> :class:`envs.bullet_world.RealWorld`
    (kwargs passed on; the sim takes no ``profile``).

    Raises:
        ValueError: unknown world.
    """
    if world == "sim":
        kwargs.pop("profile", None)
        return __getattr__("SimWorld")(**kwargs)
    if world == "real":
        return __getattr__("RealWorld")(**kwargs)
    raise ValueError(f"unknown world {world!r}; choose 'sim' or 'real'")
