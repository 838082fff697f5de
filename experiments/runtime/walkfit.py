"""Walk-level identification: terms of the identified sim fitted to real walks of one gait (the
thirteenth fidelity round, ``identified:walkfit=actuation`` and ``identified:walkfit=ground``).

The diagnosis (``sgatwalk diagnose``) fits its terms to excitation logs; the walks a grounding step
records (``optimize``'s 4 real walks of θ_i) load the legs far more and cross more of the ground, so
this module asks them too. It is system identification by simulated moments (McFadden, "A method of
simulated moments for estimation of discrete response models without numerical integration",
Econometrica 57(5), 1989): for every candidate on a grid (:data:`GRIDS`)

* ``actuation``: ``torque_limit`` (x the URDF effort, every joint), ``pd_gain`` (x kp, every leg
  joint) and ``latency`` [s]: the actuator weakness the diagnosis never names;
* ``ground``: ``latency`` [s] and the RMS height [m] of the uneven ground (``terrain_roughness``):
  the two terms the walks' moments move most (a latency lags every measured angle behind its
  command; uneven ground makes the torso sway in pitch and roll);

(``None``: the diagnosis's own value) the identified sim walks the gait on the same seeds (common
random numbers), and the candidate whose mean :func:`tracking_statistics` lie closest to the real
walks' (squared differences scaled by the spread of the real walks, :func:`moment_distance`) is
built into the world, as one more report that overrides the diagnosis term by term
(``sysid.identified.load_identified``). Only what a real robot logs is read: the commanded and
measured joint angles and the torso angle estimate.
"""

from __future__ import annotations

import itertools
import json
import os

import numpy as np

from common.files import atomic_write_text
from experiments.runtime.tasks import IDENTIFIED_CONFOUNDED
from robots import get_robot

#: The candidate grids (module docstring), by what they fit: each a dict term -> values (None: the
#: diagnosis's value), crossed. ``actuation``: torque-limit scales, leg kp scales, latencies [s] (48
#: candidates); ``ground``: latencies [s] and RMS heights [m] of the uneven ground (36 candidates).
GRIDS = {"actuation": {"torque_limit": (1.0, 0.9, 0.8, 0.7), "pd_gain": (1.0, 0.9, 0.8),
                       "latency": (None, 0.01, 0.02, 0.03)},
         "ground": {"latency": (None, 0.0125, 0.015, 0.0175, 0.02, 0.0225),
                    "terrain_roughness": (None, 0.0015, 0.002, 0.0025, 0.003, 0.0035)}}
#: Sim walks per candidate (common seeds across candidates).
SIM_WALKS = 4
#: Seconds cut from the end of a walk that fell (the fall itself is not tracking).
FALL_TAIL_S = 0.5


def statistic_names(robot_name: str = "nao") -> list[str]:
    """Names of the entries of :func:`tracking_statistics`, in order."""
    J = _tracked_legs(robot_name)
    return [f"rms[{j}]" for j in J] + [f"mean[{j}]" for j in J] + ["std[angle.pitch]", "std[angle.roll]"]


def _tracked_legs(robot_name: str) -> list[str]:
    """The leg joints with a servo command of their own (the NAO's RHipYawPitch follows LHipYawPitch)."""
    robot = get_robot(robot_name)
    return [j for j in robot.groups["legs"] if j in robot.actuated_joint_names]


def tracking_statistics(columns: dict, robot_name: str = "nao", control_dt: float = 0.01,
                        fell: bool = False) -> np.ndarray:
    """The moments a walk is summarised by: per commanded leg joint the RMS and the mean of the
    tracking error (measured − commanded angle) [rad], and the standard deviation of the torso pitch
    and roll estimates [rad].

    Args:
        columns: a recording's columns (``envs.Recording.columns``): ``q.<joint>``, ``cmd.<joint>``,
            ``angle.pitch``, ``angle.roll``.
        fell: the walk fell: its last :data:`FALL_TAIL_S` are left out.

    Returns:
        Array of shape ``(2 * J + 2,)``, J = leg joints with a command (:func:`statistic_names`).

    Raises:
        ValueError: a column is missing, or the walk is shorter than 0.5 s.
    """
    J = _tracked_legs(robot_name)
    need = [f"q.{j}" for j in J] + [f"cmd.{j}" for j in J] + ["angle.pitch", "angle.roll"]
    missing = [c for c in need if c not in columns]
    if missing:
        raise ValueError(f"recording lacks the columns {missing[:4]}{' ...' if len(missing) > 4 else ''}")
    n = len(columns["angle.pitch"])
    if fell:
        n -= int(round(FALL_TAIL_S / control_dt))
    if n * control_dt < 0.5:
        raise ValueError(f"walk too short to summarise ({n} samples)")
    E = np.stack([np.asarray(columns[f"q.{j}"], float)[:n] - np.asarray(columns[f"cmd.{j}"], float)[:n] for j in J], 1)
    return np.concatenate([np.sqrt(np.mean(E ** 2, 0)), E.mean(0),
                           [np.std(np.asarray(columns["angle.pitch"], float)[:n]),
                            np.std(np.asarray(columns["angle.roll"], float)[:n])]])


