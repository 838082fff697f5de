"""An excitation protocol a user can run on a robot to diagnose it (in the air first, then on the
ground: the bottom-up staging of Bjelonic et al., arXiv:2509.06342).

Each log is a sequence of segments, every one aimed at some family of missing physics:

==============  ============================================  =================================
segment         motion                                        separates
==============  ============================================  =================================
holds           posture holds in 2 random postures (standing:  link mass vs servo kp (gravity
                the legs squat and lean sideways with the     torque changes with posture)
                soles flat, arms and head random)
ramps           slow triangle ramps (~0.15 rad/s)             Coulomb friction (sign q̇, low |q̇|)
steps           target steps of ~0.6 amplitude every 0.2-0.3  torque limit (saturated rises),
                s                                             latency (onset), armature, kp
reversals       1.5 Hz small sine through the hold pose       backlash (load reversals)
gait            gait-like pattern at 0.9-1.6 Hz (legs in      everything at walking speeds
                phase, arms counter-swing)
chirp           0.3-4 Hz linear chirp, random per-joint        latency (phase ∝ ω), damping,
                signs and weights                             armature, kp (resonance), torque
                                                              limit (peaks)
stepping        weight shift side to side with small knee     ground compliance, foot friction
                lifts (floating base only)                    (contact phases)
saturation      steps of 1.5x the error at which the servo    torque limit (the PD torque is
                saturates (effort / kp), alternating signs,    clipped at every rise), kp vs
                0.3 s each (fixed base only; opt-in)          limit (saturated vs linear rise)
velocity_sweep  constant-speed legs at three speeds (0.1,     kp vs kp and kd together (lag
                0.5, 1.5 rad/s for a 0.2 rad joint),          kd v / kp), Coulomb vs Stribeck
                alternating direction (fixed base; opt-in)    friction (slow vs fast legs)
load_reversal   slow sweeps to both ends of 1.5x the          backlash vs encoder offset vs a
                amplitude with 0.3 s holds (fixed base;       centre-of-mass offset (the
                opt-in)                                       gravity load changes sign)
slip            feet pushed apart and pulled together in      foot friction (the feet slide
                double support at 2-3.5 Hz, growing           on a slippery floor, stick on a
                amplitude (hip and ankle roll in opposition,  grippy one; the amplitude at
                soles kept flat; floating base only)          which they start tells μ)
==============  ============================================  =================================

A floating-base (standing) log is ``slip``, ``stepping``, ``holds`` and ``gait``, the last two at
0.3 of the amplitudes. The other segments load the feet sideways little (tangential/normal force
ratio at the soles mostly under 0.3, more only on a nearly unloaded foot), so a floor with
μ = 0.2-0.4 hardly changes them; in ``slip`` the legs' lateral forces are internal (the torso
hardly moves) and the ratio grows to 0.5-0.7 with the amplitude. It comes first, while the robot
stands still on both feet: after ``stepping`` it still rocks from foot to foot, and a lifted foot
is put down, not slid.

Different seeds give different trajectories (amplitudes, frequencies, postures, weights), which
is what a held-out split by trajectory needs. All targets stay 0.01 rad inside the joint limits.
"""

from __future__ import annotations

import numpy as np

from common.defaults import CONTROL_DT
from robots import RobotModel

SEGMENTS = ("holds", "ramps", "steps", "reversals", "gait", "chirp")
#: Share of the log each segment takes (fixed base), after 0.4 s of holding the start pose.
SEGMENT_SHARES = {"holds": 0.17, "ramps": 0.13, "steps": 0.12, "reversals": 0.1, "gait": 0.16, "chirp": 0.32,
          "stepping": 0.5, "slip": 0.25, "saturation": 0.12, "velocity_sweep": 0.25, "load_reversal": 0.25}
