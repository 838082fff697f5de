"""The scorer of the blind benchmark: one ``sgatwalk diagnose`` report against the hidden truth.

:func:`score` gives a trial's top-1 family (the effect whose removal hurts the held-out fit most;
"none" when no effect is reported), the predicted and true family sets, joint/link localisation
counts (family and target must match), per-term parameter errors |θ̂-θ|/|θ-θ_nominal| (latency:
absolute ms), 95 % CI coverage, held-out RMS before/after over the noise floor, gap closed and
runtime.
"""

from __future__ import annotations

import collections

from .families import NOMINAL


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


def score(truth: list[dict], report: dict) -> dict:
    """Per-trial scores (see module docstring)."""
    fams_true = {e["family"] for e in truth}
    eff = report["effects"]
    fams_pred = {e["family"] for e in eff}
    out = {"pred_top1": _pred_family(report), "pred_families": sorted(fams_pred),
           "true_families": sorted(fams_true) or ["none"]}
    local_true = {(e["family"], t) for e in truth for t in e["targets"] if t is not None}
    local_pred = {(e["family"], _target(e)) for e in eff if _target(e) is not None}
    out["loc_tp"] = len(local_true & local_pred)
    out["loc_true"] = len(local_true)
    out["loc_pred"] = len(local_pred) if local_true else 0
    perr, cover = [], []
    for e in truth:
        for tg, v in zip(e["targets"], e["values"]):
            match = [x for x in eff if x["family"] == e["family"] and (tg is None or _target(x) == tg)]
            if not match:
                continue
            x = match[0]
            if e["family"] == "latency":
                perr.append({"family": "latency", "abs_ms": 1000 * abs(x["value"] - v)})
            else:
                perr.append({"family": e["family"], "rel": abs(x["value"] - v) / abs(v - NOMINAL[e["family"]])})
            lo, hi = x["ci95"]
            cover.append(bool(lo is not None and hi is not None and lo <= v <= hi))
    out["param_err"] = perr
    out["ci_cover"] = cover
    fl = report["noise_floor"]
    out["rms_before_over_floor"] = report["heldout_rms_before"] / fl
    out["rms_after_over_floor"] = report["heldout_rms_after"] / fl
    out["gap_closed"] = report.get("gap_closed")
    out["runtime_s"] = report["runtime_s"]
    return out