def moment_distance(sim: np.ndarray, real: np.ndarray) -> np.ndarray:
    """Distance of each candidate's mean moments from the real walks' mean moments.

    Args:
        sim: ``(candidates, walks, k)`` moments of the candidates' sim walks.
        real: ``(walks, k)`` moments of the real walks (at least 2).

    Returns:
        ``(candidates,)``: Σ_k ((mean sim − mean real) / s_k)², s_k = the real walks' standard deviation
        of moment k + 10 % of its mean's magnitude + 1e-4 (a floor where the real walks agree).

    Raises:
        ValueError: fewer than 2 real walks, or mismatched moment counts.
    """
    sim, real = np.asarray(sim, float), np.asarray(real, float)
    if real.ndim != 2 or len(real) < 2:
        raise ValueError("need the moments of at least 2 real walks")
    if sim.ndim != 3 or sim.shape[-1] != real.shape[-1]:
        raise ValueError(f"moment shapes disagree: sim {sim.shape}, real {real.shape}")
    mu = real.mean(0)
    scale = real.std(0, ddof=1) + 0.1 * np.abs(mu) + 1e-4
    return np.sum(((sim.mean(1) - mu) / scale) ** 2, axis=1)


def candidates(grid: str | dict = "actuation", robot_name: str = "nao") -> list[dict]:
    """Every candidate of ``grid`` (a name of :data:`GRIDS` or such a dict of term -> values), crossed
    in order, as ``{label: value}``: ``torque_limit``, ``pd_gain[<leg joint>]`` (one value for every leg
    joint), ``latency``, ``terrain_roughness`` (the RMS height of the uneven ground); a None value
    leaves the diagnosis's term as it is.

    Raises:
        ValueError: an unknown grid name or term.
    """
    if isinstance(grid, str):
        if grid not in GRIDS:
            raise ValueError(f"unknown walk-fit grid {grid!r}; choose from {', '.join(GRIDS)}")
        grid = GRIDS[grid]
    unknown = set(grid) - {"torque_limit", "pd_gain", "latency", "terrain_roughness"}
    if unknown:
        raise ValueError(f"walk-fit grid terms {sorted(unknown)} unknown (torque_limit, pd_gain, latency, terrain_roughness)")
    legs = get_robot(robot_name).groups["legs"]
    out = []
    for values in itertools.product(*grid.values()):
        m: dict = {}
        for term, v in zip(grid, values):
            if v is None:
                continue
            if term == "pd_gain":
                m.update({f"pd_gain[{j}]": float(v) for j in legs})
            else:
                m[term] = float(v)
        out.append(m)
    return out


def describe_terms(terms: dict) -> str:
    """``"torque limit x0.9, leg kp x0.8, latency 20 ms"``: a fitted candidate (:func:`candidates`) in
    words; terms left to the diagnosis are not named."""
    parts = []
    if "torque_limit" in terms:
        parts.append(f"torque limit x{terms['torque_limit']:g}")
    kp = next((v for k, v in terms.items() if k.startswith("pd_gain[")), None)
    if kp is not None:
        parts.append(f"leg kp x{kp:g}")
    if "latency" in terms:
        parts.append(f"latency {1000 * terms['latency']:g} ms")
    if "terrain_roughness" in terms:
        parts.append(f"ground RMS {1000 * terms['terrain_roughness']:g} mm")
    return ", ".join(parts) or "the diagnosis's values"


