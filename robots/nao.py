"""A NAO-like H25 humanoid built from primitives: one Python spec -> one URDF for both engines.

Kinematics, joint limits, effort/velocity limits and CoM-based inertials are those of the
ros-naoqi V50 URDF (github.com/ros-naoqi/nao_robot,
``nao_description/urdf/naoV50_generated_urdf/nao.urdf``, BSD; its link lengths match Aldebaran's
"H25 - Links" documentation). Collision geometry is primitive (boxes, capsules, spheres); only
the foot sole is sourced: a 160 x 88.8 mm box whose bottom face lies 45.11 mm below the ankle-roll
axis, centred 30 mm forward and 5.62 mm outward of the ankle (the sole outline of
RoboCup SPL team code's B-Human-style robot dimensions, consistent with the FSR and foot-bumper
frames of the V50 URDF).

Design choices (see README "Robot model"):

* No massless frame links. The URDF root is ``torso`` (MuJoCo's URDF import would weld a
  ``base_link`` root to the world; PyBullet gives inertia-less links 1 kg). Sole, IMU and FSR
  frames are exposed as (parent link, offset) :class:`Frame` objects instead.
* 24 hinges: head 2, arms 2x5, legs 2x6; the hands are dropped and their mass stays in
  ``l_wrist``/``r_wrist`` (the V50 URDF's wrist link already carries it).
* ``RHipYawPitch`` mimics ``LHipYawPitch`` (one motor; ``<mimic>`` in the V50 URDF). The action
  space therefore has 23 actuated joints; the right HipYawPitch target always equals the left one.
"""

from __future__ import annotations

import functools
import math

from robots.model import Frame, Geom, Inertial, JointSpec, LegGeometry, RobotModel

# --------------------------------------------------------------------------------------------
# Named lengths [m] (V50 URDF joint origins; Aldebaran "H25 - Links")
NECK_OFFSET_Z = 0.1265
SHOULDER_OFFSET_Y = 0.098
SHOULDER_OFFSET_Z = 0.100
UPPER_ARM_LENGTH = 0.105
ELBOW_OFFSET_Y = 0.015
LOWER_ARM_LENGTH = 0.05595
HIP_OFFSET_Y = 0.050
HIP_OFFSET_Z = 0.085
THIGH_LENGTH = 0.100
TIBIA_LENGTH = 0.1029
FOOT_HEIGHT = 0.04511

# Foot sole (source: module docstring), in the ankle-roll frame of the left foot.
SOLE_LENGTH = 0.160
SOLE_WIDTH = 0.0888
SOLE_CENTER_X = 0.030
SOLE_CENTER_Y_OUT = 0.00562
SOLE_THICKNESS = 0.015  # primitive choice: a 15 mm plate

# IMU in the torso frame (the V50 URDF's ``ImuTorso*`` frames).
GYRO_OFFSET = (-0.008, 0.006, 0.029)
ACCEL_OFFSET = (-0.008, 0.00606, 0.027)
# FSRs in the left ankle-roll frame, at the sole plane (the V50 URDF's ``*Fsr*_frame`` frames);
# right foot mirrors y.
FSR_XY_LEFT = {"FL": (0.07025, 0.0299), "FR": (0.07025, -0.0231), "RL": (-0.03025, 0.0299),
               "RR": (-0.02965, -0.0191)}

_S = 1.0 / math.sqrt(2.0)
#: The NAO's legs (a closed-form IK: ``walk_engine.kinematics``).
NAO_LEG = LegGeometry(HIP_OFFSET_Y, HIP_OFFSET_Z, THIGH_LENGTH, TIBIA_LENGTH, FOOT_HEIGHT)
#: The NAO's sole rectangle in its sole frame, (front, back, inner, outer) [m]: the sole box of the
#: module docstring (160 x 88.8 mm, centred 30 mm forward and 5.62 mm outward of the ankle).
NAO_SOLE = (0.110, -0.050, 0.03878, 0.05002)


# --------------------------------------------------------------------------------------------
# Inertials from the V50 URDF (about the CoM, as URDF expects), left side.
TORSO = Inertial(1.04956, (-0.00413, 0.0, 0.04342),
                 (3.08361e-3, 2.88350e-3, 1.59240e-3, 1.43e-5, -3.30e-5, -2.71e-5))
