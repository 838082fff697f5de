"""An excitation protocol a user can run on a robot to diagnose it (in the air first, then on the
ground: the bottom-up staging of Bjelonic et al., arXiv:2509.06342).

Each log is a sequence of segments, every one aimed at some family of missing physics:

==============  ============================================  =================================
segment         motion                                        separates
==============  ============================================  =================================
holds           posture holds in 2 random postures            link mass vs servo kp (gravity
                                                              torque changes with posture)
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
_SHARE = {"holds": 0.17, "ramps": 0.13, "steps": 0.12, "reversals": 0.1, "gait": 0.16, "chirp": 0.32,
          "stepping": 0.5, "slip": 0.25}
#: Segments of a floating-base log, in this order, when ``segments`` has no ``"stepping"``
#: (``holds`` and ``gait`` only if asked for).
_FLOATING = ("slip", "stepping")


def _amplitudes(robot: RobotModel) -> np.ndarray:
    """Per actuated joint motion amplitude [rad]: legs 0.2, arms 0.3, head 0.25."""
    out = []
    for n in robot.actuated_joint_names:
        out.append(0.3 if any(k in n for k in ("Shoulder", "Elbow", "Wrist")) else 0.25 if n.startswith("Head") else 0.2)
    return np.array(out)


def _smooth_step(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * x)


def protocol(robot: RobotModel, seconds: float = 8.0, seed: int = 0, *, control_dt: float = CONTROL_DT,
             pose: str = "crouch", segments=SEGMENTS, fixed_base: bool = True, scale: float = 1.0) -> np.ndarray:
    """Joint targets [rad] for one excitation log, shape (round(seconds / control_dt), 23).

    Args:
        robot: the robot; ``pose``: the named pose the motion is centred on (and starts/ends in).
        seconds: log duration [s] (>= 3).  seed: trajectory seed.
        segments: subset/order of :data:`SEGMENTS`. For a floating base (``fixed_base=False``)
            without ``"stepping"`` in it, the log is ``slip``, ``stepping`` and then the asked-for
            ``holds`` and ``gait`` (at 0.3 of the amplitudes; ``slip`` is about a fifth of the
            log); a list with ``"stepping"`` is taken as given.
        scale: multiplies every amplitude (0.5 for a cautious first run on hardware).

    Raises:
        ValueError: ``seconds < 3``, unknown segment, non-positive ``scale``.
    """
    if seconds < 3.0:
        raise ValueError(f"an excitation log needs >= 3 s, got {seconds}")
    if not scale > 0:
        raise ValueError(f"scale must be positive, got {scale}")
    segments = list(segments)
    if not fixed_base and "stepping" not in segments:
        segments = list(_FLOATING) + [s for s in segments if s in ("holds", "gait")]
    for s in segments:
        if s not in _SHARE:
            raise ValueError(f"unknown excitation segment {s!r}; known: {', '.join(_SHARE)}")
    rng = np.random.default_rng(seed)
    n = int(round(seconds / control_dt))
    q0 = robot.pose(pose, actuated=True)
    amp = _amplitudes(robot) * scale
    if not fixed_base:  # standing: small posture changes so the robot keeps its balance
        amp = amp * 0.3
    names = robot.actuated_joint_names
    na = len(names)
    lead = int(round(0.4 / control_dt))
    tail = int(round(0.3 / control_dt))
    body = n - lead - tail
    shares = np.array([_SHARE[s] for s in segments])
    lens = np.floor(shares / shares.sum() * body).astype(int)
    lens[-1] = body - lens[:-1].sum()
    out = [np.zeros((lead, na))]
    for seg, L in zip(segments, lens):
        t = np.arange(L) * control_dt
        T = max(L * control_dt, control_dt)
        env = _smooth_step(t / min(0.25, T / 4)) * _smooth_step((T - t) / min(0.25, T / 4))
        if seg == "holds":
            # two postures, each reached by a smooth 0.25 T transition and held
            p1 = rng.uniform(-1, 1, na) * amp
            p2 = rng.uniform(-1, 1, na) * amp
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
        elif seg == "reversals":
            f = rng.uniform(1.2, 1.8)
            d = 0.4 * amp[None] * np.sin(2 * np.pi * f * t[:, None] + rng.uniform(0, 2 * np.pi, na)[None]) * env[:, None]
        elif seg == "gait":
            f = rng.uniform(0.9, 1.6)
            ph = 2 * np.pi * f * t
            d = np.zeros((L, na))
            for i, nm in enumerate(names):
                side = 1.0 if nm.startswith("L") else -1.0
                if "HipPitch" in nm:
                    d[:, i] = -0.6 * amp[i] * np.sin(ph) * side
                elif "KneePitch" in nm:
                    d[:, i] = 0.8 * amp[i] * (0.5 + 0.5 * np.sin(ph * side + np.pi / 2)) - 0.4 * amp[i]
                elif "AnklePitch" in nm:
                    d[:, i] = 0.4 * amp[i] * np.sin(ph) * side
                elif "Roll" in nm and ("Hip" in nm or "Ankle" in nm):
                    d[:, i] = 0.3 * amp[i] * np.sin(ph + np.pi / 2)
                elif "ShoulderPitch" in nm:
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
            for i, nm in enumerate(names):
                side = 1.0 if nm.startswith("L") else -1.0
                if "HipRoll" in nm:
                    d[:, i] = side * spread
                elif "AnkleRoll" in nm:
                    d[:, i] = -side * spread
        else:  # stepping (floating base): weight shift with small alternating knee lifts
            f = rng.uniform(0.5, 0.7)
            ph = 2 * np.pi * f * t
            d = np.zeros((L, na))
            sway = 0.08 * scale * np.sin(ph)
            for i, nm in enumerate(names):
                side = 1.0 if nm.startswith("L") else -1.0
                if "HipRoll" in nm:
                    d[:, i] = sway
                elif "AnkleRoll" in nm:
                    d[:, i] = -sway
                elif "KneePitch" in nm:
                    d[:, i] = 0.22 * scale * np.maximum(0.0, -side * np.sin(ph)) ** 2
                elif "HipPitch" in nm or "AnklePitch" in nm:
                    d[:, i] = -0.11 * scale * np.maximum(0.0, -side * np.sin(ph)) ** 2
            d *= env[:, None]
        out.append(d)
    out.append(np.zeros((tail, na)))
    delta = np.concatenate(out)[:n]
    # the HipYawPitch motor is shared; keep it moving like any other joint
    lo = robot.lower[robot.actuated_index] + 0.01
    hi = robot.upper[robot.actuated_index] - 0.01
    return np.clip(q0[None] + delta, lo, hi)
