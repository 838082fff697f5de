"""Effect classes of the blind benchmark and the constants the referee and the scorer share.

``FAMILIES`` / ``CLASSES`` (fixed base, per world) and ``CLASSES_FLOATING`` (standing/stepping) are
the hidden-effect classes a trial can draw; ``SEED_ORDER`` fixes the class index behind each trial's
seed; ``NOMINAL`` is each family's no-effect value (the scale of the relative parameter error);
``NOISE``, ``ANGLE_NOISE``, ``GYRO_NOISE`` are the recordings' sensor noise levels.
"""

from __future__ import annotations

FAMILIES = ["latency", "backlash", "coulomb_friction", "viscous_damping", "pd_gain", "torque_limit", "link_mass",
            "armature", "sensor_bias", "joint_compliance"]
#: Classes the referee can inject that the tool's default library does not screen (``--extra-classes``):
#: a torque-constant error (kp and kd scaled together) and a parallel joint spring
#: (``sysid.candidates.OPTIONAL_FAMILIES``).
OPTIONAL_CLASSES = ["torque_constant", "parallel_spring"]
CLASSES = {"sim": ["none"] + FAMILIES, "real": ["none"] + [f for f in FAMILIES if f != "armature"]}
#: Floating-base (standing/stepping) classes; PyBullet ground compliance is a stiffness/damping pair
#: with no one-to-one map to MuJoCo's solref time constant, so it is run in the sim world only.
#: Terrain roughness: every log on a fresh sparse-bump field (``terrain.lumpy`` via
#: ``sysid.worlds.rough_ground``; the tool's model is a dense Gaussian random field).
CLASSES_FLOATING = {"sim": ["none", "foot_friction", "ground_compliance", "terrain_roughness"],
                    "real": ["none", "foot_friction", "terrain_roughness"]}
#: Class order behind each trial's seed (appending keeps earlier trials' draws unchanged).
SEED_ORDER = ("none", "latency", "backlash", "coulomb_friction", "viscous_damping", "pd_gain", "torque_limit",
              "link_mass", "armature", "sensor_bias", "none", "foot_friction", "ground_compliance",
              "terrain_roughness", "joint_compliance", "torque_constant", "parallel_spring")
NOMINAL = {"latency": 0.0, "backlash": 0.0, "coulomb_friction": 0.0, "viscous_damping": 0.0, "pd_gain": 1.0,
           "torque_constant": 1.0, "parallel_spring": 0.0,
           "joint_compliance": 0.0, "torque_limit": 1.0, "link_mass": 1.0, "armature": 0.0, "sensor_bias": 0.0, "foot_friction": 0.8,
           "ground_compliance": 0.01, "terrain_roughness": 0.0}
ANGLE_NOISE, GYRO_NOISE = 2e-3, 1e-2  # floating base: torso roll/pitch [rad], gyro [rad/s]
NOISE = 1e-3  # encoder noise [rad]
MIN_LINK_MASS = 0.1  # links lighter than this are not drawn for mass errors [kg]
