"""The strangers' setting of the blind benchmark: hidden effects from a world written apart from the
diagnosis's candidate library (``benchmarks.strangers``), and what counts as naming them right.

The strangers' world (:func:`benchmarks.strangers.world.make_world`) injects each kind of its table
(:data:`benchmarks.strangers.effects.KINDS`) in a physical form of its own; only its API and its table
(names, ranges, physical descriptions) are used here. :data:`KIND_FAMILIES` maps each kind to the
diagnosis families that name the same physics; a kind is *named right* when the report names one of
them (a finding) at a true target, or lists an equivalence class that contains one of them there
(with the segment that would separate it: ``report["equivalent"]``). A *confident wrong Found* is a
finding that is no true effect (another family at a true target, or any family elsewhere).

:func:`truth_values` turns a hidden effect into the values of those families (the headline value and
the other parameters the family carries: a back-EMF limit's slope effort / no-load speed, a Stribeck
friction's static excess (stiction ratio - 1) x Coulomb, a centre-of-mass shift's three axes), which
the parameter errors and the 95 % interval coverage are scored on.
"""

from __future__ import annotations

import numpy as np

#: Stranger kind -> the diagnosis families that name it (the first is its own form).
KIND_FAMILIES = {
    "servo_gain": ("torque_constant",),
    "kp_error": ("pd_gain",),
    "kd_error": ("kd_gain",),
    "backlash_motor": ("backlash_motor",),
    "backlash_link": ("backlash_link",),
    "torque_saturation": ("joint_torque_limit", "torque_limit"),
    "torque_speed": ("back_emf",),
    "friction_coulomb_viscous": ("coulomb_friction", "viscous_damping"),
    "friction_stribeck": ("stribeck_friction", "coulomb_friction"),
    "encoder_offset": ("encoder_offset",),
    "readout_offset": ("sensor_bias",),
    "com_offset": ("link_com",),
    "inertia_scale": ("link_inertia",),
    "torso_mass": ("link_mass",),
    "torso_com": ("link_com",),
    "latency_lowpass": ("command_lowpass", "latency"),
    "foot_friction": ("foot_friction",),
    "uneven_ground": ("terrain_roughness",),
}
#: Kinds whose second family alone is not their form (Stribeck friction named as plain Coulomb friction,
#: a delay behind a low-pass named as the delay alone): such a report is counted as *partly right*
#: beside the named-right rate, not in it.
PARTIAL = {"friction_stribeck": ("coulomb_friction",), "latency_lowpass": ("latency",)}
#: Families that are a part of a kind's form but do not name it alone: the viscous term of the strangers'
#: Stribeck friction (its ``viscous`` parameter, drawn in every trial) and the spring of the gear contact
#: of the strangers' motor-side play (stiffness ``CONTACT_STIFFNESS_RATIO`` x kp in series with the play,
#: :func:`benchmarks.strangers.effects.contact_parameters`: a series joint compliance of 1 / kc when
#: engaged; the Nordin-Gutman dead-zone model; the link-side play has rigid teeth). A finding of one at
#: the kind's place is no wrong Found; it does not make the kind named right either.
COMPONENTS = {"friction_stribeck": ("viscous_damping",), "backlash_motor": ("joint_compliance",)}


def kinds(fixed_base: bool) -> list[str]:
    """The stranger kinds a trial can draw for a fixed or floating base, plus ``"none"``."""
    from benchmarks.strangers.effects import FIXED_BASE_KINDS, FLOATING_ONLY_KINDS

    if fixed_base:
        return ["none"] + list(FIXED_BASE_KINDS)
    return ["none"] + list(FLOATING_ONLY_KINDS) + ["latency_lowpass", "servo_gain"]


def draw_trial(s: int, kind: str, seed0: int, robot) -> tuple[int, list[dict]]:
    """The trial's seed and hidden effects: none for ``"none"``, else one effect of ``kind``
    (:func:`benchmarks.strangers.effects.draw_effect`). The seed depends only on (``seed0``, ``s``, the
    kind's name), so adding kinds leaves earlier trials' draws unchanged."""
    import zlib

    from benchmarks.strangers.effects import draw_effect

    seed = int(np.random.SeedSequence([seed0, s, zlib.crc32(kind.encode()), 7]).generate_state(1)[0])
    if kind == "none":
        return seed, []
    return seed, [draw_effect(kind, np.random.default_rng(seed), robot)]


