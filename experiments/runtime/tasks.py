"""Picklable rollout tasks for the executors: one walk episode in a named world.

A task is a plain dict (so it pickles cheaply and travels to process-pool or Ray workers):

========================  =====================================================================
key                       meaning
========================  =====================================================================
``world``                 ``"sim"`` (MuJoCo), ``"real"`` (PyBullet), ``"identified"`` (MuJoCo with
                          the effects of the diagnosis reports in ``identified``), ``"grounded"``
                          (the sim, or the identified sim if ``identified`` is given, wrapped in
                          ``sgat.GroundedEnv`` with the transformer saved in ``transformer``)
``theta``                 the 16 gait parameters in SI units (list)
``seed``                  the episode seed (terrain, effects, noise, SGAT sampling)
``seconds``               episode length [s] (the paper: 7.5)
``profile``               real-world effect profile name (real world only); ``NAME:mean`` is that
                          profile with every effect fixed at the middle of its range
                          (:func:`mean_profile`: its mean physics without its spread)
``action_noise``          std [rad] of Gaussian noise on the applied leg targets (sim data
                          collection with exploration noise, or the ANE baseline)
``transformer``           directory of a saved ``sgat.ActionTransformer`` (grounded world)
``identified``            list of ``report.json`` paths of ``sgatwalk diagnose`` (identified world,
                          or the base of a grounded one: hybrid grounding)
``identified_terms``      False: leave the deterministic effects out (ablation; default True)
``identified_ground``     False: leave the identified uneven ground out (ablation; default True)
``identified_confounded`` True: also build in the contact terms that only stand in for the identified
                          uneven ground (``sysid.identified.confounded_with_ground``; default
                          :data:`IDENTIFIED_CONFOUNDED`)
``ground``                ``[kind, level]``: the uneven ground of every episode in place of the world's
                          own, drawn from the episode seed: ``"real"`` the real world's lumpy terrain of
                          amplitude ``level`` [m] (``envs.bullet_world.real_ground``), ``"model"`` the
                          identified sim's Gaussian surface of RMS height ``level`` [m]
                          (``sysid.identified.model_ground``); for the real and identified worlds (the
                          oracle yardsticks of ``sgatwalk fidelity``, ``ground=``)
``robot``                 ``robots.get_robot`` name (default ``"nao"``; the identified worlds are the NAO's)
``record``                return the recording too (columns + metadata)
``meta``                  extra metadata for the recording
========================  =====================================================================

Workers cache worlds and transformers per process, so a generation of CMA-ES builds each once.
Torch is kept to one thread in workers (``experiments.runtime.executors``).
"""

from __future__ import annotations

import os
import time

import numpy as np

#: Whether the identified worlds build in the contact terms the diagnosis kept only as uncertain and
#: could not tell apart from the uneven ground it declared (``sysid.identified.confounded_with_ground``):
#: the default of a task's ``identified_confounded`` and of every identified / hybrid world of
#: ``fidelity``, ``optimize`` and ``walkfit``. False since the fourteenth fidelity round (README), True before.
IDENTIFIED_CONFOUNDED = False

from common.defaults import EPISODE_SECONDS
from robots import get_robot

_WORLDS: dict = {}
_TRANSFORMERS: dict = {}


def _transformer(path: str):
    from sgat.transformer import ActionTransformer  # lazy: sgat loads torch

    key = (path, os.path.getmtime(os.path.join(path, "transformer.json")))
    if key not in _TRANSFORMERS:
        _TRANSFORMERS.clear()
        _TRANSFORMERS[key] = ActionTransformer.load(path)
    return _TRANSFORMERS[key]


