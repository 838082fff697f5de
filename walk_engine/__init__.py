"""ZMP walk engine for the NAO-like robot, pure NumPy/SciPy (no physics engine is imported).

GaitParams (the 16) -> FootstepPlanner -> ZmpPreview (Kajita 2003) -> swing trajectory -> analytic
leg IK with the shared HipYawPitch -> gyro feedback -> 23 joint targets at 100 Hz (WalkEngine).
See walk_engine/README.md.
"""

from walk_engine.engine import WalkEngine, observation_slices
from walk_engine.footsteps import STAND, FootstepPlanner, Phase, WalkCommand, plan_phases
from walk_engine.params import NAMES, N_PARAMS, SPECS, GaitParams, ParamSpec
from walk_engine.preview import ZmpPreview, cart_table, preview_gains

__all__ = ["NAMES", "N_PARAMS", "SPECS", "STAND", "FootstepPlanner", "GaitParams", "ParamSpec", "Phase",
           "WalkCommand", "WalkEngine", "ZmpPreview", "cart_table", "observation_slices", "plan_phases",
           "preview_gains"]