def truth_values(e: dict, robot) -> list[tuple[str, str | None, float]]:
    """(family, target, value) the diagnosis would report for hidden stranger effect ``e``, in the family's
    units: one entry per target of the headline family, and one per other family the kind carries
    (Stribeck's Coulomb level beside its static excess, the delay of a low-pass with one, a
    centre-of-mass shift per axis, the gear contact's compliance 1 / kc [rad/(N m)] beside a motor-side
    play). Targets: a joint, ``LINK:AXIS`` for a centre-of-mass axis, the root link, or None (global)."""
    from benchmarks.strangers.effects import contact_parameters

    k = e["kind"] if "kind" in e else e["family"]
    params = e.get("params") or [{} for _ in e["targets"]]
    out = []
    eff = dict(zip(robot.joint_names, robot.effort))
    for tg, v, p in zip(e["targets"], e["values"], params):
        v = float(v)
        if k == "servo_gain":
            out.append(("torque_constant", tg, v))
        elif k == "kp_error":
            out.append(("pd_gain", tg, v))
        elif k == "kd_error":
            out.append(("kd_gain", tg, v))
        elif k in ("backlash_motor", "backlash_link"):
            out.append((k, tg, v))
            if k == "backlash_motor":
                out.append(("joint_compliance", tg, 1.0 / contact_parameters(robot, tg)[0]))
        elif k == "torque_saturation":
            out.append(("joint_torque_limit", tg, v))
        elif k == "torque_speed":
            out.append(("back_emf", tg, float(eff[tg]) / v))
        elif k == "friction_coulomb_viscous":
            out.append(("coulomb_friction", tg, v))
            if p.get("viscous"):
                out.append(("viscous_damping", tg, float(p["viscous"])))
        elif k == "friction_stribeck":
            out.append(("stribeck_friction", tg, (float(p.get("stiction_ratio", 1.5)) - 1.0) * v))
            out.append(("coulomb_friction", tg, v))
            if p.get("viscous"):
                out.append(("viscous_damping", tg, float(p["viscous"])))
        elif k == "encoder_offset":
            out.append(("encoder_offset", tg, v))
        elif k == "readout_offset":
            out.append(("sensor_bias", tg, v))
        elif k in ("com_offset", "torso_com"):
            u = np.asarray(p.get("direction", [1.0, 0.0, 0.0]), dtype=float)
            u = u / max(np.linalg.norm(u), 1e-12)
            for ax, c in zip("xyz", u):
                out.append(("link_com", f"{tg}:{ax}", v * float(c)))
        elif k == "inertia_scale":
            out.append(("link_inertia", tg, v))
        elif k == "torso_mass":
            out.append(("link_mass", tg, v))
        elif k == "latency_lowpass":
            out.append(("command_lowpass", None, v))
            if p.get("delay"):
                out.append(("latency", None, float(p["delay"])))
        elif k == "foot_friction":
            out.append(("foot_friction", None, v))
        elif k == "uneven_ground":
            out.append(("terrain_roughness", None, v))
        else:
            raise ValueError(f"unknown stranger kind {k!r}")
    return out


def _place(x: dict) -> set:
    """The joints and links a report entry is at (a centre-of-mass axis: its link)."""
    return set(x.get("joints") or []) | set(x.get("links") or [])


def _truth_places(e: dict) -> set:
    return {tg for tg in e["targets"] if tg is not None}


def _at(x: dict, e: dict) -> bool:
    """Whether report entry ``x`` is at hidden effect ``e``'s place (global effects: anywhere global)."""
    places = _truth_places(e)
    if not places:
        return not x.get("links") and (len(x.get("joints") or []) != 1)
    return bool(_place(x) & places)


def _term_value(x: dict, fam: str, tg) -> tuple[float, list] | None:
    """(value, ci95) of family ``fam`` at target ``tg`` in report entry ``x`` (a finding), or None."""
    if x["family"] != fam:
        return None
    if fam == "link_com":
        lbl = f"link_com[{tg}]"
        if x.get("term_label") != lbl:
            return None
    elif tg is not None and tg not in _place(x):
        return None
    return float(x["value"]), x.get("ci95") or [None, None]


