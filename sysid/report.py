"""The diagnosis report: printed text, ``report.json``, plots and the identified model as MJCF.

:func:`write_report` writes into ``REPORT_DIR``:

* ``report.json``: the dict of :func:`sysid.diagnose.diagnose` (keys ``verdict``, ``noise_floor``,
  ``heldout_rms_before``, ``heldout_rms_after`` [rad], ``effects`` [{family, joints, links, value,
  unit, ci95, ...}] (the findings), ``equivalent`` (effects named only as their class: the candidates
  the held-out test cannot separate and the excitation segment that would), ``class_tests`` (every
  held-out test of a finding against its class's rivals), ``uncertain`` (fitted terms not claimed as
  physics, each with its ``reasons``), ``rejected``, ``indistinguishable``, ``residual``, ``localisation``,
  ``base_state`` (where the floating base's replay state came from), ``noise`` (the logs' sensor σ,
  the calibration's for reference, the floor per channel), ...);
* ``report.txt``: the printed report;
* ``overlay.png`` (per-joint measured vs sim before/after on a held-out log), ``residual_by_joint.png``,
  ``residual_by_phase.png``, ``hysteresis.png`` (command vs output where backlash or Coulomb
  friction was found);
* ``identified_model.xml``: the MuJoCo sim with the effects found (``MjSpec.to_xml``).

Every file is written atomically (temporary file, then rename).
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

from sysid.candidates import Term
from common.files import atomic_write_text, jsonable


def public_json(o):
    """``o`` as strict JSON values without its private (``_``-prefixed) keys (:func:`common.files.jsonable`)."""
    return jsonable(o, private=False)


def _ci_text(e: dict) -> str:
    lo, hi = e["ci95"]
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return "95 % CI: not identifiable with this data"
    if e["family"] == "latency":
        return f"95 % CI [{1000 * lo:.2f}, {1000 * hi:.2f}] ms"
    if e["unit"] == "rad":
        return f"95 % CI [{1000 * lo:.2f}, {1000 * hi:.2f}] mrad"
    if e["unit"] == "m":
        return f"95 % CI [{1000 * lo:.1f}, {1000 * hi:.1f}] mm"
    return f"95 % CI [{lo:.4g}, {hi:.4g}] {e['unit']}".rstrip()


def _nominal_text(e: dict) -> str:
    from sysid.candidates import FAMILIES

    return FAMILIES[e["family"]].fmt(e["nominal"])


def format_report(rep: dict) -> str:
    """The human-readable report (what ``sgatwalk diagnose`` prints)."""
    mm = 1000.0
    lines = ["=" * 100, "VERDICT: " + rep["verdict"], "=" * 100]
    noise = rep["noise"]
    cal_sigma = (noise.get("calibration_sigma") or {}).get("encoders")
    lines.append(f"noise floor {mm * rep['noise_floor']:.3f} mrad (sensor σ {mm * noise['sigma']['encoders']:.3f} mrad"
                 + (" from these logs" if "sigma_source" in noise else "")
                 + (f", the calibration's {mm * cal_sigma:.3f} mrad" if cal_sigma is not None else "")
                 + (", engine gap calibrated" if noise["engine_gap_calibrated"] else ", engine gap not calibrated")
                 + f"); held-out RMS before {mm * rep['heldout_rms_before']:.3f} mrad, after {mm * rep['heldout_rms_after']:.3f} mrad"
                 + (f", gap closed {100 * rep['gap_closed']:.0f} %" if rep.get("gap_closed") is not None else ""))
    lines.append(f"data: {rep['split']['note']}; {rep['split']['mode']}; train {', '.join(rep['split']['train'])}; "
                 f"held out {', '.join(rep['split']['heldout'])}")
    if rep.get("base_state"):
        lines.append(f"base state of the replays: {rep['base_state']}")
    if rep.get("weighing"):
        w = rep["weighing"]
        lines.append(f"weight on the feet: {w['text']}; "
                     + (f"{w['root']} mass x{w['root_scale']:.3f} in every replay" if w["found"] else "no mass difference"))
    for wtxt in rep.get("warnings", []):
        if wtxt not in rep["verdict"]:
            lines.append(f"WARNING: {wtxt}")
    lines.append("")
    lines.append("EFFECTS FOUND" + ("" if rep["effects"] else ": none"))
    for e in rep["effects"]:
        lines.append(f"  - {e['words']} at {e['where']}: {e['display']}  ({_ci_text(e)}; the sim had {_nominal_text(e)})")
    if rep.get("equivalent"):
        lines.append("")
        lines.append("NAMED AS A CLASS (the best fit is in the identified model; these logs cannot tell the candidates "
                     "apart)")
        for e in rep["equivalent"]:
            lines.append(f"  - {e['words'] or 'effect'} at {e['where']}:")
            for c in e["candidates"]:
                z = c.get("z")
                lines.append(f"      {c['words']}: {c['display']} (held-out cost {c['heldout_cost']:.2f}"
                             + ("" if z is None else f", held-out test z {z:+.2f} against the best") + ")")
            lines.append(f"      to tell them apart: record the {e['segment']} segment ({e['experiment']}): "
                         f"sgatwalk excite --segments +{e['segment']}, then diagnose again")
    if rep.get("uncertain"):
        lines.append("")
        lines.append("UNCERTAIN / COMPENSATING (in the identified model, not claimed as physics)")
        for e in rep["uncertain"]:
            lines.append(f"  - {e['words']} at {e['where']}: {e['display']}  ({_ci_text(e)}; the sim had {_nominal_text(e)})")
            for r in e["reasons"]:
                lines.append(f"      {r}")
    lines.append("")
    lines.append("CONSIDERED AND REJECTED")
    if rep["rejected"]:
        for r in rep["rejected"]:
            lines.append(f"  - {r['term']} ({r['value']:.4g}): {r['reason']}")
    fam_found = ({e["family"] for e in rep["effects"] + rep.get("uncertain", [])}
                 | {c["family"] for e in rep.get("equivalent", []) for c in e["candidates"]}
                 | {r["family"] for r in rep["rejected"]})
    not_picked = [f for f in rep["families_considered"] if f not in fam_found]
    if not_picked:
        lines.append(f"  - not selected by screening (sensitivity dictionary + OMP/BIC): {', '.join(not_picked)}")
    lines.append("")
    lines.append("CANNOT BE TOLD APART WITH THIS DATA" + ("" if rep["indistinguishable"] else ": nothing flagged"))
    for p in rep["indistinguishable"]:
        c = p.get("corr")
        cor = (f" (|corr| {abs(c):.2f})" if c is not None and math.isfinite(c)
               else f" (held-out cost within {p['heldout_cost_difference']:.2f}: both explain the data)"
               if p.get("heldout_cost_difference") is not None else "")
        lines.append(f"  - {p['a']} vs {p['b']}{cor}; to separate them: {p['experiment']}")
    lines.append("")
    lines.append("LOCALISATION (nominal replay, all logs): worst channels")
    ch = rep["localisation"]["channels"]
    worst = sorted(ch.items(), key=lambda kv: -kv[1]["rms_over_floor"])
    w = max(16, *(len(nm) for nm in ch))  # 16 for the NAO's names; the G1's are longer
    hdr = f"  {'channel':{w}s} {'RMS/floor':>9s} {'lag ms':>7s} {'bias mrad':>9s} {'c(sgn v)':>8s} {'c(v)':>6s} {'c(acc)':>6s} {'c(trk)':>6s} {'c(grav)':>7s} {'acf1':>5s}"
    lines.append(hdr)
    shown = 0
    for nm, s in worst:
        if s["rms_over_floor"] ** 2 <= 1.5 and shown >= 3:
            break
        lines.append(f"  {nm:{w}s} {s['rms_over_floor']:9.2f} {s['lag_ms']:7.1f} {1000 * s['bias']:9.3f} {s['corr_sign_v']:8.2f} "
                     f"{s['corr_v']:6.2f} {s['corr_acc']:6.2f} {s.get('corr_tracking', float('nan')):6.2f} "
                     f"{s.get('corr_gravity', float('nan')):7.2f} {s['whiteness'][0]:5.2f}")
        shown += 1
        if shown >= 10:
            break
    g = rep["localisation"]["groups"]
    lines.append("  signal groups (RMS/floor): " + ", ".join(f"{k} {v:.2f}" for k, v in g.items()))
    ph = rep["localisation"]["phases"]
    lines.append("  residual energy by phase (/floor²): " + ", ".join(
        f"{k} {v['energy']:.2f} ({v['samples']} samples)" if isinstance(v, dict) else f"{k} {v:.2f}" for k, v in ph.items()))
    lines.append("")
    res = rep["residual"]
    after = res["per_joint_rms_over_floor_after"]
    top = sorted(after.items(), key=lambda kv: -kv[1])[:5]
    lines.append("RESIDUAL LEFT (identified model, all logs): worst channels " +
                 ", ".join(f"{k} {v:.2f}x" for k, v in top) + " of the floor")
    wh = res["whiteness_after"]
    acf1 = float(np.median([v[0] for v in wh.values()]))
    lines.append(f"  median lag-1 autocorrelation {acf1:.2f} (0 = white); "
                 + ("unexplained joints: " + ", ".join(res["unexplained_joints"]) if res["unexplained_joints"]
                    else "every joint within 1.5x its floor energy"))
    lines.append("  by phase (/floor²): " + ", ".join(
        f"{k} {v['energy']:.2f}" if isinstance(v, dict) else f"{k} {v:.2f}" for k, v in res["phases_after"].items()))
    lines.append("")
    lines.append(f"runtime {rep['runtime_s']:.1f} s, {rep['rollouts']} replays"
                 + ("; the time budget stopped the search early (--time-budget)" if rep.get("time_budget_reached") else ""))
    return "\n".join(lines)


def export_mjcf(model_terms: dict, fixed_base: bool, physics_dt: float, robot_name: str = "nao") -> str:
    """MJCF text of the sim of the robot ``robot_name`` (``RobotModel.name``; a recording's
    ``meta["robot"]``) with ``model_terms`` (Term -> value) applied.

    Sensor biases are not physics: they are stored as ``<numeric name="sensor_bias:JOINT">``.

    Raises:
        KeyError: an unknown robot name.
    """
    from robots import get_robot
    from sysid.candidates import Term, series_structure
    from sysid.model import (STRIBECK_GAIN_SHARE, STRIBECK_SUFFIX, STRIBECK_VELOCITY, Structure, joint_inertia,
                             replay_spec, spring_stiffness_max)

    robot = get_robot(robot_name)
    st = series_structure(Structure(fixed_base=fixed_base, physics_dt=physics_dt, robot=robot.name), model_terms)
    spec = replay_spec(robot, st)
    eff = dict(zip(robot.joint_names, robot.effort))
    for t, v in model_terms.items():
        v = float(v)
        f = t.family
        if f == "latency":  # the servos' commands (a Stribeck element is friction, not commanded)
            for n in robot.joint_names:
                spec.actuator(n).delay = v
        elif f in ("coulomb_friction", "coulomb_friction_all"):
            for n in ([t.target] if f == "coulomb_friction" else robot.joint_names):
                spec.joint(n).frictionloss = spec.joint(n).frictionloss + v
        elif f == "stribeck_friction":  # as sysid.candidates.apply_terms: the static level, given back with speed
            spec.joint(t.target).frictionloss = spec.joint(t.target).frictionloss + v
            vs = float(model_terms.get(Term("stribeck_velocity", t.target), STRIBECK_VELOCITY))
            k = min(v / vs, STRIBECK_GAIN_SHARE * joint_inertia(robot.name, fixed_base)[t.target] / physics_dt)
            a = spec.actuator(t.target + STRIBECK_SUFFIX)
            a.biasprm[2] = k
            # MuJoCo 4.0 compiles an affine bias [0, 0, k] under a zero gain to [0, 0, -0]; a gain of 1e-12
            # keeps it (the element has no command: ctrl 0, so the gain adds nothing)
            a.gainprm[0] = 1e-12
            a.forcerange = [-max(v, 1e-9), max(v, 1e-9)]
        elif f in ("viscous_damping", "viscous_damping_all"):
            for n in ([t.target] if f == "viscous_damping" else robot.joint_names):
                j = spec.joint(n)
                d = list(j.damping)
                d[0] += v
                j.damping = d
        elif f == "armature":
            spec.joint(t.target).armature = spec.joint(t.target).armature + v
        elif f == "pd_gain":
            a = spec.actuator(t.target)
            a.gainprm[0] = a.gainprm[0] * v
            a.biasprm[1] = a.biasprm[1] * v
        elif f == "pd_gain_all":
            for n in robot.joint_names:
                a = spec.actuator(n)
                a.gainprm[0] = a.gainprm[0] * v
                a.biasprm[1] = a.biasprm[1] * v
        elif f == "torque_constant":
            a = spec.actuator(t.target)
            a.gainprm[0] = a.gainprm[0] * v
            a.biasprm[1] = a.biasprm[1] * v
            a.biasprm[2] = a.biasprm[2] * v
        elif f == "torque_limit":
            for n in robot.joint_names:
                spec.actuator(n).forcerange = [-eff[n] * v, eff[n] * v]
        elif f == "link_mass":
            b = spec.body(t.target)
            b.mass = b.mass * v
            b.fullinertia = [x * v for x in b.fullinertia]
        elif f == "backlash":
            spec.joint(t.target + "__play").range = [-v / 2, v / 2]
        elif f == "joint_compliance":
            k_max = spring_stiffness_max(fixed_base, physics_dt, robot.name)[t.target]
            spec.joint(t.target + "__spring").stiffness = [min(1.0 / max(v, 1e-12), k_max), 0.0, 0.0]
        elif f == "parallel_spring":  # -k q about the zero angle: joint stiffness, springref 0 (combined
            j = spec.joint(t.target)      # with any spring the joint had: (s + k) about s r / (s + k))
            s0, r0 = float(j.stiffness[0]), float(j.springref)
            j.springref = s0 * r0 / (s0 + v) if s0 + v > 0 else r0
            j.stiffness = [s0 + v, *list(j.stiffness)[1:]]
        elif f == "sensor_bias":
            spec.add_numeric(name=f"sensor_bias:{t.target}", data=[v])
        elif f == "foot_friction":
            for g in spec.geoms:
                g.friction = [v, g.friction[1], g.friction[2]]
        elif f == "ground_compliance":
            for g in spec.geoms:
                g.solref = [v, g.solref[1]]
    spec.compile()
    return spec.to_xml()


def _plots(rep: dict, logs, out_dir: str) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sysid.replay import Window, predict

    written = []

    def save(fig, name: str, dpi: int) -> None:
        fig.tight_layout()
        path = os.path.join(out_dir, name)
        fig.savefig(path, dpi=dpi)
        plt.close(fig)
        written.append(path)
    model = rep.get("_model_terms", {})
    names = list(rep["residual"]["per_joint_rms_before"])
    held = [lg for lg in logs if lg.name in rep["split"]["heldout"]] or logs[-1:]
    lg = held[0]
    w = Window(logs.index(lg), 0, len(lg))
    if lg.fixed_base:
        y = predict(logs, [w], [rep.get("_base_terms", {}), model])[0]
    else:
        y = None
    # per-joint RMS before/after
    fig, ax = plt.subplots(figsize=(12, 4))
    x = np.arange(len(names))
    ax.bar(x - 0.2, [1000 * rep["residual"]["per_joint_rms_before"][n] for n in names], 0.4, label="sim before")
    ax.bar(x + 0.2, [1000 * rep["residual"]["per_joint_rms_after"][n] for n in names], 0.4, label="identified model")
    ax.axhline(1000 * rep["noise_floor"], color="k", ls="--", lw=1, label="noise floor")
    ax.set_xticks(x, names, rotation=70, fontsize=7)
    ax.set_ylabel("held-out RMS [mrad]")
    ax.set_yscale("log")
    ax.legend()
    save(fig, "residual_by_joint.png", 110)
    if y is not None:
        before = rep["residual"]["per_joint_rms_before"]
        top = sorted(range(len(names)), key=lambda j: -before[names[j]])[:4]
        fig, axes = plt.subplots(len(top), 2, figsize=(13, 2.4 * len(top)), squeeze=False)
        for r, j in enumerate(top):
            a, b = axes[r]
            a.plot(lg.t, lg.q[:, j], "k", lw=0.8, label="measured")
            a.plot(lg.t, y[0, :, j], "C0", lw=0.8, label="sim before")
            a.plot(lg.t, y[1, :, j], "C1--", lw=0.8, label="identified")
            a.set_ylabel(f"{names[j]} [rad]", fontsize=8)
            b.plot(lg.t, 1000 * (lg.q[:, j] - y[0, :, j]), "C0", lw=0.6, label="residual before")
            b.plot(lg.t, 1000 * (lg.q[:, j] - y[1, :, j]), "C1", lw=0.6, label="residual after")
            b.set_ylabel("mrad", fontsize=8)
            if r == 0:
                a.legend(fontsize=7)
                b.legend(fontsize=7)
        axes[-1, 0].set_xlabel(f"t [s] (held-out log {lg.name})")
        axes[-1, 1].set_xlabel("t [s]")
        save(fig, "overlay.png", 100)
        hyst = [t.target for t in model if t.family in ("backlash", "coulomb_friction")]
        if hyst:
            fig, axes = plt.subplots(1, len(hyst[:4]), figsize=(4.2 * len(hyst[:4]), 3.8), squeeze=False)
            for a, jn in zip(axes[0], hyst[:4]):
                j = names.index(jn)
                a.plot(lg.cmd[:, j], lg.q[:, j] - lg.cmd[:, j], "k.", ms=1.5, label="measured")
                a.plot(lg.cmd[:, j], y[0, :, j] - lg.cmd[:, j], "C0.", ms=1.0, label="sim before")
                a.plot(lg.cmd[:, j], y[1, :, j] - lg.cmd[:, j], "C1.", ms=1.0, label="identified")
                a.set_xlabel(f"command {jn} [rad]")
                a.set_ylabel("output - command [rad]")
                a.legend(fontsize=7)
            save(fig, "hysteresis.png", 100)
    ph_b = {k: v for k, v in rep["localisation"]["phases"].items() if isinstance(v, dict)}
    ph_a = {k: v for k, v in rep["residual"]["phases_after"].items() if isinstance(v, dict)}
    if ph_b:
        fig, ax = plt.subplots(figsize=(7, 3.5))
        keys = list(ph_b)
        x = np.arange(len(keys))
        ax.bar(x - 0.2, [ph_b[k]["energy"] for k in keys], 0.4, label="sim before")
        ax.bar(x + 0.2, [ph_a.get(k, {"energy": np.nan})["energy"] for k in keys], 0.4, label="identified model")
        ax.axhline(1.0, color="k", ls="--", lw=1, label="noise floor")
        ax.set_xticks(x, keys, fontsize=8)
        ax.set_ylabel("residual energy / floor²")
        ax.set_yscale("log")
        ax.legend(fontsize=8)
        save(fig, "residual_by_phase.png", 100)
    rough = rep.get("terrain_roughness")
    if rough:  # the distribution fit: simulated excess vs RMS height, and what the logs show
        fig, ax = plt.subplots(figsize=(6, 3.8))
        g = 1000 * np.asarray(rough["grid"])
        ax.plot(g, rough["excess"], "C0o-", label="logs simulated on random surfaces")
        ax.axhline(rough["excess_obs"], color="k", ls="--", lw=1, label="recordings (all logs)")
        ax.axvline(1000 * rough["rms_height"], color="C1", lw=1.2, label=f"fitted {1000 * rough['rms_height']:.2f} mm")
        ax.axvspan(1000 * rough["ci95"][0], 1000 * rough["ci95"][1], color="C1", alpha=0.15, label="95 % CI")
        ax.set_xlabel("RMS height of the ground surface, Sq [mm]")
        ax.set_ylabel("excess residual per window [floor²]")
        ax.set_title("uneven ground: " + ("declared" if rough["declared"] else "rejected"), fontsize=9)
        ax.legend(fontsize=7)
        save(fig, "terrain_roughness.png", 100)
    return written


def write_report(rep: dict, logs, out_dir: str, plots: bool = True) -> dict:
    """Write report.json, report.txt, plots and identified_model.xml into ``out_dir``.

    Returns:
        dict name -> path of what was written.
    """
    os.makedirs(out_dir, exist_ok=True)
    paths = {}
    text = format_report(rep)
    p = os.path.join(out_dir, "report.txt")
    atomic_write_text(p, text + "\n")
    paths["text"] = p
    xml = export_mjcf(rep.get("_model_terms", {}), rep["fixed_base"], logs[0].physics_dt, logs[0].robot_name)
    p = os.path.join(out_dir, "identified_model.xml")
    atomic_write_text(p, xml)
    paths["mjcf"] = p
    if plots:
        paths["plots"] = _plots(rep, logs, out_dir)
    rep = dict(rep)
    rep["files"] = paths
    p = os.path.join(out_dir, "report.json")
    atomic_write_text(p, json.dumps(public_json(rep), indent=1, allow_nan=False))
    paths["json"] = p
    return paths


def terms_from_labels(model: dict) -> dict:
    """Inverse of ``report["model"]``: {"family[target]": value} -> {Term: value}."""
    from sysid.candidates import FAMILIES

    out = {}
    for lbl, v in model.items():
        f, tg = (lbl[:-1].split("[", 1)) if "[" in lbl else (lbl, None)
        if f not in FAMILIES:
            raise ValueError(f"unknown effect family {f!r} in a report model")
        out[Term(f, tg)] = float(v)
    return out
