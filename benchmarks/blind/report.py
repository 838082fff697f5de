"""The markdown report of the blind benchmark (``summary.md``) from scored trial rows.

:func:`summarize` tabulates the single-effect trials (family top-1, false positives on "none",
localisation, parameter error, held-out RMS over the floor, gap closed, CI coverage, runtime, a
per-family table and the confusion matrix) and the two-effect trials (both found, exact set,
precision, one line per trial).
"""

from __future__ import annotations

import numpy as np

from .families import CLASSES, NOISE


def _frac(k: int, n: int) -> dict:
    return {"k": int(k), "n": int(n), "rate": (k / n) if n else None}


def metrics(rows: list[dict]) -> dict:
    """Headline figures of scored trials (what the README shows), against the diagnosis's targets:
    ``top1`` (single-effect trials with an effect; top-1 family), ``none_fp`` (trials on clean logs
    with any term found), ``spurious`` (trials with a reported term that is no true term),
    ``coverage`` (95 % intervals of every reported term holding the truth), ``precision``/``recall``
    (reported terms that are true / true terms found), ``param_err_median`` (non-latency true terms
    found), ``latency_err_ms`` (median), ``both_found`` (two-effect trials), ``runtime_s`` (median),
    ``uncertain`` (terms reported as uncertain / compensating: how many of them are true terms),
    ``per_class`` (single-effect class -> top-1 and median parameter error of its true terms found),
    ``top1_detectable`` (top-1 over the single-effect trials whose effect is detectable:
    :data:`.scorer.DETECTABLE_RMS`), ``named_right_detectable`` (those whose every effect is a finding
    of its family or among the candidates of an equivalence entry at its target), ``wrong_found``
    (effect trials with a finding that is no true term).
    Findings are the report's ``effects``; uncertain terms count only in ``coverage``."""
    single = [r for r in rows if r["kind"] == "single"]
    eff = [r for r in single if r["truth_class"] != "none"]
    det = [r for r in eff if r["score"]["detectable"]]
    none = [r for r in single if r["truth_class"] == "none"]
    two = [r for r in rows if r["kind"] == "two"]
    sc = [r["score"] for r in rows]
    cov = [c for s in sc for c in s["ci_cover"]]
    rel = [p["rel"] for s in sc for p in s["param_err"] if "rel" in p]
    lat = [p["abs_ms"] for s in sc for p in s["param_err"] if "abs_ms" in p]
    return {
        "trials": len(rows), "single": len(single), "two": len(two),
        "top1": _frac(sum(r["score"]["pred_top1"] == r["truth_class"] for r in eff), len(eff)),
        "top1_detectable": _frac(sum(r["score"]["pred_top1"] == r["truth_class"] for r in det), len(det)),
        "named_right_detectable": _frac(sum(bool(r["score"].get("named_right")) for r in det), len(det)),
        "wrong_found": _frac(sum(bool(r["score"].get("wrong_found")) for r in eff), len(eff)),
        "none_fp": _frac(sum(bool(r["score"]["pred_families"]) for r in none), len(none)),
        "spurious": _frac(sum(bool(s.get("spurious")) for s in sc), len(sc)),
        "coverage": _frac(sum(cov), len(cov)),
        "precision": _frac(sum(s.get("pred_matched", s["loc_tp"]) for s in sc), sum(s["loc_pred"] for s in sc)),
        "recall": _frac(sum(s["loc_tp"] for s in sc), sum(s["loc_true"] for s in sc)),
        "param_err_median": float(np.median(rel)) if rel else None,
        "latency_err_ms": float(np.median(lat)) if lat else None,
        "both_found": _frac(sum(set(r["score"]["true_families"]) <= set(r["score"]["pred_families"]) for r in two),
                            len(two)),
        "runtime_s": float(np.median([s["runtime_s"] for s in sc])) if sc else None,
        "uncertain": _frac(sum(s.get("uncertain_true", 0) for s in sc), sum(s.get("uncertain", 0) for s in sc)),
        "per_class": {c: {"top1": _frac(sum(r["score"]["pred_top1"] == c for r in rs), len(rs)),
                          "named_right": _frac(sum(bool(r["score"].get("named_right")) for r in rs
                                                   if r["score"]["detectable"]),
                                               sum(bool(r["score"]["detectable"]) for r in rs)),
                          "param_err_median": (float(np.median(pe)) if (pe := [p["rel"] for r in rs
                                                                              for p in r["score"]["param_err"]
                                                                              if "rel" in p]) else None)}
                      for c in sorted({r["truth_class"] for r in single})
                      for rs in [[r for r in single if r["truth_class"] == c]]},
    }