def _world(task: dict):
    from envs import NaoRealEnv, NaoSimEnv  # lazy: loads the engines
    from envs.wrappers import ActionMismatch  # lazy: loads the engines
    from sgat.transformer import GroundedEnv  # lazy: sgat loads torch
    from experiments.runtime.grounding import nao_spec  # lazy: loads torch (sgat)

    world = task["world"]
    if world not in ("real", "sim", "grounded", "identified"):
        raise ValueError(f"unknown world {world!r}; choose sim, real, identified or grounded")
    reports = tuple(task.get("identified") or ())
    if world == "identified" and not reports:
        raise ValueError("the identified world needs the diagnosis reports (task['identified'])")
    parts = (bool(task.get("identified_terms", True)), bool(task.get("identified_ground", True)),
             bool(task.get("identified_confounded", IDENTIFIED_CONFOUNDED)))
    robot_name = task.get("robot", "nao")
    if reports and robot_name != "nao":
        raise ValueError("the identified worlds model the NAO only")
    key = (world == "real", task.get("profile", "real"), task.get("terrain", "lumpy"), reports, parts, robot_name,
           tuple(task.get("ground") or ()))
    if key not in _WORLDS:
        ground = _ground(task.get("ground"), world)  # the world's own: built once with it
        if len(_WORLDS) >= 8:  # a fidelity sweep builds one identified world per draw: keep a few
            for env in _WORLDS.values():
                env.close()
            _WORLDS.clear()
        robot = get_robot(robot_name)
        if world == "real":
            _WORLDS[key] = NaoRealEnv(robot, profile=_real_profile(task.get("profile", "real"), robot),
                                      terrain=task.get("terrain", "lumpy"), ground=ground)
        elif reports:
            from sysid.identified import IdentifiedSimEnv, load_identified  # lazy: loads the engines

            terms, rms = load_identified(list(reports), confounded=parts[2])
            _WORLDS[key] = IdentifiedSimEnv(terms if parts[0] else {}, rms if parts[1] else 0.0, ground=ground)
        else:
            _WORLDS[key] = NaoSimEnv(robot)
    env = _WORLDS[key]
    sigma = float(task.get("action_noise", 0.0) or 0.0)
    if sigma > 0:
        env = ActionMismatch(env, noise_std=sigma, index=nao_spec(robot=robot_name).action_index, seed=task["seed"])
    if world == "grounded":
        env = GroundedEnv(env, _transformer(task["transformer"]))
    return env


def _ground(spec, world: str):
    """The ``seed -> Heightfield`` of a task's ``ground`` (``[kind, level]``), or None without one.

    Raises:
        ValueError: an unknown kind, a negative level, or a world that does not draw its ground.
    """
    if not spec:
        return None
    import functools

    kind, level = spec
    level = float(level)
    if world not in ("real", "identified"):
        raise ValueError(f"task ground {spec!r}: only the real and the identified worlds take a ground, not {world!r}")
    if not level >= 0:
        raise ValueError(f"task ground {spec!r}: its level must be >= 0 [m]")
    if kind == "real":
        from envs.bullet_world import real_ground  # lazy: loads the engines

        return functools.partial(real_ground, amplitude=level)
    if kind == "model":
        from sysid.identified import model_ground  # lazy: loads the engines

        return functools.partial(model_ground, rms_height=level)
    raise ValueError(f"task ground {spec!r}: unknown kind {kind!r} (real or model)")


def mean_profile(profile):
    """``profile`` (an ``envs.effects.RealProfile``) with every effect fixed at the middle of its
    range, named ``"<name>:mean"``: the real world's mean physics without its spread from episode to
    episode (the terrain's shape stays random per episode; its amplitude is fixed too). What a
    training world that identified the real physics exactly, as one point, can at best be."""
    import dataclasses

    from envs.effects import EFFECTS  # lazy: loads the engines

    mids = {f: ((lo + hi) / 2.0,) * 2 for f in EFFECTS for lo, hi in [getattr(profile, f)]}
    return dataclasses.replace(profile, name=f"{profile.name}:mean", **mids)