NECK = Inertial(0.07842, (-0.00001, 0.0, -0.02742), (1.603e-5, 1.704e-5, 5.53e-6, 0, 0, 0))
HEAD = Inertial(0.60533, (-0.00112, 0.0, 0.05258), (9.578e-4, 8.168e-4, 9.850e-4, 8.8e-6, 5.3e-6, -3.0e-5))
PELVIS = Inertial(0.06981, (-0.00781, -0.01114, 0.02661), (2.341e-5, 4.764e-5, 4.970e-5, 1.1e-6, -1.8e-6, 2.8e-6))
HIP = Inertial(0.14053, (-0.01549, 0.00029, -0.00515), (2.384e-5, 6.082e-5, 5.437e-5, -6.5e-7, 7.1e-6, -2.1e-7))
THIGH = Inertial(0.38968, (0.00138, 0.00221, -0.05373), (5.098e-4, 4.654e-4, 3.011e-4, 2.1e-6, 5.64e-5, -7.9e-6))
TIBIA = Inertial(0.30142, (0.00453, 0.00225, -0.04936), (4.462e-4, 3.881e-4, 1.855e-4, 3.7e-6, -3.09e-5, 6.0e-6))
ANKLE_PITCH = Inertial(0.13416, (0.00045, 0.00029, 0.00685), (3.220e-5, 6.794e-5, 5.483e-5, 0.0, 4.3e-6, 2.8e-7))
FOOT = Inertial(0.17184, (0.02542, 0.0033, -0.03239), (8.729e-5, 3.530e-4, 4.128e-4, 8.7e-6, -2.1e-6, 3.7e-7))
SHOULDER = Inertial(0.09304, (-0.00165, -0.02663, 0.00014), (1.830e-5, 1.390e-5, 2.019e-5, 2.1e-6, 0.0, -3.7e-7))
BICEP = Inertial(0.15777, (0.02455, 0.00563, 0.0033), (8.718e-5, 2.747e-4, 2.418e-4, -2.5e-5, -1.4e-5, 4.7e-7))
ELBOW = Inertial(0.06483, (-0.02744, 0.0, -0.00014), (5.60e-6, 2.662e-5, 2.763e-5, 0, 0, 0))
FOREARM = Inertial(0.07761, (0.02556, 0.00281, 0.00076), (2.467e-5, 3.838e-5, 3.597e-5, 3.2e-6, 1.6e-6, 1.4e-7))
WRIST = Inertial(0.18533, (0.03434, -0.00088, 0.00308), (6.865e-5, 1.358e-4, 1.332e-4, 1.2e-7, -2.9e-6, 2.7e-6))

# PD gains [N m/rad], [N m s/rad] per joint family. Explicit PD on armature-free links (PyBullet
# has no joint armature: its ``changeDynamics``, PyBullet Quickstart Guide, offers none) is stable
# only while kd*dt/I and kp*dt^2/I stay small, where I is
# the smallest effective joint inertia 1/(M^-1)_ii (hanging robot, crouch pose): 4e-5 kg m^2 for
# WristYaw, 1.8e-4 for AnkleRoll. At the 1 ms physics step these gains keep kd*dt/I <= 0.5 and
# kp*dt^2/I <= 0.2, with damping ratio ~0.8 against the joint's own mass-matrix diagonal where that
# bound allows; a 0.1 rad error saturates the leg motors (effort 3.0-3.3 N m).
GAINS = {
    "Head": (5.0, 0.10),
    "HipYawPitch": (30.0, 0.40), "HipRoll": (30.0, 1.00), "HipPitch": (30.0, 0.60),
    "KneePitch": (30.0, 0.60), "AnklePitch": (30.0, 0.23), "AnkleRoll": (30.0, 0.09),
    "ShoulderPitch": (8.0, 0.40), "ShoulderRoll": (8.0, 0.30), "ElbowYaw": (3.0, 0.04),
    "ElbowRoll": (3.0, 0.11), "WristYaw": (1.0, 0.013),
}