def score(truth: list[dict], report: dict, robot) -> dict:
    """One strangers' trial against its report (module docstring).

    Returns:
        ``named_right`` (every hidden effect named right: a finding of one of its families at a true
        place, or an equivalence entry there whose candidates include one, or a finding there that
        lists one as a nested excess it could not exclude: ``not_excluded``), ``by_class`` (named right
        through an equivalence entry only), ``partly_right`` (named only by a partial family,
        :data:`PARTIAL`), ``wrong_found`` (findings that are no true effect, as ``family[place]``),
        ``wrong_at_truth`` (those at a true place), ``found``, ``equivalent`` (the report's families),
        ``ci_cover`` (per true value of a right finding: its 95 % interval holds it), ``param_err``
        ([{family, rel}] |v̂ - v| / |v - nominal|), ``detectable``, ``runtime_s``, RMS over floor before/after.
    """
    from sysid.candidates import FAMILIES

    from .scorer import detectable

    eff = report["effects"]
    eq = report.get("equivalent", [])
    named, by_class, partly = [], [], []
    right_entries = set()
    for e in truth:
        k = e["family"]
        fams = KIND_FAMILIES[k]
        part = PARTIAL.get(k, ())
        full = [f for f in fams if f not in part]
        hit_f = [i for i, x in enumerate(eff) if x["family"] in full and _at(x, e)]
        hit_c = [x for x in eq if _at(x, e) and any(c["family"] in full for c in x["candidates"])]
        # a finding that lists the kind's family as a nested excess it could not exclude, with the segment
        # that would show it (a Coulomb friction with a Stribeck excess not excluded), names its class too
        hit_c += [x for x in eff if _at(x, e) and any(n["family"] in full for n in x.get("not_excluded", ()))]
        hit_p = [i for i, x in enumerate(eff) if x["family"] in part and _at(x, e)]
        named.append(bool(hit_f or hit_c))
        by_class.append(bool(hit_c and not hit_f))
        partly.append(bool(not hit_f and not hit_c and hit_p))
        right_entries.update(i for i, x in enumerate(eff)
                             if x["family"] in fams + COMPONENTS.get(k, ()) and _at(x, e))
    wrong_entries = [x for i, x in enumerate(eff) if i not in right_entries]

    def label(x):
        return f"{x['family']}[{','.join(sorted(_place(x))) if len(_place(x)) < 4 else 'all'}]"
    wrong = [label(x) for x in wrong_entries]
    wrong_at = [label(x) for x in wrong_entries if any(_at(x, e) for e in truth)]
    cover, perr = [], []
    for e in truth:
        for fam, tg, v in truth_values(e, robot):
            for x in eff:
                tv = _term_value(x, fam, tg)
                if tv is None:
                    continue
                val, (lo, hi) = tv
                cover.append(bool(lo is not None and hi is not None and lo <= v <= hi))
                nom = FAMILIES[fam].nominal
                perr.append({"family": fam, "rel": abs(val - v) / max(abs(v - nom), 1e-12)})
                break
    fl = report["noise_floor"]
    return {"named_right": bool(truth) and all(named), "by_class": any(by_class) and all(named),
            "partly_right": any(partly), "wrong_found": wrong, "wrong_at_truth": wrong_at,
            "found": sorted({x["family"] for x in eff}),
            "equivalent": [sorted(c["family"] for c in x["candidates"]) for x in eq],
            "ci_cover": cover, "param_err": perr, "detectable": detectable(report),
            "rms_before_over_floor": report["heldout_rms_before"] / fl,
            "rms_after_over_floor": report["heldout_rms_after"] / fl, "runtime_s": report["runtime_s"],
            "rollouts": report.get("rollouts")}


def _frac(k: int, n: int) -> dict:
    return {"k": int(k), "n": int(n), "rate": (k / n) if n else None}


def metrics(rows: list[dict]) -> dict:
    """Headline figures of scored strangers' trials against the diagnosis targets: ``named_right``
    (detectable effect trials), ``wrong_found`` (effect trials with a confident wrong finding),
    ``none_fp`` (clean trials with any finding or equivalence entry), ``coverage``, ``param_err_median``,
    ``runtime_s`` (median), ``per_kind``."""
    eff = [r for r in rows if r["truth_class"] != "none"]
    det = [r for r in eff if r["score"]["detectable"]]
    none = [r for r in rows if r["truth_class"] == "none"]
    cov = [c for r in rows for c in r["score"]["ci_cover"]]
    rel = [p["rel"] for r in rows for p in r["score"]["param_err"]]
    return {
        "trials": len(rows),
        "named_right_detectable": _frac(sum(r["score"]["named_right"] for r in det), len(det)),
        "named_by_class": _frac(sum(r["score"]["by_class"] for r in det), len(det)),
        "partly_right": _frac(sum(r["score"]["partly_right"] for r in det), len(det)),
        "detectable": _frac(len(det), len(eff)),
        "wrong_found": _frac(sum(bool(r["score"]["wrong_found"]) for r in eff), len(eff)),
        "wrong_at_truth": _frac(sum(bool(r["score"]["wrong_at_truth"]) for r in eff), len(eff)),
        "none_fp": _frac(sum(bool(r["score"]["found"] or r["score"]["equivalent"]) for r in none), len(none)),
        "coverage": _frac(sum(cov), len(cov)),
        "param_err_median": float(np.median(rel)) if rel else None,
        "runtime_s": float(np.median([r["score"]["runtime_s"] for r in rows])) if rows else None,
        "per_kind": {k: {"named_right": _frac(sum(r["score"]["named_right"] for r in rs if r["score"]["detectable"]),
                                              sum(r["score"]["detectable"] for r in rs)),
                         "trials": len(rs), "wrong_found": _frac(sum(bool(r["score"]["wrong_found"]) for r in rs),
                                                                 len(rs))}
                     for k in sorted({r["truth_class"] for r in rows})
                     for rs in [[r for r in rows if r["truth_class"] == k]]},
    }


