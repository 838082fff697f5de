"""The outputs of an optimization run a person reads: Table I as text and the CMA-ES progress figure."""

from __future__ import annotations

import numpy as np

from common.files import atomic_path


def format_table(rows: list[dict]) -> str:
    """The paper's Table I: a row per method and grounding step (θ0 first); rows without real trials
    are left out."""
    lines = [f"{'method':24s} {'step':>4s} {'speed [cm/s]':>16s} {'falls':>7s}", "-" * 54]
    for r in rows:
        if not r.get("trials"):
            continue
        name = "θ0" if r["method"] == "theta0" else r["method"].upper()
        step = "-" if r["method"] == "theta0" else str(r["step"])
        lines.append(f"{name:24s} {step:>4s} {r['speed_mean']:8.2f} ± {r['speed_std']:5.2f} "
                     f"{r['falls']:>3d}/{r['trials']:<3d}")
    return "\n".join(lines)


def plot_progress(generations: list[dict], methods, path: str) -> None:
    """CMA-ES progress: the best (solid) and median (dashed) fitness of every generation in the training
    world, grounding steps concatenated per method; written atomically to ``path`` (PNG)."""
    import matplotlib  # lazy: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib

    if not generations:
        return
    methods = list(methods)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    keys = sorted({(g["method"], g["step"]) for g in generations}, key=lambda k: (methods.index(k[0]), k[1]))
    offset: dict = {}
    for m, s in keys:
        rows = [g for g in generations if g["method"] == m and g["step"] == s]
        x0 = offset.get(m, 0)
        x = x0 + np.array([g["gen"] for g in rows])
        line, = ax.plot(x, [g["best"] for g in rows], "-", label=f"{m.upper()} step {s}: best")
        ax.plot(x, [g["median"] for g in rows], "--", color=line.get_color(), alpha=0.6)
        offset[m] = x0 + len(rows)
    ax.set_xlabel("generation (grounding steps concatenated per method; dashed: population median)")
    ax.set_ylabel("fitness in the training world [cm/s, -15 per fall]")
    ax.set_title("CMA-ES progress")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)


__all__ = ["format_table", "plot_progress"]
