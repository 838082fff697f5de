"""The two worlds as gymnasium environments: MuJoCo "sim" and PyBullet "real"; recordings."""

from envs.base import NaoEnv, ObservationLayout
from envs.bullet_world import NaoRealEnv
from envs.effects import EFFECTS, PROFILES, EffectDraw, RealProfile, get_profile
from envs.mujoco_world import NaoSimEnv
from envs.recording import Recording, RecordingError
from envs.rollout import CommandLog, HoldPose, rollout

__all__ = ["EFFECTS", "PROFILES", "CommandLog", "EffectDraw", "HoldPose", "NaoEnv", "NaoRealEnv", "NaoSimEnv",
           "ObservationLayout", "RealProfile", "Recording", "RecordingError", "get_profile", "rollout"]


def make_world(world: str, **kwargs) -> NaoEnv:
    """``"sim"`` -> :class:`NaoSimEnv`, ``"real"`` -> :class:`NaoRealEnv` (kwargs passed on).

    Raises:
        ValueError: unknown world.
    """
    if world == "sim":
        kwargs.pop("profile", None)
        return NaoSimEnv(**kwargs)
    if world == "real":
        return NaoRealEnv(**kwargs)
    raise ValueError(f"unknown world {world!r}; choose 'sim' or 'real'")


__all__.append("make_world")