def summarize(rows: list[dict], fixed_base: bool, noise_mrad: float) -> str:
    """Markdown summary of strangers' trials: the headline figures and one row per trial."""
    m = metrics(rows)

    def pct(f):
        return "-" if f["rate"] is None else f"{f['k']}/{f['n']} ({100 * f['rate']:.0f} %)"

    L = [f"## sysid blind benchmark, the strangers' world ({'fixed' if fixed_base else 'floating'} base, "
         f"encoder noise {noise_mrad:g} mrad)", "",
         f"- detectable effects named right (family, or a class containing it): {pct(m['named_right_detectable'])}"
         f" (through a class: {pct(m['named_by_class'])}; partly right: {pct(m['partly_right'])})",
         f"- effect trials with a confident wrong Found: {pct(m['wrong_found'])} (at the truth's place: "
         f"{pct(m['wrong_at_truth'])})",
         f"- clean trials with anything named: {pct(m['none_fp'])}",
         f"- 95 % interval coverage of right findings: {pct(m['coverage'])}; median parameter error "
         f"{m['param_err_median'] if m['param_err_median'] is None else round(100 * m['param_err_median'], 1)} %",
         f"- median runtime {m['runtime_s']:.1f} s" if m["runtime_s"] is not None else "", "",
         "| kind | trials | named right (detectable) | wrong Found |", "|---|---|---|---|"]
    for k, v in m["per_kind"].items():
        L.append(f"| {k} | {v['trials']} | {pct(v['named_right'])} | {pct(v['wrong_found'])} |")
    L += ["", "| trial | truth | found | classes | right | wrong | det | after/floor | s |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        s = r["score"]
        tr = "; ".join(f"{e['family']}[{','.join(str(t) for t in e['targets'])}] "
                       f"{','.join(f'{v:.3g}' for v in e['values'])}" for e in r["truth"]) or "none"
        L.append(f"| {r['trial']} | {tr} | {', '.join(s['found']) or '-'} | "
                 f"{'; '.join('/'.join(c) for c in s['equivalent']) or '-'} | {s['named_right']} | "
                 f"{', '.join(s['wrong_found']) or '-'} | {s['detectable']} | {s['rms_after_over_floor']:.2f} | "
                 f"{s['runtime_s']:.0f} |")
    return "\n".join(L) + "\n"


#: The project's own referee class (``benchmarks/blind/families.py``) of each stranger kind's family, where
#: the project's benchmark injects that family (in its own form); None where it has no such class.
OWN_CLASS = {"servo_gain": "torque_constant", "kp_error": "pd_gain", "kd_error": None, "backlash_motor": "backlash",
             "backlash_link": "backlash", "torque_saturation": "torque_limit", "torque_speed": None,
             "friction_coulomb_viscous": "coulomb_friction", "friction_stribeck": None, "encoder_offset": None,
             "readout_offset": "sensor_bias", "com_offset": "link_mass", "inertia_scale": None, "torso_mass": None,
             "torso_com": None, "latency_lowpass": "latency", "foot_friction": "foot_friction",
             "uneven_ground": "terrain_roughness"}


def comparison(stranger_rows: list[dict], own_rows: list[dict]) -> str:
    """Markdown table, one row per stranger kind: its library family, detectable trials named right on
    the strangers' world, and, beside it, the project's own blind benchmark on the class that injects
    that family in the project's own form (:data:`OWN_CLASS`; named right = a finding of the family
    or an equivalence entry holding it, ``benchmarks/blind/scorer.py``)."""
    def cell(rows, key):
        det = [r for r in rows if r["score"]["detectable"]]
        k = sum(bool(r["score"].get(key)) for r in det)
        return f"{k}/{len(det)}" if det else "-"

    L = ["| stranger kind (form) | library family | strangers: named right | strangers: wrong Found | "
         "project's class | project: named right |", "|---|---|---|---|---|---|"]
    for kind in sorted({r["truth_class"] for r in stranger_rows} - {"none"}):
        rs = [r for r in stranger_rows if r["truth_class"] == kind]
        own = OWN_CLASS.get(kind)
        os_ = [r for r in own_rows if r.get("truth_class") == own] if own else []
        wrong = sum(bool(r["score"]["wrong_found"]) for r in rs)
        L.append(f"| {kind} | {', '.join(KIND_FAMILIES[kind])} | {cell(rs, 'named_right')} | {wrong}/{len(rs)} | "
                 f"{own or '-'} | {cell(os_, 'named_right') if own else '-'} |")
    return "\n".join(L) + "\n"
