"""The referee's own excitation: a second source of logs that is not the project's protocol.

``sgatwalk excite`` records the protocol of ``sysid.excitation`` (holds, ramps, steps, load
reversals, a gait-like pattern, a chirp). A diagnosis scored only on logs of its own protocol can
be tuned to that protocol; the blind benchmark therefore also records logs the tool has never been
designed for, written here independently of ``sysid``:

* a **random multisine** per joint: 12 frequencies spread log-uniformly over 0.2-5 Hz with random
  phases (a broadband signal, as used for frequency-domain identification: Pintelon & Schoukens,
  *System Identification: A Frequency Domain Approach*, 2nd ed., Wiley 2012, ch. 5), scaled to a
  random share of each joint's amplitude;
* **random steps**: piecewise-constant offsets held 0.3-1.2 s (a random telegraph signal), whose
  sharp edges excite the servo's stiffness and damping;

added around the crouch pose, each joint's amplitude a quarter of its range (at most 0.3 rad) and the
targets kept 0.05 rad inside the limits. Fixed base only (a free-standing robot would fall over).
"""

from __future__ import annotations

import numpy as np

#: Multisine band [Hz] and number of tones.
BAND = (0.2, 5.0)
TONES = 12
#: Hold time [s] of the random steps.
HOLD = (0.3, 1.2)


def referee_commands(robot, seconds: float, seed: int, control_dt: float = 0.01) -> np.ndarray:
    """Joint targets [rad], shape (round(seconds / control_dt), n actuated): see the module docstring.

    Raises:
        ValueError: non-positive ``seconds`` or ``control_dt``.
    """
    if not (seconds > 0 and control_dt > 0):
        raise ValueError(f"seconds and control_dt must be positive, got {seconds}, {control_dt}")
    rng = np.random.default_rng(seed)
    n = int(round(seconds / control_dt))
    t = np.arange(n) * control_dt
    idx = robot.actuated_index
    lo, hi = robot.lower[idx] + 0.05, robot.upper[idx] - 0.05
    q0 = np.clip(robot.pose("crouch", actuated=True), lo, hi)
    amp = np.minimum(0.25 * (robot.upper[idx] - robot.lower[idx]), 0.3)
    na = len(idx)
    freqs = np.exp(rng.uniform(np.log(BAND[0]), np.log(BAND[1]), (na, TONES)))
    phases = rng.uniform(0, 2 * np.pi, (na, TONES))
    ms = np.sin(2 * np.pi * freqs[:, :, None] * t[None, None, :] + phases[:, :, None]).sum(1)
    ms /= np.maximum(np.abs(ms).max(axis=1, keepdims=True), 1e-12)
    steps = np.zeros((na, n))
    for j in range(na):
        k = 0
        while k < n:
            m = int(round(rng.uniform(*HOLD) / control_dt))
            steps[j, k:k + m] = rng.uniform(-1.0, 1.0)
            k += m
    share = rng.uniform(0.3, 0.7, (na, 1))  # of each joint's amplitude: multisine vs steps
    ramp = np.clip(t / 0.5, 0.0, 1.0)  # from the pose into the excitation over 0.5 s
    x = (share * ms + (1.0 - share) * steps) * amp[:, None] * ramp[None, :]
    return np.clip(q0[None, :] + x.T, lo, hi)


def record_referee(env, out_dir: str, *, n_logs: int, seconds: float, seed: int, prefix: str = "log") -> list[str]:
    """Record ``n_logs`` logs of :func:`referee_commands` (trajectory seeds ``seed + i``) in the
    fixed-base world ``env``; returns the paths.

    Raises:
        ValueError: a floating-base world, or non-positive ``n_logs``.
    """
    import os

    from envs.rollout import CommandLog, rollout

    base = env.unwrapped
    if not base.fixed_base:
        raise ValueError("the referee's excitation is for a fixed base only")
    if n_logs < 1:
        raise ValueError(f"need at least one log, got {n_logs}")
    os.makedirs(out_dir, exist_ok=True)
    paths = []
    for i in range(n_logs):
        cmd = referee_commands(base.robot, seconds, seed + i, base.control_dt)
        rec = rollout(env, CommandLog(cmd), seed=seed + i, seconds=seconds, options={"pose": "crouch"})
        paths.append(rec.to_parquet(os.path.join(out_dir, f"{prefix}_{i:03d}.parquet")))
    return paths
