"""The scorer of the blind benchmark: one ``sgatwalk diagnose`` report against the hidden truth.

:func:`score` gives a trial's top-1 family (the effect whose removal hurts the held-out fit most;
"none" when no effect is reported), the predicted and true family sets, joint/link localisation
counts (family and target must match; every reported term counts against precision, whatever the
truth, a global one included; terms the report lists as uncertain are not findings), per-term parameter errors |θ̂-θ|/|θ-θ_nominal| of the true terms found
(latency: absolute ms), 95 % CI coverage over every reported term (spurious terms: does the interval
hold the sim's value), the spurious terms, held-out RMS before/after over the noise floor, gap closed,
whether the hidden effects were detectable (:data:`DETECTABLE_RMS`) and runtime.
"""

from __future__ import annotations

import collections
import math

from .families import NOMINAL

#: A hidden effect is *detectable* (its signal is above the noise) when it lifts at least one
#: channel's residual RMS against the plain sim, over the trial's logs before anything is fitted, to
#: sqrt(1.5) x that channel's noise floor: 1.5x the energy, the level at which the tool flags a joint.
#: The diagnosis's top-1 target is on detectable effects; below it no tool can tell an effect
#: from the noise, and "no missing physics" is the right answer.
DETECTABLE_RMS = math.sqrt(1.5)


def detectable(report: dict) -> bool:
    """Whether the effects behind ``report`` are detectable (:data:`DETECTABLE_RMS`): the largest
    per-channel RMS over floor of the report's localisation (measured vs plain sim, all logs)."""
    ch = report["localisation"]["channels"].values()
    return bool(ch) and max(c["rms_over_floor"] for c in ch) >= DETECTABLE_RMS


def _pred_family(report: dict) -> str:
    """Top-1 family of a report: the one whose removal costs the held-out fit most ("none": no effect)."""
    eff = report["effects"]
    if not eff:
        return "none"
    imp = collections.defaultdict(float)
    for e in eff:
        imp[e["family"]] += max(0.0, e.get("heldout_cost_without", 0.0))
    return max(imp, key=imp.get) if imp else eff[0]["family"]


def _target(e: dict):
    """The report effect's target: its link, its joint when it has exactly one, else None."""
    return e["links"][0] if e["links"] else e["joints"][0] if len(e["joints"]) == 1 else None


def _matches(x: dict, e: dict, tg) -> bool:
    """Whether reported effect ``x`` is the truth term (family ``e``, target ``tg``; None: global)."""
    return x["family"] == e["family"] and (tg is None or _target(x) == tg)


def _nominal_covered(x: dict) -> bool:
    """Whether a spurious term's 95 % interval holds the sim's (true) value."""
    lo, hi = x["ci95"]
    nominal = NOMINAL.get(x["family"])
    return bool(nominal is not None and lo is not None and hi is not None and lo <= nominal <= hi)


def score(truth: list[dict], report: dict) -> dict:
    """Per-trial scores (see module docstring).

    Every reported term counts (honest scoring, whatever the truth is): ``loc_pred`` is the number of
    reported terms, ``pred_matched`` how many of them are a true term (family, and the joint or link
    where the truth has one), ``spurious`` the others (with their labels); ``ci_cover`` has one entry
    per reported term (a true term's interval holds the true value, a spurious one's the sim's
    value); ``param_err`` has the true terms found. ``loc_tp`` / ``loc_true``: true terms found / all.
    Terms the report lists as uncertain (``report["uncertain"]``: fitted but not claimed) are not
    findings: they count in neither precision nor the spurious terms, but their intervals count in
    ``ci_cover``; ``uncertain`` / ``uncertain_true``: how many there are / how many are a true term.
    """
    fams_true = {e["family"] for e in truth}
    eff = report["effects"]
    fams_pred = {e["family"] for e in eff}
    out = {"pred_top1": _pred_family(report), "pred_families": sorted(fams_pred),
           "true_families": sorted(fams_true) or ["none"]}
    terms_true = [(e, tg, v) for e in truth for tg, v in zip(e["targets"], e["values"])]
    out["loc_true"] = len(terms_true)
    out["loc_tp"] = sum(any(_matches(x, e, tg) for x in eff) for e, tg, _ in terms_true)
    out["loc_pred"] = len(eff)
    matched = [any(_matches(x, e, tg) for e, tg, _ in terms_true) for x in eff]
    out["pred_matched"] = int(sum(matched))
    out["spurious"] = [f"{x['family']}[{_target(x) or 'all'}]" for x, m in zip(eff, matched) if not m]
    perr, cover = [], []
    for e, tg, v in terms_true:
        match = [x for x in eff if _matches(x, e, tg)]
        if not match:
            continue
        x = match[0]
        if e["family"] == "latency":
            perr.append({"family": "latency", "abs_ms": 1000 * abs(x["value"] - v)})
        else:
            perr.append({"family": e["family"], "rel": abs(x["value"] - v) / abs(v - NOMINAL[e["family"]])})
        lo, hi = x["ci95"]
        cover.append(bool(lo is not None and hi is not None and lo <= v <= hi))
    cover += [_nominal_covered(x) for x, m in zip(eff, matched) if not m]
    # uncertain terms (fitted, not claimed): not findings, but their intervals are claims too
    unc = report.get("uncertain", [])
    n_true = 0
    for x in unc:
        v = next((v for e, tg, v in terms_true if _matches(x, e, tg)), None)
        if v is None:
            cover.append(_nominal_covered(x))
        else:
            n_true += 1
            lo, hi = x["ci95"]
            cover.append(bool(lo is not None and hi is not None and lo <= v <= hi))
    out["uncertain"] = len(unc)
    out["uncertain_true"] = n_true
    out["param_err"] = perr
    out["ci_cover"] = cover
    fl = report["noise_floor"]
    out["rms_before_over_floor"] = report["heldout_rms_before"] / fl
    out["rms_after_over_floor"] = report["heldout_rms_after"] / fl
    out["gap_closed"] = report.get("gap_closed")
    out["detectable"] = detectable(report)
    out["runtime_s"] = report["runtime_s"]
    # named right: every true effect is a finding of its family at a true target, or is among the
    # candidates of an equivalence entry there (the class with the segment that would separate it)
    eq = report.get("equivalent", [])
    named = []
    for e in truth:
        tgs = [tg for tg in e["targets"]]
        hit = any(_matches(x, e, tg) for x in eff for tg in tgs)
        hit_c = any(any(c["family"] == e["family"] for c in x["candidates"]) and
                    (tgs == [None] or _target(x) in tgs) for x in eq)
        named.append(hit or hit_c)
    out["named_right"] = bool(truth) and all(named)
    out["by_class"] = out["named_right"] and any(
        any(c["family"] == e["family"] for x in eq for c in x["candidates"]) for e in truth)
    out["wrong_found"] = list(out["spurious"])  # findings that are no true term
    out["equivalent"] = [sorted(c["family"] for c in x["candidates"]) for x in eq]
    return out