#: Segments outside the default protocol, added on request (``sgatwalk excite --segments``): each separates
#: members of a class of effects the default protocol can leave tied (:mod:`sysid.equivalence`, whose
#: report names the segment to record): ``saturation`` (torque limits: a limit common to all joints, one
#: joint's, a back-EMF limit; servo damping against viscous friction), ``velocity_sweep`` (kp against
#: kp and kd together, a series spring; Coulomb against Stribeck friction), ``load_reversal`` (backlash
#: against an encoder offset or a centre of mass off the joint axis). Fixed base only.
OPTIONAL_SEGMENTS = ("saturation", "velocity_sweep", "load_reversal")
#: Speeds of the three phases of ``velocity_sweep`` [rad/s] for a joint of amplitude 0.2 rad (scaled with
#: the joint's amplitude), and the number of constant-speed legs in each phase.
SWEEP_SPEEDS = (0.1, 0.5, 1.5)
SWEEP_LEGS = (1, 2, 4)
#: ``load_reversal``: the sweep's amplitude as a multiple of the joint's motion amplitude (within
#: :data:`SATURATION_RANGE_SHARE` of its range) and the hold at each end [s].
REVERSAL_AMPLITUDE = 1.5
REVERSAL_HOLD = 0.3
#: Every segment name :func:`protocol` knows.
KNOWN_SEGMENTS = tuple(SEGMENT_SHARES)
#: Saturation steps: the step is this multiple of the error at which the PD torque reaches the effort
#: limit (effort / kp), at most :data:`SATURATION_RANGE_SHARE` of the joint's range.
SATURATION_FACTOR = 1.5
SATURATION_RANGE_SHARE = 0.35
#: Segments of a floating-base log, in this order, when ``segments`` has no ``"stepping"``
#: (``holds`` and ``gait`` only if asked for).
_FLOATING = ("slip", "stepping")


#: Motion amplitude [rad] per joint group (``RobotModel.groups``): arms, head, everything else (legs,
#: waist, torso); never more than :data:`RANGE_SHARE` of a joint's range.
GROUP_AMPLITUDE = {"arms": 0.3, "head": 0.25}
DEFAULT_AMPLITUDE = 0.2
RANGE_SHARE = 0.25


def _amplitudes(robot: RobotModel) -> np.ndarray:
    """Per actuated joint motion amplitude [rad]: arms 0.3, head 0.25, the rest (legs, waist) 0.2
    (:data:`GROUP_AMPLITUDE`), at most :data:`RANGE_SHARE` of the joint's range (G1 ankle roll:
    0.13 of its +-0.26 rad)."""
    arms, head = set(robot.groups.get("arms", ())), set(robot.groups.get("head", ()))
    out = [GROUP_AMPLITUDE["arms"] if n in arms else GROUP_AMPLITUDE["head"] if n in head else DEFAULT_AMPLITUDE
           for n in robot.actuated_joint_names]
    idx = robot.actuated_index
    return np.minimum(np.array(out), RANGE_SHARE * (robot.upper[idx] - robot.lower[idx]))