def summarize(rows: list[dict], world: str, classes=None, noise_mrad: float | None = None) -> str:
    """Markdown tables of the benchmark results; ``noise_mrad``: the trial logs' encoder noise
    (default: the benchmark's 1 mrad)."""
    single = [r for r in rows if r["kind"] == "single"]
    two = [r for r in rows if r["kind"] == "two"]
    L = [f"## sysid blind benchmark, world = {world} ({'MuJoCo sim-as-real' if world == 'sim' else 'PyBullet real'})", ""]
    if single:
        seeds = sorted({r["seed"] for r in single})
        classes = classes or CLASSES[world]
        L.append(f"Single-effect trials: {len(single)} ({len(classes)} classes x {len(seeds)} seeds: {seeds}); "
                 f"{single[0]['n_logs']} logs x {single[0]['seconds']:g} s per trial "
                 f"(train {single[0]['n_logs'] - 1}, held out 1), encoder noise {1000 * NOISE if noise_mrad is None else noise_mrad:g} mrad.")
        L.append("")
        top1 = np.mean([r["score"]["pred_top1"] == r["truth_class"] for r in single])
        none = [r for r in single if r["truth_class"] == "none"]
        fp = np.mean([bool(r["score"]["pred_families"]) for r in none]) if none else float("nan")
        tp = sum(r["score"]["loc_tp"] for r in single)
        nt = sum(r["score"]["loc_true"] for r in single)
        npred = sum(r["score"]["loc_pred"] for r in single)
        pm = sum(r["score"].get("pred_matched", r["score"]["loc_tp"]) for r in single)
        spur = [r for r in single if r["score"].get("spurious")]
        eff = [r for r in single if r["truth_class"] != "none"]
        after = [r["score"]["rms_after_over_floor"] for r in eff]
        gc = [r["score"]["gap_closed"] for r in eff if r["score"]["gap_closed"] is not None]
        cov = [c for r in single for c in r["score"]["ci_cover"]]  # "none" trials: their spurious terms
        L.append("| metric | value |")
        L.append("|---|---|")
        L.append(f"| family top-1 | {top1:.0%} ({sum(r['score']['pred_top1'] == r['truth_class'] for r in single)}/{len(single)}) |")
        L.append(f"| false positives on none | {fp:.0%} ({sum(bool(r['score']['pred_families']) for r in none)}/{len(none)}) |")
        L.append(f"| localisation precision / recall (family+joint/link; every reported term) | {pm / max(npred, 1):.2f} / {tp / max(nt, 1):.2f} ({pm}/{npred}, {tp}/{nt}) |")
        L.append(f"| trials with a spurious term | {len(spur) / len(single):.0%} ({len(spur)}/{len(single)}) |")
        rel = [p["rel"] for r in eff for p in r["score"]["param_err"] if "rel" in p]
        lat = [p["abs_ms"] for r in eff for p in r["score"]["param_err"] if "abs_ms" in p]
        L.append(f"| median parameter error (non-latency terms found) | {np.median(rel):.1%} over {len(rel)} terms |" if rel else "| median parameter error | - |")
        L.append(f"| latency error (median / max) | {np.median(lat):.2f} / {np.max(lat):.2f} ms over {len(lat)} |" if lat else "| latency error | - |")
        if eff:
            L.append(f"| held-out RMS after / noise floor (median, max) | {np.median(after):.2f}, {np.max(after):.2f} |")
            L.append(f"| held-out RMS before / floor (median) | {np.median([r['score']['rms_before_over_floor'] for r in eff]):.2f} |")
        L.append(f"| gap closed (median, min) | {np.median(gc):.1%}, {np.min(gc):.1%} |" if gc else "| gap closed | - |")
        L.append(f"| 95 % CI coverage (every reported term) | {np.mean(cov):.0%} ({sum(cov)}/{len(cov)}) |" if cov else "| 95 % CI coverage | - |")
        L.append(f"| diagnose runtime (median, max) | {np.median([r['score']['runtime_s'] for r in single]):.1f} s, {np.max([r['score']['runtime_s'] for r in single]):.1f} s |")
        L.append("")
        L.append("Per family: top-1, median parameter error, after/floor")
        L.append("")
        L.append("| truth | n | top-1 | param err (median) | RMS after/floor (max) |")
        L.append("|---|---|---|---|---|")
        for c in classes:
            rr = [r for r in single if r["truth_class"] == c]
            if not rr:
                continue
            pe = [p.get("rel", p.get("abs_ms")) for r in rr for p in r["score"]["param_err"]]
            unit = " ms" if c == "latency" else ""
            pes = (f"{np.median(pe):.2f}{unit}" if c == "latency" else f"{np.median(pe):.1%}") if pe else "-"
            L.append(f"| {c} | {len(rr)} | {sum(r['score']['pred_top1'] == c for r in rr)}/{len(rr)} | {pes} | "
                     f"{max(r['score']['rms_after_over_floor'] for r in rr):.2f} |")
        L.append("")
        L.append("Confusion matrix (rows truth, columns top-1 prediction)")
        L.append("")
        preds = classes + sorted({r["score"]["pred_top1"] for r in single} - set(classes))
        L.append("| truth \\ pred | " + " | ".join(p[:10] for p in preds) + " |")
        L.append("|---" * (len(preds) + 1) + "|")
        for c in classes:
            rr = [r for r in single if r["truth_class"] == c]
            L.append(f"| {c} | " + " | ".join(str(sum(r["score"]["pred_top1"] == p for r in rr)) for p in preds) + " |")
        L.append("")
    if two:
        both = [set(r["score"]["true_families"]) <= set(r["score"]["pred_families"]) for r in two]
        exact = [set(r["score"]["true_families"]) == set(r["score"]["pred_families"]) for r in two]
        prec = [len(set(r["score"]["true_families"]) & set(r["score"]["pred_families"])) / max(1, len(r["score"]["pred_families"])) for r in two]
        tp = sum(r["score"]["loc_tp"] for r in two)
        nt = sum(r["score"]["loc_true"] for r in two)
        npred = sum(r["score"]["loc_pred"] for r in two)
        pm = sum(r["score"].get("pred_matched", r["score"]["loc_tp"]) for r in two)
        rel = [p["rel"] for r in two for p in r["score"]["param_err"] if "rel" in p]
        after = [r["score"]["rms_after_over_floor"] for r in two]
        cov = [c for r in two for c in r["score"]["ci_cover"]]
        L.append(f"Two-effect trials: {len(two)} (seeds {sorted({r['seed'] for r in two})})")
        L.append("")
        L.append("| metric | value |")
        L.append("|---|---|")
        L.append(f"| both families found | {np.mean(both):.0%} ({sum(both)}/{len(two)}) |")
        L.append(f"| exact family set | {np.mean(exact):.0%} ({sum(exact)}/{len(two)}) |")
        L.append(f"| family precision (mean) | {np.mean(prec):.2f} |")
        L.append(f"| localisation precision / recall (every reported term) | {pm / max(npred, 1):.2f} / {tp / max(nt, 1):.2f} |")
        L.append(f"| median parameter error (non-latency) | {np.median(rel):.1%} |" if rel else "| median parameter error | - |")
        L.append(f"| held-out RMS after / floor (median, max) | {np.median(after):.2f}, {np.max(after):.2f} |")
        L.append(f"| 95 % CI coverage | {np.mean(cov):.0%} ({sum(cov)}/{len(cov)}) |" if cov else "| 95 % CI coverage | - |")
        L.append(f"| diagnose runtime (median) | {np.median([r['score']['runtime_s'] for r in two]):.1f} s |")
        L.append("")
        L.append("| trial | truth | found | RMS after/floor |")
        L.append("|---|---|---|---|")
        for r in two:
            tr = "; ".join(f"{e['family']}" + (f"[{','.join(str(t) for t in e['targets'])}]" if e["targets"][0] else "")
                           + " " + ",".join(f"{v:.4g}" for v in e["values"]) for e in r["truth"])
            fd = "; ".join(f"{k}" for k in r["report_model"]) or "none"
            L.append(f"| {r['trial']} | {tr} | {fd} | {r['score']['rms_after_over_floor']:.2f} |")
    return "\n".join(L) + "\n"