def _leg(side: str) -> list[JointSpec]:
    s = 1.0 if side == "L" else -1.0
    low = side.lower()
    m = (lambda i: i) if side == "L" else (lambda i: i.mirrored())
    mg = (lambda g: g) if side == "L" else (lambda g: g.mirrored())
    foot_geom = Geom("box", (SOLE_LENGTH, SOLE_WIDTH, SOLE_THICKNESS),
                     (SOLE_CENTER_X, SOLE_CENTER_Y_OUT, -FOOT_HEIGHT + SOLE_THICKNESS / 2))
    thigh_geom = Geom("capsule", (0.033, 0.060), (0.0, 0.0, -0.050))
    tibia_geom = Geom("capsule", (0.030, 0.060), (0.0, 0.0, -0.052))

    def lim(lo, hi):  # right side mirrors roll limits
        return (lo, hi) if side == "L" else (-hi, -lo)

    j = []
    j.append(JointSpec(f"{side}HipYawPitch", "torso", f"{side}Pelvis", (0.0, s * HIP_OFFSET_Y, -HIP_OFFSET_Z),
                       (0.0, _S, -_S) if side == "L" else (0.0, _S, _S), -1.1453, 0.7407, 3.348, 4.162,
                       *GAINS["HipYawPitch"], m(PELVIS), (), None if side == "L" else "LHipYawPitch"))
    j.append(JointSpec(f"{side}HipRoll", f"{side}Pelvis", f"{side}Hip", (0, 0, 0), (1, 0, 0),
                       *lim(-0.3794, 0.7905), 3.348, 4.162, *GAINS["HipRoll"], m(HIP)))
    j.append(JointSpec(f"{side}HipPitch", f"{side}Hip", f"{side}Thigh", (0, 0, 0), (0, 1, 0),
                       -1.5359, 0.4840, 3.023, 6.402, *GAINS["HipPitch"], m(THIGH), (mg(thigh_geom),)))
    j.append(JointSpec(f"{side}KneePitch", f"{side}Thigh", f"{side}Tibia", (0, 0, -THIGH_LENGTH), (0, 1, 0),
                       -0.0923, 2.1126, 3.023, 6.402, *GAINS["KneePitch"], m(TIBIA), (mg(tibia_geom),)))
    ap_lo, ap_hi = (-1.1894, 0.9226) if side == "L" else (-1.1863, 0.9320)
    j.append(JointSpec(f"{side}AnklePitch", f"{side}Tibia", f"{side}AnklePitch", (0, 0, -TIBIA_LENGTH),
                       (0, 1, 0), ap_lo, ap_hi, 3.023, 6.402, *GAINS["AnklePitch"], m(ANKLE_PITCH)))
    j.append(JointSpec(f"{side}AnkleRoll", f"{side}AnklePitch", f"{low}_ankle", (0, 0, 0), (1, 0, 0),
                       *lim(-0.3978, 0.7690), 3.348, 4.162, *GAINS["AnkleRoll"], m(FOOT), (mg(foot_geom),)))
    return j


def _arm(side: str) -> list[JointSpec]:
    s = 1.0 if side == "L" else -1.0
    low = side.lower()
    m = (lambda i: i) if side == "L" else (lambda i: i.mirrored())
    mg = (lambda g: g) if side == "L" else (lambda g: g.mirrored())

    def lim(lo, hi):
        return (lo, hi) if side == "L" else (-hi, -lo)

    upper = Geom("capsule", (0.025, 0.070), (0.060, 0.0, 0.0), (0.0, math.pi / 2, 0.0))
    fore = Geom("capsule", (0.022, 0.080), (0.060, 0.0, 0.0), (0.0, math.pi / 2, 0.0))
    return [
        JointSpec(f"{side}ShoulderPitch", "torso", f"{side}Shoulder", (0.0, s * SHOULDER_OFFSET_Y, SHOULDER_OFFSET_Z),
                  (0, 1, 0), -2.0857, 2.0857, 1.329, 8.268, *GAINS["ShoulderPitch"], m(SHOULDER)),
        JointSpec(f"{side}ShoulderRoll", f"{side}Shoulder", f"{side}Bicep", (0, 0, 0), (0, 0, 1),
                  *lim(-0.3142, 1.3265), 1.7835, 7.194, *GAINS["ShoulderRoll"], m(BICEP), (mg(upper),)),
        JointSpec(f"{side}ElbowYaw", f"{side}Bicep", f"{side}Elbow", (UPPER_ARM_LENGTH, s * ELBOW_OFFSET_Y, 0.0),
                  (1, 0, 0), -2.0857, 2.0857, 1.547, 8.268, *GAINS["ElbowYaw"], m(ELBOW)),
        JointSpec(f"{side}ElbowRoll", f"{side}Elbow", f"{side}ForeArm", (0, 0, 0), (0, 0, 1),
                  *lim(-1.5446, -0.0349), 1.532, 7.194, *GAINS["ElbowRoll"], m(FOREARM)),
        JointSpec(f"{side}WristYaw", f"{side}ForeArm", f"{low}_wrist", (LOWER_ARM_LENGTH, 0.0, 0.0),
                  (1, 0, 0), -1.8238, 1.8238, 0.4075, 24.62, *GAINS["WristYaw"], m(WRIST), (mg(fore),)),
    ]