def _report(path: str, terms: dict, extra: dict | None = None) -> str:
    """Write ``terms`` as a report that ``sysid.identified.load_identified`` reads as overrides:
    ``terrain_roughness`` as a declared uneven ground, the rest as model terms."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    model = {k: v for k, v in terms.items() if k != "terrain_roughness"}
    effects = [{"family": "terrain_roughness", "value": terms["terrain_roughness"]}] if "terrain_roughness" in terms else []
    atomic_write_text(path, json.dumps({"model": model, "base_model": {}, "effects": effects, **(extra or {})}, indent=1))
    return path


def fit_walk_terms(real_recordings: list, reports: list[str], theta, out_dir: str, executor, *,
                       seeds: list[int], seconds: float, grid: str | dict = "actuation", robot_name: str = "nao",
                       identified_confounded: bool = IDENTIFIED_CONFOUNDED) -> dict:
    """Fit the terms of ``grid`` in the identified sim of ``reports`` to real walks of the gait ``theta``.

    Args:
        real_recordings: ``envs.Recording`` of the real walks (at least 2), all of ``theta``.
        reports: the diagnosis reports of the identified sim (``sysid.identified.load_identified``).
        theta: the gait (16 parameters, SI).
        out_dir: where the candidates' reports and the result (``report.json``) go; a result there
            is returned as it is (resumable).
        executor: an executor of ``experiments.runtime.executors`` (the sim walks run on it).
        seeds: the sim walks' seeds, the same for every candidate (common random numbers).
        seconds: walk length [s].
        grid: what is fitted: a name of :data:`GRIDS` or such a dict (:func:`candidates`).
        identified_confounded: also build in the contact terms confounded with the uneven ground
            (``sysid.identified.confounded_with_ground``; default ``experiments.runtime.tasks.IDENTIFIED_CONFOUNDED``).

    Returns:
        The saved result: ``{"terms": the chosen terms (:func:`candidates` labels), "walkfit":
        {"grid", "statistics", "candidates": [{"terms", "distance", "falls"}], "best", "real_walks",
        "real_moments"}, "path": report.json}``.

    Raises:
        ValueError: fewer than 2 real walks, an unknown grid, or a recording without the columns (named).
    """
    from experiments.runtime.batch import map_episodes  # lazy: loads the engines

    path = os.path.join(out_dir, "report.json")
    if os.path.exists(path):
        with open(path) as f:
            doc = json.load(f)
        return {"terms": doc["walkfit"]["candidates"][doc["walkfit"]["best"]]["terms"], "walkfit": doc["walkfit"],
                "path": path}
    cands = candidates(grid, robot_name)
    if len(real_recordings) < 2:
        raise ValueError(f"the walk fit needs at least 2 real walks, got {len(real_recordings)}")
    R = np.array([tracking_statistics(r.columns, robot_name, float(r.meta.get("control_dt", 0.01)),
                                      bool(r.meta.get("fell", False))) for r in real_recordings])
    paths = [_report(os.path.join(out_dir, "candidates", f"c{i:02d}", "report.json"), m) for i, m in enumerate(cands)]
    tasks = [{"world": "identified", "identified": list(reports) + [p], "identified_confounded": identified_confounded,
              "theta": list(map(float, theta)), "seed": int(s), "seconds": float(seconds), "record": True, "robot": robot_name}
             for p in paths for s in seeds]
    res = map_episodes(executor, tasks)
    S = np.array([tracking_statistics(r["recording"][0], robot_name, float(r["recording"][1].get("control_dt", 0.01)),
                                      bool(r["fell"])) for r in res])
    S = S.reshape(len(cands), len(seeds), -1)
    dist = moment_distance(S, R)
    best = int(np.argmin(dist))
    falls = np.array([r["fell"] for r in res], float).reshape(len(cands), len(seeds)).mean(1)
    fit = {"grid": grid if isinstance(grid, str) else "custom", "statistics": statistic_names(robot_name),
           "best": best, "real_walks": len(real_recordings), "real_moments": R.mean(0).tolist(),
           "candidates": [{"terms": m, "distance": float(d), "falls": float(f)} for m, d, f in zip(cands, dist, falls)]}
    _report(path, cands[best], {"walkfit": fit})
    return {"terms": cands[best], "walkfit": fit, "path": path}
