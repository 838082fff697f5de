"""ZMP walk engine for the NAO-like robot and other humanoids, pure NumPy/SciPy (no physics engine
is imported).

GaitParams (the 16; per robot: params_for) -> FootstepPlanner -> ZmpPreview (Kajita 2003) -> swing
trajectory -> leg IK (the NAO's closed form with the shared HipYawPitch; other robots: LegChain) ->
gyro feedback -> joint targets at 100 Hz (WalkEngine). See walk_engine/README.md.
"""

from walk_engine.engine import WalkEngine
from walk_engine.footsteps import STAND, FootstepPlanner, Phase, WalkCommand, plan_phases
from walk_engine.legs import LegChain
from walk_engine.params import NAMES, N_PARAMS, SPECS, GaitParams, ParamSpec, params_for
from walk_engine.preview import ZmpPreview, cart_table, preview_gains

__all__ = ["NAMES", "N_PARAMS", "SPECS", "STAND", "FootstepPlanner", "GaitParams", "LegChain", "ParamSpec", "Phase",
           "WalkCommand", "WalkEngine", "ZmpPreview", "cart_table", "plan_phases",
           "params_for", "preview_gains"]