#: The effect families of :func:`mean_physics_report`'s model and ground, in its order (``drop=``).
MEAN_PHYSICS_FAMILIES = ("latency", "torque_limit", "foot_friction", "pd_gain", "backlash", "coulomb_friction",
                         "viscous_damping", "link_mass", "terrain_roughness")


def mean_physics_report(profile, robot_name: str = "nao", terrain_samples: int = 16, *,
                        ground_compliance: float | None = None, drop=()) -> dict:
    """The real world's mean physics (:func:`mean_profile`) as a report of ``sgatwalk diagnose``, so
    that the identified sim (``sysid.identified.IdentifiedSimEnv``) builds it into MuJoCo: what the
    identified world would be if the diagnosis found every effect exactly (the ``oracle:mean=1:
    engine=mujoco`` world of ``sgatwalk fidelity``, thirteenth round; it reads the profile, so it is
    a yardstick, not a method).

    Each effect at the middle of its range becomes the diagnosis family with the same meaning:
    ``kp_scale`` -> ``pd_gain[j]``, ``latency_s`` -> ``latency``, ``backlash_rad`` -> ``backlash[j]``,
    ``coulomb_friction_nm`` -> ``coulomb_friction[j]``, ``viscous_damping`` -> ``viscous_damping[j]``
    (every actuated joint j), ``torque_limit_scale`` -> ``torque_limit``, ``mass_scale`` ->
    ``link_mass[l]`` (every link), ``foot_friction``; ``terrain_amplitude`` -> a declared uneven ground
    of the RMS height the lumpy terrain of that amplitude has (mean over ``terrain_samples`` surfaces:
    the identified world's ground is a Gaussian surface of that RMS height, not the lumpy one). Left
    out: the servo damping scale (its middle is 1), the encoder offsets (middle 0) and the sensor
    noises (no deterministic family).

    The MuJoCo form itself, and ablations (thirty-first round; ``benchmarks/engine_gap_walks.py``
    measures the form against PyBullet): ``ground_compliance`` adds the ground contact's time constant
    the diagnosis identifies on the real world's stepping logs (the sim's own is
    ``envs.mujoco_world.GROUND_TIMECONST``; MuJoCo holds it at 2 physics steps or more); ``drop``
    leaves families out: ``backlash``, which ``sysid.model`` builds as a series play hinge on every
    joint (a walk unlike the real world's dead-band servos even at zero width), or any other, to ask
    what an identified world that misses it loses (``terrain_roughness``: flat ground).

    Args:
        profile: an ``envs.effects.RealProfile`` or a profile name (``envs.effects.get_profile``).
        ground_compliance: contact time constant of the ground [s] (None: the sim's own).
        drop: names of :data:`MEAN_PHYSICS_FAMILIES` to leave out.

    Returns:
        ``{"model": {label: value}, "base_model": {}, "effects": [terrain_roughness] or []}``.

    Raises:
        ValueError: ``ground_compliance`` not finite and > 0; an unknown family in ``drop``.
    """
    if ground_compliance is not None and not (np.isfinite(ground_compliance) and ground_compliance > 0):
        raise ValueError(f"ground_compliance must be a time constant > 0 s, got {ground_compliance!r}")
    drop = set(drop)
    if drop - set(MEAN_PHYSICS_FAMILIES):
        raise ValueError(f"unknown effect famil(ies) {', '.join(sorted(drop - set(MEAN_PHYSICS_FAMILIES)))} to drop; "
                         f"choose from {', '.join(MEAN_PHYSICS_FAMILIES)}")
    from envs.effects import get_profile  # lazy: loads the engines
    from terrain import lumpy

    robot = get_robot(robot_name)
    p = mean_profile(get_profile(profile, robot))
    mid = {f: getattr(p, f)[0] for f in ("kp_scale", "latency_s", "backlash_rad", "coulomb_friction_nm", "viscous_damping",
                                         "torque_limit_scale", "mass_scale", "foot_friction", "terrain_amplitude")}
    model: dict[str, float] = {"latency": mid["latency_s"], "torque_limit": mid["torque_limit_scale"],
                               "foot_friction": mid["foot_friction"]}
    for fam, eff in (("pd_gain", "kp_scale"), ("backlash", "backlash_rad"), ("coulomb_friction", "coulomb_friction_nm"),
                     ("viscous_damping", "viscous_damping")):
        for j in robot.actuated_joint_names:
            model[f"{fam}[{j}]"] = mid[eff]
    for link in robot.links:
        model[f"link_mass[{link}]"] = mid["mass_scale"]
    model = {k: v for k, v in model.items() if k.split("[")[0] not in drop}
    if ground_compliance is not None:
        model["ground_compliance"] = float(ground_compliance)
    effects = []
    if mid["terrain_amplitude"] > 0 and "terrain_roughness" not in drop:
        rms = float(np.mean([lumpy(s, amplitude=mid["terrain_amplitude"]).heights.std() for s in range(terrain_samples)]))
        effects.append({"family": "terrain_roughness", "value": rms})
    return {"model": model, "base_model": {}, "effects": effects}