def _rpy_matrix(r: float, p: float, y: float) -> np.ndarray:
    """URDF ``rpy`` (fixed axes x, y, z) -> rotation matrix."""
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _zero_pose_axes(robot: RobotModel) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Joint name -> (origin, unit axis) in the root frame at zero joint angles (URDF chain: origin
    ``xyz``, ``rpy``, then the joint's rotation)."""
    frames = {robot.root: (np.zeros(3), np.eye(3))}
    out: dict = {}
    todo = list(robot.joints)
    while todo:
        rest = []
        for j in todo:
            if j.parent not in frames:
                rest.append(j)
                continue
            p0, R0 = frames[j.parent]
            p, R = p0 + R0 @ np.asarray(j.xyz, float), R0 @ _rpy_matrix(*j.rpy)
            frames[j.child] = (p, R)
            a = R @ np.asarray(j.axis, float)
            out[j.name] = (p, a / np.linalg.norm(a))
        if len(rest) == len(todo):  # a joint whose parent is on no chain from the root
            raise ValueError(f"{robot.name}: joints {[j.name for j in rest]} do not hang from the root {robot.root!r}")
        todo = rest
    return out


def joint_roles(robot: RobotModel) -> dict[str, tuple[str, float, float]]:
    """The joints the protocol's coordinated patterns (gait, slip, stepping) move, by role.

    Found from the kinematic chain, not from names: in each leg (``groups["left_leg"]`` /
    ``groups["right_leg"]``, hip to ankle) the joints whose axis at zero angles is within 26 deg of
    the root's x axis are rolls (first: ``hip_roll``, last: ``ankle_roll``), those near its y axis
    pitches (first: ``hip_pitch``, last: ``ankle_pitch``, the one between: ``knee``); in each arm
    (``groups["arms"]``, side by the shoulder's y coordinate) the first or second joint with a
    pitch axis is ``shoulder_pitch``. A coupled yaw-pitch hip (the NAO's HipYawPitch) has neither.

    Returns:
        joint name -> (role, side: +1 left / -1 right, axis sign: +1 when the axis points along +x
        (rolls) or +y (pitches), else -1).
    """
    axes = _zero_pose_axes(robot)
    roles: dict[str, tuple[str, float, float]] = {}
    for grp, side in (("left_leg", 1.0), ("right_leg", -1.0)):
        leg = list(robot.groups.get(grp, ()))
        rolls = [n for n in leg if abs(axes[n][1][0]) > 0.9]
        pitches = [n for n in leg if abs(axes[n][1][1]) > 0.9]
        named = []
        if len(rolls) >= 2:
            named += [(rolls[0], "hip_roll", 0), (rolls[-1], "ankle_roll", 0)]
        if len(pitches) >= 2:
            named += [(pitches[0], "hip_pitch", 1), (pitches[-1], "ankle_pitch", 1)]
        if len(pitches) >= 3:
            named.append((pitches[1], "knee", 1))
        for n, role, k in named:
            roles[n] = (role, side, 1.0 if axes[n][1][k] > 0 else -1.0)
    arms = list(robot.groups.get("arms", ()))
    for side in (1.0, -1.0):
        chain = [n for n in arms if np.sign(axes[n][0][1]) == side]
        for n in chain[:2]:
            if abs(axes[n][1][1]) > 0.9:
                roles[n] = ("shoulder_pitch", side, 1.0 if axes[n][1][1] > 0 else -1.0)
                break
    return roles


def _standing_posture(p: np.ndarray, role: list, legs: np.ndarray) -> np.ndarray:
    """A hold posture for a robot standing on both feet, from the random posture ``p`` (m,) [rad].

    Independent random offsets on every leg joint tilt the soles against the floor and lean the
    body: after the stepping segment's rocking, some seeds tipped the NAO over backwards in its own
    flat world (8 of 100 seeds of a 6 s log in the sim, 0.3-1 s after the holds). Here the legs
    move together so the soles stay flat and the centre of mass over the feet: a squat of depth
    ``s`` (the first knee's draw; knee ``s``, hip and ankle pitch ``-s/2`` each, rotations about
    the same lateral axis, so the torso stays upright above the ankles) and a sideways lean ``y``
    (the first hip roll's draw; hip roll ``y`` and ankle roll ``-y`` on both legs, a
    parallelogram). Other leg joints (a yaw or the NAO's HipYawPitch) hold still; joints outside
    the legs (arms, head, waist) keep their draws.

    Args:
        p: (m,) posture offsets per actuated joint [rad].  role: per actuated joint (role, side,
            axis sign) (:func:`joint_roles`).  legs: (m,) bool, the actuated joints of the legs.

    Returns:
        A new (m,) array [rad].
    """
    out = np.where(legs, 0.0, p)
    knees = [i for i, (rl, _, _) in enumerate(role) if rl == "knee"]
    rolls = [i for i, (rl, _, _) in enumerate(role) if rl == "hip_roll"]
    s = float(p[knees[0]]) if knees else 0.0  # rotation about the lateral axis [rad]
    y = float(p[rolls[0]]) if rolls else 0.0  # rotation about the forward axis [rad]
    for i, (rl, _, ax) in enumerate(role):  # ax: an axis along -x / -y turns the other way
        if rl == "knee":
            out[i] = s * ax
        elif rl in ("hip_pitch", "ankle_pitch"):
            out[i] = -0.5 * s * ax
        elif rl == "hip_roll":
            out[i] = y * ax
        elif rl == "ankle_roll":
            out[i] = -y * ax
    return out


def _smooth_step(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * x)


def protocol(robot: RobotModel, seconds: float = 8.0, seed: int = 0, *, control_dt: float = CONTROL_DT,
             pose: str = "crouch", segments=SEGMENTS, fixed_base: bool = True, scale: float = 1.0,
             shares: dict | None = None) -> np.ndarray:
    """Joint targets [rad] for one excitation log, shape (round(seconds / control_dt), m), m = the
    robot's actuated joint count (``RobotModel.actuated_joint_names``: 23 for the NAO, 29 for the G1).

    Amplitudes come from the joint groups and ranges (:func:`_amplitudes`), the coordinated
    patterns (gait, slip, stepping) from the joints' roles in the chain (:func:`joint_roles`).

    Args:
        robot: the robot; ``pose``: the named pose the motion is centred on (and starts/ends in).
        seconds: log duration [s] (>= 3).  seed: trajectory seed.
        segments: subset/order of :data:`SEGMENTS` and :data:`OPTIONAL_SEGMENTS`. For a floating base (``fixed_base=False``)
            without ``"stepping"`` in it, the log is ``slip``, ``stepping`` and then the asked-for
            ``holds`` and ``gait`` (at 0.3 of the amplitudes; ``slip`` is about a fifth of the
            log); a list with ``"stepping"`` is taken as given.
        scale: multiplies every amplitude (0.5 for a cautious first run on hardware).
        shares: segment -> share of the log (e.g. a D-optimal design, :func:`sysid.design.design`);
            default the protocol's own shares. Missing segments keep theirs; they are normalised.

    Raises:
        ValueError: ``seconds < 3``, unknown segment, non-positive ``scale``, ``saturation`` with a
            floating base, a negative share or shares summing to 0.
        KeyError: unknown ``pose``.
    """
    if seconds < 3.0:
        raise ValueError(f"an excitation log needs >= 3 s, got {seconds}")
    if not scale > 0:
        raise ValueError(f"scale must be positive, got {scale}")
    segments = list(segments)
    for seg in ("saturation", "velocity_sweep", "load_reversal"):
        if not fixed_base and seg in segments:
            raise ValueError(f"the {seg} segment is for a fixed base only (a standing robot would fall)")
    if not fixed_base and "stepping" not in segments:
        segments = list(_FLOATING) + [s for s in segments if s in ("holds", "gait")]
    for s in segments:
        if s not in SEGMENT_SHARES:
            raise ValueError(f"unknown excitation segment {s!r}; known: {', '.join(SEGMENT_SHARES)}")
    rng = np.random.default_rng(seed)
    n = int(round(seconds / control_dt))
    q0 = robot.pose(pose, actuated=True)
    amp = _amplitudes(robot) * scale
    if not fixed_base:  # standing: small posture changes so the robot keeps its balance
        amp = amp * 0.3
    names = robot.actuated_joint_names
    na = len(names)
    roles = joint_roles(robot)
    role = [roles.get(nm, (None, 0.0, 1.0)) for nm in names]  # (role, side, axis sign) per actuated joint
    leg_names = set(robot.groups.get("left_leg", ())) | set(robot.groups.get("right_leg", ()))
    legs = np.array([nm in leg_names for nm in names])
    lead = int(round(0.4 / control_dt))
    tail = int(round(0.3 / control_dt))
    body = n - lead - tail
    if shares is not None and (any(not v >= 0 for v in shares.values()) or not sum(shares.values()) > 0):
        raise ValueError(f"shares must be non-negative and not all 0, got {shares}")
    shares = np.array([(shares or {}).get(s, SEGMENT_SHARES[s]) for s in segments], dtype=float)
    lens = np.floor(shares / shares.sum() * body).astype(int)
    lens[-1] = body - lens[:-1].sum()
    out = [np.zeros((lead, na))]
    for seg, L in zip(segments, lens):
        if L <= 0:
            continue
        t = np.arange(L) * control_dt
        T = max(L * control_dt, control_dt)
        env = _smooth_step(t / min(0.25, T / 4)) * _smooth_step((T - t) / min(0.25, T / 4))
        if seg == "holds":
            # two postures, each reached by a smooth 0.25 T transition and held
            p1 = rng.uniform(-1, 1, na) * amp
            p2 = rng.uniform(-1, 1, na) * amp
            if not fixed_base:  # standing: legs in postures the robot balances in (same draws)
                p1, p2 = _standing_posture(p1, role, legs), _standing_posture(p2, role, legs)
            x = t / T
            w1 = _smooth_step(x / 0.2) - _smooth_step((x - 0.4) / 0.2)
            w2 = _smooth_step((x - 0.4) / 0.2) - _smooth_step((x - 0.8) / 0.2)
            d = w1[:, None] * p1 + w2[:, None] * p2
        elif seg == "ramps":
            speed = rng.uniform(0.1, 0.2)  # rad/s
            tri = 1.0 - np.abs(2.0 * ((t / T * 2.0) % 1.0) - 1.0)  # two triangles
            sign = rng.choice([-1.0, 1.0], na)
            d = sign[None] * np.minimum(speed * T / 4, amp)[None] * tri[:, None]
        elif seg == "steps":
            dwell = min(rng.uniform(0.2, 0.3), T / 3)
            k = np.floor(t / dwell).astype(int)
            levels = rng.uniform(0.3, 0.7, (k.max() + 1, na)) * rng.choice([-1.0, 1.0], (k.max() + 1, na)) * amp[None]
            levels[-1] = 0.0  # back to the pose before the next segment
            d = levels[k]
        elif seg == "saturation":
            if not fixed_base:
                raise ValueError("the saturation segment is for a fixed base only (a standing robot would fall)")
            # steps beyond effort/kp: the servo's torque is clipped at the effort limit during every rise
            idx = robot.actuated_index
            sat = np.asarray(robot.effort, float)[idx] / np.asarray(robot.kp, float)[idx]
            size = np.minimum(SATURATION_FACTOR * sat, SATURATION_RANGE_SHARE * (robot.upper[idx] - robot.lower[idx]))
            dwell = min(0.3, T / 2)
            k = np.floor(t / dwell).astype(int)
            sign = rng.choice([-1.0, 1.0], na)
            levels = np.where((np.arange(k.max() + 1) % 2 == 0)[:, None], 1.0, -1.0) * sign[None] * size[None]
            levels[-1] = 0.0  # back to the pose before the next segment
            d = levels[k]
        elif seg == "velocity_sweep":
            # constant-speed legs at three speeds (slow, medium, fast; phases of 45, 30, 25 % of the
            # segment), each phase's legs alternating direction: a servo's lag behind a ramp is
            # kd qdot / kp, so a kp-only error changes it with speed and a kp-and-kd error does not;
            # dry friction breaks away on the slow legs, Stribeck friction falls away on the fast ones
            d = np.zeros((L, na))
            bounds = np.cumsum([0.0, 0.45, 0.30, 0.25]) * L
            sign = rng.choice([-1.0, 1.0], na)
            for (a, b), v0, legs in zip(zip(bounds[:-1], bounds[1:]), SWEEP_SPEEDS, SWEEP_LEGS):
                i0, i1 = int(a), max(int(a) + 1, int(b))
                tt = (np.arange(i1 - i0) + 0.5) * control_dt
                leg = max((i1 - i0) * control_dt / legs, control_dt)
                k = np.minimum((tt // leg).astype(int), legs - 1)
                x = tt - k * leg  # time into the current leg
                direction = np.where(k % 2 == 0, 1.0, -1.0)
                v = v0 * amp / DEFAULT_AMPLITUDE  # per joint [rad/s]
                pos = np.where(direction[:, None] > 0, 0.0, 1.0) * (v * leg)[None] + direction[:, None] * v[None] * x[:, None]
                d[i0:i1] = sign[None] * (np.minimum(pos, 2 * amp[None]) - np.minimum(v * leg, 2 * amp)[None] / 2)
            d *= env[:, None]
        elif seg == "load_reversal":
            # slow sweeps to both ends of a wide range with holds: the gravity load of a hanging link
            # changes sign across its balance angle, where backlash flips its offset (an encoder offset
            # does not) and a centre-of-mass offset turns its torque (a mass error scales it)
            idx = robot.actuated_index
            big = np.minimum(REVERSAL_AMPLITUDE * amp, SATURATION_RANGE_SHARE * (robot.upper[idx] - robot.lower[idx]))
            hold = min(REVERSAL_HOLD, T / 8)
            move = max((T - 2 * hold) / 3, control_dt)
            sign = rng.choice([-1.0, 1.0], na)
            knots_t = np.array([0.0, 0.5 * move, 0.5 * move + hold, 1.5 * move + hold, 1.5 * move + 2 * hold, T])
            knots_x = np.array([0.0, 1.0, 1.0, -1.0, -1.0, 0.0])
            prof = np.interp(t, knots_t, knots_x)
            d = (sign * big)[None] * prof[:, None]
        elif seg == "reversals":
            f = rng.uniform(1.2, 1.8)
            d = 0.4 * amp[None] * np.sin(2 * np.pi * f * t[:, None] + rng.uniform(0, 2 * np.pi, na)[None]) * env[:, None]
        elif seg == "gait":
            f = rng.uniform(0.9, 1.6)
            ph = 2 * np.pi * f * t
            d = np.zeros((L, na))
            for i, (rl, side, _) in enumerate(role):
                if rl == "hip_pitch":
                    d[:, i] = -0.6 * amp[i] * np.sin(ph) * side
                elif rl == "knee":
                    d[:, i] = 0.8 * amp[i] * (0.5 + 0.5 * np.sin(ph * side + np.pi / 2)) - 0.4 * amp[i]
                elif rl == "ankle_pitch":
                    d[:, i] = 0.4 * amp[i] * np.sin(ph) * side
                elif rl in ("hip_roll", "ankle_roll"):
                    d[:, i] = 0.3 * amp[i] * np.sin(ph + np.pi / 2)
                elif rl == "shoulder_pitch":
                    d[:, i] = 0.8 * amp[i] * np.sin(ph) * side
                else:
                    d[:, i] = 0.3 * amp[i] * np.sin(ph + rng.uniform(0, 2 * np.pi))
            d *= env[:, None]
        elif seg == "chirp":
            f0, f1 = 0.3, 4.0
            phase = 2 * np.pi * (f0 * t + (f1 - f0) / (2 * T) * t ** 2)
            inst_f = f0 + (f1 - f0) * t / T
            taper = np.minimum(1.0, 1.5 / inst_f)  # smaller at high frequency: keeps torques plausible
            w = rng.uniform(0.5, 1.0, na) * rng.choice([-1.0, 1.0], na)
            phi = rng.uniform(0, 0.5 * np.pi, na)
            d = (amp * w)[None] * (np.sin(phase[:, None] + phi[None]) - np.sin(phi)[None]) * (taper * env)[:, None]
        elif seg == "slip":
            # legs apart/together in double support: hip and ankle roll in opposition keep the
            # soles flat; the feet's lateral forces cancel, so the torso stays put while their
            # ratio to the normal force grows with the amplitude (slip from μ ~0.6 down)
            f = rng.uniform(2.0, 3.5)
            a = rng.uniform(0.06, 0.09) * scale * rng.choice([-1.0, 1.0])
            grow = 0.4 + 0.6 * t / T
            spread = a * grow * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) * env
            d = np.zeros((L, na))
            for i, (rl, side, ax) in enumerate(role):  # ax: a roll axis along -x turns the other way
                if rl == "hip_roll":
                    d[:, i] = side * spread * ax
                elif rl == "ankle_roll":
                    d[:, i] = -side * spread * ax
        else:  # stepping (floating base): weight shift with small alternating knee lifts
            f = rng.uniform(0.5, 0.7)
            ph = 2 * np.pi * f * t
            d = np.zeros((L, na))
            sway = 0.08 * scale * np.sin(ph)
            for i, (rl, side, ax) in enumerate(role):  # ax: an axis along -x / -y turns the other way
                if rl == "hip_roll":
                    d[:, i] = sway * ax
                elif rl == "ankle_roll":
                    d[:, i] = -sway * ax
                elif rl == "knee":
                    d[:, i] = 0.22 * scale * np.maximum(0.0, -side * np.sin(ph)) ** 2 * ax
                elif rl in ("hip_pitch", "ankle_pitch"):
                    d[:, i] = -0.11 * scale * np.maximum(0.0, -side * np.sin(ph)) ** 2 * ax
            d *= env[:, None]
        out.append(d)
    out.append(np.zeros((tail, na)))
    delta = np.concatenate(out)[:n]
    # a mimic pair (the NAO's HipYawPitch) shares one motor; it moves like any other joint
    lo = robot.lower[robot.actuated_index] + 0.01
    hi = robot.upper[robot.actuated_index] - 0.01
    return np.clip(q0[None] + delta, lo, hi)