def _head() -> list[JointSpec]:
    return [
        JointSpec("HeadYaw", "torso", "Neck", (0.0, 0.0, NECK_OFFSET_Z), (0, 0, 1), -2.0857, 2.0857, 1.547, 8.268,
                  *GAINS["Head"], NECK),
        JointSpec("HeadPitch", "Neck", "Head", (0, 0, 0), (0, 1, 0), -0.6720, 0.5149, 1.532, 7.194,
                  *GAINS["Head"], HEAD, (Geom("sphere", (0.060,), (0.0, 0.0, 0.058)),)),
    ]


TORSO_GEOMS = (Geom("box", (0.080, 0.140, 0.180), (-0.010, 0.0, 0.030)),)

# Standing poses [rad] by joint name; joints not named are 0.
ARMS_DOWN = {"LShoulderPitch": 1.45, "RShoulderPitch": 1.45, "LShoulderRoll": 0.15, "RShoulderRoll": -0.15,
             "LElbowYaw": -1.2, "RElbowYaw": 1.2, "LElbowRoll": -0.45, "RElbowRoll": 0.45}


def _leg_pose(hip: float, knee: float, ankle: float) -> dict[str, float]:
    out = {}
    for side in "LR":
        out.update({f"{side}HipPitch": hip, f"{side}KneePitch": knee, f"{side}AnklePitch": ankle})
    return out


POSES = {
    "zero": {},
    "stand": {**ARMS_DOWN},
    "crouch": {**ARMS_DOWN, **_leg_pose(-0.45, 0.9, -0.45)},
    "deep_crouch": {**ARMS_DOWN, **_leg_pose(-0.6, 1.2, -0.6)},
}


@functools.lru_cache(maxsize=1)
def nao_h25() -> RobotModel:
    """The NAO-like H25 model (24 hinges, 5.3054 kg). Cached: treat it as read-only."""
    joints = tuple(_head() + _arm("L") + _arm("R") + _leg("L") + _leg("R"))
    frames = {
        "l_sole": Frame("l_ankle", (0.0, 0.0, -FOOT_HEIGHT)),
        "r_sole": Frame("r_ankle", (0.0, 0.0, -FOOT_HEIGHT)),
        "gyro": Frame("torso", GYRO_OFFSET),
        "accel": Frame("torso", ACCEL_OFFSET),
    }
    swap = {"FL": "FR", "FR": "FL", "RL": "RR", "RR": "RL"}  # mirroring swaps left and right sensors
    for k, (x, y) in FSR_XY_LEFT.items():
        frames[f"LFsr{k}"] = Frame("l_ankle", (x, y, -FOOT_HEIGHT))
        frames[f"RFsr{swap[k]}"] = Frame("r_ankle", (x, -y, -FOOT_HEIGHT))
    names = [j.name for j in joints]
    legs = tuple(n for n in names if any(k in n for k in ("Hip", "Knee", "Ankle")))
    groups = {"legs": legs, "left_leg": tuple(n for n in legs if n.startswith("L")),
              "right_leg": tuple(n for n in legs if n.startswith("R")),
              "arms": tuple(n for n in names if any(k in n for k in ("Shoulder", "Elbow", "Wrist"))),
              "head": tuple(n for n in names if n.startswith("Head"))}
    return RobotModel("nao", joints, root="torso", root_inertial=TORSO, root_geoms=TORSO_GEOMS, group_names=groups,
                      fall_height=0.20, frames=frames, poses=POSES, source="robots.nao (ros-naoqi V50 URDF)",
                      leg_geometry=NAO_LEG, sole=NAO_SOLE)