def _real_profile(name: str, robot):
    """The profile a task names: ``"real"`` etc. as they are (``envs.effects.get_profile`` resolves
    them), ``"<name>:mean"`` as :func:`mean_profile` of that profile for ``robot``.

    Raises:
        ValueError: an unknown suffix after ``:``.
    """
    base, sep, mode = str(name).partition(":")
    if not sep:
        return name
    if mode != "mean":
        raise ValueError(f"profile {name!r}: unknown form {mode!r} (NAME or NAME:mean)")
    from envs.effects import get_profile  # lazy: loads the engines

    return mean_profile(get_profile(base, robot))


def run_episode(task: dict) -> dict:
    """Run one walk episode; returns the fitness metrics (and the recording if asked).

    Returns:
        dict with ``fitness``, ``speed_cm_s``, ``fell``, ``fall_reason``, ``fall_time_s``,
        ``drift_m``, ``distance_m``, ``seed``, and ``recording`` = (columns, meta) if
        ``task["record"]``. A NaN or exploding simulation counts as a fall ("unstable").
    """
    from experiments.runtime.fitness import run_walk  # lazy: loads the engines
    from walk_engine import params_for  # lazy: scipy

    env = _world(task)
    params = params_for(env.unwrapped.robot).from_array(np.asarray(task["theta"], dtype=float))
    rec, res = run_walk(params, seed=int(task["seed"]), seconds=float(task.get("seconds", EPISODE_SECONDS)), env=env)
    return episode_result(task, rec, res)


def episode_result(task: dict, rec, res) -> dict:
    """What :func:`run_episode` returns for a finished walk: the fitness metrics, the seed, and the
    recording (with the task's world and metadata) if the task asks for it."""
    rec.meta.update({"world": task["world"], **task.get("meta", {})})
    out = res.to_dict()
    out["seed"] = int(task["seed"])
    if task.get("record"):
        out["recording"] = (rec.columns, rec.meta)
    return out


