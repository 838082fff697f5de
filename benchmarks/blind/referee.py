"""The referee of the blind benchmark: draws hidden effects and trials, records the blind logs.

:func:`draw_effect` draws one hidden effect of a family (moderate, plausible magnitudes);
:func:`plan_trials` and :func:`draw_trial` lay out a run's single- and two-effect trials and draw
each one's hidden effects from its own seed; :func:`roughness_truth` turns a drawn bump height into
the value the tool is scored on; :func:`record` records excitation logs in a referee world
(:mod:`.worlds`) and strips them to a robot's own log (:func:`blind`: no ``gt.*`` columns, metadata
whitelisted), so only the recordings reach the tool; :func:`run_diagnose` runs what ``sgatwalk diagnose``
runs, in-process, on such a folder.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import time

import numpy as np

from .families import MIN_LINK_MASS, NOISE, SEED_ORDER
from .worlds import make_world


# ------------------------------------------------------------------------------------------ drawing
_STABLE: dict = {}


def _effective_inertia(robot, physics_dt: float = 0.001) -> dict:
    """Joint name -> effective inertia 1 / (M^-1)_ii [kg m^2] with the base fixed, from MuJoCo's
    mass matrix at the initial pose (cached)."""
    key = (robot.name, physics_dt)
    if key not in _STABLE:
        import mujoco

        from envs.mujoco_world import build_model

        m = build_model(robot, fixed_base=True, physics_dt=physics_dt)
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        Minv = np.linalg.inv(M)
        _STABLE[key] = {j.name: 1.0 / Minv[m.joint(j.name).dofadr[0], m.joint(j.name).dofadr[0]]
                        for j in robot.joints if j.name in robot.actuated_joint_names}
    return _STABLE[key]


def explicit_damping_stable_joints(robot, physics_dt: float = 0.001, b_max_share: float = 0.4) -> tuple[str, ...]:
    """Actuated joints on which the referees' explicit damping ``-(kd + b) qdot`` (applied once per
    ``physics_dt`` step, as both referee worlds do) stays numerically stable for every drawn b.

    Explicit Euler on a damper is stable only while ``dt (kd + b) / I_eff < 2`` (I_eff: the joint's
    effective inertia with the base fixed, from MuJoCo's mass matrix at the initial pose). NAO's
    lightest joints (ElbowYaw 3e-5, WristYaw 2e-5, AnkleRoll 2e-4 kg m^2) exceed it at the top of
    the drawn range: their "real" recordings would be a numerical blow-up, not physics, so the
    referee does not draw damping on them (documented in the benchmark's results).
    """
    inertia = _effective_inertia(robot, physics_dt)
    return tuple(j.name for j in robot.joints if j.name in inertia
                 and physics_dt * (j.kd + b_max_share * j.effort / 3.0) / inertia[j.name] < 2.0)


def explicit_spring_stable_joints(robot, physics_dt: float = 0.001, ratio_max: float = 4.0) -> tuple[str, ...]:
    """Actuated joints on which the referees' explicit series spring (stiffness up to ``ratio_max``
    x kp, applied to the link once per step) stays stable with a factor 2 margin:
    ``dt^2 k / I_eff < 1``."""
    inertia = _effective_inertia(robot, physics_dt)
    return tuple(j.name for j in robot.joints if j.name in inertia
                 and physics_dt ** 2 * ratio_max * j.kp / inertia[j.name] < 1.0)


def draw_effect(family: str, rng: np.random.Generator, robot) -> dict:
    """One hidden effect: {"family", "targets": [names] or [None], "values": [per target]}.

    Magnitudes (moderate, plausible for NAO-size servos; per-joint values of friction, damping
    and armature scale with the joint's motor size effort/3 N m):
    latency 8-35 ms (whole ms); backlash 10-40 mrad; Coulomb 0.1-0.3 N m; damping 0.1-0.4 N m s/rad;
    kp x0.5-0.8 (70 %) or x1.25-1.6; torque limit x0.5-0.75; link mass x1.4-2.0 (70 %) or
    x0.6-0.75 on one link >= 0.1 kg; armature 0.003-0.012 kg m^2; sensor bias ±5-20 mrad;
    1-3 joints (any actuated joint; for damping only those of
    :func:`explicit_damping_stable_joints`) for local effects; foot friction 0.2-0.4 (nominal 0.8); ground
    contact time constant 20-40 ms (nominal 10 ms); terrain roughness: peak bump height 5-15 mm
    (scored as the RMS height of the laid surfaces, :func:`roughness_truth`);
    joint compliance: a series spring of stiffness 1.5-4 x the joint's kp (statically x0.6-0.8 of the
    servo stiffness) on 1-3 joints of :func:`explicit_spring_stable_joints` other than HipYawPitch, value its compliance
    1/k [rad/(N m)]; parallel spring (a passive -k q across the joint: cables, seals, a counterbalance
    spring): k 0.2-0.6 x effort/3 N m/rad (a torque of 7-20 % of the joint's effort at 1 rad, like the
    Coulomb draws) on 1-3 of any actuated joints.
    """
    joints = list(robot.actuated_joint_names)
    eff = dict(zip(robot.joint_names, robot.effort))
    if family == "viscous_damping":
        joints = [j for j in joints if j in explicit_damping_stable_joints(robot)]
    if family == "joint_compliance":  # not on the HipYawPitch pair (one motor drives both outputs)
        coupled = set(robot.mimic) | set(robot.mimic.values())
        joints = [j for j in joints if j in explicit_spring_stable_joints(robot) and j not in coupled]
    kp = dict(zip(robot.joint_names, robot.kp))
    if family == "latency":
        # on the 1 ms physics grid: the FIFO delays by whole physics steps (mean of the jitter)
        return {"family": family, "targets": [None], "values": [float(rng.integers(8, 36)) / 1000.0]}
    if family == "torque_limit":
        return {"family": family, "targets": [None], "values": [float(rng.uniform(0.5, 0.75))]}
    if family == "foot_friction":
        return {"family": family, "targets": [None], "values": [float(rng.uniform(0.2, 0.4))]}
    if family == "terrain_roughness":  # peak height of the sparse-bump field [m]
        return {"family": family, "targets": [None], "values": [float(rng.uniform(0.005, 0.015))]}
    if family == "ground_compliance":  # MuJoCo contact time constant [s] (the sim's hard floor: 10 ms)
        return {"family": family, "targets": [None], "values": [float(rng.uniform(0.02, 0.04))]}
    if family == "link_mass":
        masses = {j.child: j.inertial.mass for j in robot.joints}
        links = [ln for ln, m in masses.items() if m >= MIN_LINK_MASS]
        ln = str(rng.choice(links))
        v = rng.uniform(1.4, 2.0) if rng.random() < 0.7 else rng.uniform(0.6, 0.75)
        return {"family": family, "targets": [ln], "values": [float(v)]}
    k = int(rng.integers(1, 4))
    tg = [str(x) for x in rng.choice(joints, k, replace=False)]
    vals = []
    for j in tg:
        s = eff[j] / 3.0
        if family == "backlash":
            v = rng.uniform(0.01, 0.04)
        elif family == "coulomb_friction":
            v = rng.uniform(0.1, 0.3) * s
        elif family == "viscous_damping":
            v = rng.uniform(0.1, 0.4) * s
        elif family in ("pd_gain", "torque_constant"):
            v = rng.uniform(0.5, 0.8) if rng.random() < 0.7 else rng.uniform(1.25, 1.6)
        elif family == "armature":
            v = rng.uniform(0.003, 0.012) * s
        elif family == "sensor_bias":
            v = rng.uniform(0.005, 0.02) * rng.choice([-1.0, 1.0])
        elif family == "joint_compliance":
            v = 1.0 / (rng.uniform(1.5, 4.0) * kp[j])
        elif family == "parallel_spring":  # [N m/rad]
            v = rng.uniform(0.2, 0.6) * s
        else:
            raise ValueError(family)
        vals.append(float(v))
    return {"family": family, "targets": tg, "values": vals}


# ------------------------------------------------------------------------------------------ recording
#: The metadata a blind log keeps (the documented minimal schema, envs/recording.py): nothing of the
#: profile, the effects, the seeds, the terrain or the world's name.
META_KEYS = ("robot", "control_dt", "physics_dt", "fixed_base")


def blind(rec):
    """``rec`` stripped to what a robot's own log holds: no ``gt.*`` columns (ground truth a real robot
    does not have), metadata whitelisted to :data:`META_KEYS`. Returns a new ``Recording``."""
    from envs.recording import Recording

    cols = {k: v for k, v in rec.columns.items() if not k.startswith("gt.")}
    return Recording(cols, {k: rec.meta[k] for k in META_KEYS if k in rec.meta})


#: Excitation sources: the project's protocol (``sgatwalk excite``) or the referee's own (:mod:`.excitation`).
SOURCES = ("protocol", "referee")


def record(world: str, hidden: list[dict], out_dir: str, n_logs: int, seconds: float, seed: int,
           fixed_base: bool = True, source: str = "protocol", noise: float = NOISE) -> float:
    """Record ``n_logs`` excitation logs with ``hidden`` effects into ``out_dir`` (:func:`blind`: no
    ground truth, minimal metadata; files named ``log_NNN.parquet``).

    ``source``: ``"protocol"`` (``sysid.excitation``, what ``sgatwalk excite`` records) or
    ``"referee"`` (:func:`.excitation.referee_commands`, fixed base only). ``noise``: encoder noise
    standard deviation [rad].

    Raises:
        ValueError: unknown source, or the referee's source with a floating base.
    """
    from envs.recording import Recording
    from sysid.worlds import record_excitation, rough_ground

    from .excitation import record_referee

    if source not in SOURCES:
        raise ValueError(f"unknown excitation source {source!r}; choose from {', '.join(SOURCES)}")
    if source == "referee" and not fixed_base:
        raise ValueError("the referee's excitation is for a fixed base only")
    t0 = time.perf_counter()
    env = make_world(world, hidden, fixed_base, noise=noise)
    tmp = out_dir + ".tmp"
    if source == "referee":
        paths = record_referee(env, tmp, n_logs=n_logs, seconds=seconds, seed=seed)
    else:
        amp = sum(v for e in hidden if e["family"] == "terrain_roughness" for v in e.get("peak", ()))
        paths = record_excitation(env, tmp, n_logs=n_logs, seconds=seconds, seed=seed, prefix="log",
                                  terrain=rough_ground(amp, seed) if amp > 0 else None)
    env.close()
    os.makedirs(out_dir, exist_ok=True)
    for p in paths:
        blind(Recording.from_parquet(p)).to_parquet(os.path.join(out_dir, os.path.basename(p)))
        os.remove(p)
    os.rmdir(tmp)
    return time.perf_counter() - t0


def roughness_truth(hidden: list[dict], seed: int, n_logs: int) -> list[dict]:
    """The referee lays sparse bumps of the drawn peak height (its own parameter, kept as ``peak``)
    and scores the RMS height Sq of the surfaces it laid (``values``: the mean over the trial's logs
    of the heights' standard deviation over the 2 x 2 m patch), which is what the tool's value means.
    ``seed``: the recording seed :func:`record` passes to :func:`sysid.worlds.rough_ground`."""
    from sysid.worlds import rough_ground

    for e in hidden:
        if e["family"] == "terrain_roughness":
            e["peak"] = list(e["values"])
            ground = rough_ground(e["peak"][0], seed)
            e["values"] = [float(np.mean([ground(i).heights.std() for i in range(n_logs)]))]
    return hidden


def run_diagnose(args_list: list[str]) -> dict:
    """What ``sgatwalk diagnose`` does with these arguments, in-process, through the ``sysid`` API it
    calls (:func:`sysid.data.load_logs`, :func:`sysid.diagnose.calibrate` / :func:`sysid.diagnose.diagnose`,
    :func:`sysid.report.write_report`): ``["diagnose", "--real", DIR, "--out", OUT]`` plus ``--calibrate``,
    ``--calibration FILE``, ``--families LIST`` (``+NAME`` adds to the default), ``--no-plots``.
    Returns the report as the command's ``--json`` prints it (``calibration.json``'s content with
    ``--calibrate``).

    Raises:
        ValueError: an argument this runner does not know.
    """
    from sysid.candidates import FAMILIES, FIXED_BASE_FAMILIES, FLOATING_BASE_FAMILIES
    from sysid.data import load_logs
    from sysid.diagnose import calibrate, diagnose
    from sysid.report import public_json, write_report

    a = list(args_list)
    if a and a[0] == "diagnose":
        a = a[1:]
    opts, flags = {}, set()
    i = 0
    while i < len(a):
        if a[i] in ("--calibrate", "--no-plots"):
            flags.add(a[i])
            i += 1
        elif a[i] in ("--real", "--out", "--calibration", "--families"):
            opts[a[i]] = a[i + 1]
            i += 2
        else:
            raise ValueError(f"run_diagnose: unknown argument {a[i]!r}")
    logs = load_logs(opts["--real"])
    os.makedirs(opts["--out"], exist_ok=True)
    with contextlib.redirect_stdout(io.StringIO()):
        if "--calibrate" in flags:
            cal = calibrate(logs)
            with open(os.path.join(opts["--out"], "calibration.json"), "w") as f:
                json.dump(public_json(cal), f, indent=1)
            return public_json(cal)
        cal = None
        if "--calibration" in opts:
            with open(opts["--calibration"]) as f:
                cal = json.load(f)
        fams = None
        if "--families" in opts:
            text = opts["--families"]
            names = [x.strip() for x in text.lstrip("+").split(",") if x.strip()]
            if text.startswith("+"):
                default = FIXED_BASE_FAMILIES if logs[0].fixed_base else FLOATING_BASE_FAMILIES
                names = [f for f in FAMILIES if f in default or f in names]
            fams = names
        rep = diagnose(logs, calibration=cal, families=fams)
        write_report(rep, logs, opts["--out"], plots="--no-plots" not in flags)
    return json.loads(json.dumps(public_json(rep)))


# ------------------------------------------------------------------------------------------ trials
def plan_trials(classes: list[str], seeds: int, two_effect: int, seed0: int) -> list[tuple]:
    """The run's trials in order: ``("single", seed index, class)`` and ``("two", trial index, None)``.

    Interleaved: each seed's single-effect block (its classes in a permutation drawn from
    ``seed0 + s``) is followed by its share of the two-effect trials, so a run stopped early still has
    both kinds; two-effect trials left over go last.
    """
    trials = []
    per_block = int(np.ceil(two_effect / max(1, seeds)))
    two = list(range(two_effect))
    for s in range(seeds):
        order = np.random.default_rng(seed0 + s).permutation(len(classes))
        for c in order:
            trials.append(("single", s, classes[c]))
        for i in two[s * per_block:(s + 1) * per_block]:
            trials.append(("two", i, None))
    for i in two[seeds * per_block:]:
        trials.append(("two", i, None))
    return trials


def trial_id(kind: str, s: int, cls: str | None) -> str:
    """The trial's name in the truth folder and ``results.jsonl``: ``single_SS_CLASS`` or ``two_II``
    (the folder the tool reads is :func:`opaque_id`)."""
    return f"{kind}_{s:02d}_{cls}" if kind == "single" else f"two_{s:02d}"


def opaque_id(tid: str, seed0: int) -> str:
    """The trial's folder name under ``trials/``: a hash of its name and the run's base seed, so the
    path the tool reads says nothing of the hidden effect."""
    import hashlib

    return "t_" + hashlib.sha256(f"{seed0}:{tid}".encode()).hexdigest()[:12]


def draw_trial(kind: str, s: int, cls: str | None, seed0: int, pair_fams: list[str], robot,
               n_logs: int) -> tuple[int, list[dict]]:
    """The trial's seed and hidden effects (none for class "none"; two of ``pair_fams`` for a
    two-effect trial), with the terrain-roughness truth of its ``n_logs`` logs filled in.

    The seed depends only on (``seed0``, ``s``, the class's place in ``SEED_ORDER``, the kind), so
    adding classes or trials leaves earlier trials' draws unchanged.
    """
    cidx = SEED_ORDER.index(cls) if cls else 99
    seed = int(np.random.SeedSequence([seed0, s, cidx, 0 if kind == "single" else 1]).generate_state(1)[0])
    rng = np.random.default_rng(seed)
    if kind == "single":
        hidden = [] if cls == "none" else [draw_effect(cls, rng, robot)]
    else:
        fa, fb = rng.choice(pair_fams, 2, replace=False)
        hidden = [draw_effect(str(fa), rng, robot), draw_effect(str(fb), rng, robot)]
    hidden = roughness_truth(hidden, seed % 100000, n_logs)
    return seed, hidden