def fit_grounding_task(task: dict) -> dict:
    """Fit and save the action transformer of one grounding step (a picklable executor task).

    Task keys: ``real``, ``sim`` (lists of recording paths), ``config`` (a
    :class:`sgat.grounding.GroundingConfig` as a dict), ``seed``, ``out`` (directory to save to),
    optional ``state``/``history`` (the grounding state), ``robot``, and ``identified`` /
    ``identified_confounded`` (hybrid grounding: the identified sim is the one grounded, which DAD
    rounds replay in).

    Returns:
        ``{"out", "forward_val", "inverse_val", "n_real", "n_sim", "wall_s"}``.
    """
    from envs import Recording  # lazy: loads the engines
    from experiments.runtime.grounding import fit_nao_grounding  # lazy: loads torch (sgat)
    from sgat.grounding import GroundingConfig  # lazy: sgat loads torch

    t0 = time.perf_counter()
    cfg = dict(task["config"])
    cfg["hidden"] = tuple(cfg["hidden"])
    config = GroundingConfig(**cfg)
    base = None
    if config.dad_iterations:  # the sim the transformer grounds: the identified one for hybrid grounding
        base = _world({"world": "identified" if task.get("identified") else "sim", "seed": 0,
                       **{k: task[k] for k in ("identified", "identified_confounded", "robot") if k in task}})
    fit = fit_nao_grounding([Recording.from_parquet(p) for p in task["real"]],
                            [Recording.from_parquet(p) for p in task["sim"]], config,
                            state=task.get("state", "legs"), history=int(task.get("history", 1)), seed=int(task["seed"]),
                            robot=task.get("robot", "nao"), base_env=base)
    fit.transformer.save(task["out"])
    return {"out": task["out"], "forward_val": float(np.mean([r.val_loss for r in fit.forward_reports])),
            "inverse_val": float(np.mean([r.val_loss for r in fit.inverse_reports])), "n_real": fit.info["n_real"],
            "n_sim": fit.info["n_sim"], "wall_s": time.perf_counter() - t0}


def replay_walk_task(task: dict) -> dict:
    """Teacher-force the grounded sim along one recorded real walk (``sgat.TeacherForcedEnv``).

    Task keys: ``recording`` (the real walk's parquet path), ``transformer`` (directory of the fitted
    transformer), ``theta`` (the walk's gait), ``seconds``, optional ``identified`` and
    ``identified_confounded`` (hybrid: teacher-force the identified sim) and ``robot``. The episode
    seed is the recording's; after the recording ends the sim walks on ungrounded to ``seconds``.

    Returns:
        ``{"fell", "fall_time_s", "real_fell", "real_fall_time_s", "q_rms_rad", "q_rms_plain_rad"}``:
        whether the teacher-forced sim fell and when, the same of the real walk, and the RMS error
        of the 12 leg joint angles against the real walk over its length [rad], teacher-forced and
        with the sim ungrounded (what the tracking closes).
    """
    from envs import ObservationLayout, Recording  # lazy: loads the engines
    from experiments.runtime.fitness import run_walk  # lazy: loads the engines
    from sgat.grounding import recording_observations  # lazy: sgat loads torch
    from sgat.transformer import TeacherForcedEnv  # lazy: sgat loads torch
    from walk_engine import params_for  # lazy: scipy

    rec = Recording.from_parquet(task["recording"])
    tr = _transformer(task["transformer"])
    robot = get_robot(task.get("robot", "nao"))
    layout = ObservationLayout(robot)
    ref = tr.spec.states(recording_observations(rec, layout))
    base = _world({**task, "world": "identified" if task.get("identified") else "sim"})
    params = params_for(robot).from_array(np.asarray(task["theta"], dtype=float))
    seed, seconds = int(rec.meta.get("seed", 0)), float(task.get("seconds", EPISODE_SECONDS))
    nq = len(robot.groups["legs"])

    def q_rms(r) -> float:
        S = tr.spec.states(recording_observations(r, layout))
        n = min(len(S), len(ref))
        return float(np.sqrt(np.mean((S[:n, :nq] - ref[:n, :nq]) ** 2)))

    forced, res = run_walk(params, seed=seed, seconds=seconds, env=TeacherForcedEnv(base, tr, ref))
    plain, _ = run_walk(params, seed=seed, seconds=seconds, env=base)
    return {"fell": bool(res.fell), "fall_time_s": res.fall_time_s, "real_fell": bool(rec.meta.get("fell", False)),
            "real_fall_time_s": rec.meta.get("fall_time"), "q_rms_rad": q_rms(forced), "q_rms_plain_rad": q_rms(plain)}
