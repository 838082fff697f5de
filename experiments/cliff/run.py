"""``sgatwalk cliff``: GAT vs SGAT on Cliff Walking over a sweep of "real" noise (paper Fig. 7).

Reproduces §IV.A of Desai et al., "Stochastic Grounded Action Transformation for Robot Learning
in Simulation" (IROS 2020): for each noise value ``p`` (chance per step that the "real" move
goes in a uniformly random direction) GAT and SGAT ground the deterministic simulator on real
data and re-solve it by policy iteration until the policy stops changing; each resulting
policy, and the policy solved on the true real MDP (the optimum), is evaluated on the real MDP
over ``--episodes`` episodes (paper: 10,000). The algorithm itself lives in
:mod:`sgat.tabular`; this module sweeps, prints, and writes ``cliff.csv``, ``cliff.png``
(style of the paper's Fig. 7, ``fig:grid_plot``) and ``cliff_paths.png`` (style of Fig. 6,
``fig:gridworld_diagram``: the paths the policies take).
"""

from __future__ import annotations

import csv
import io
import time
from pathlib import Path
from typing import Any

import numpy as np

from common.files import atomic_write_bytes as _atomic_write_bytes
from common.parse import parse_values
from experiments.runtime.progress import Reporter
from sgat import tabular as T

#: Columns of ``cliff.csv`` (the first six are the ``--json`` row keys).
CSV_COLUMNS = [
    "noise",
    "gat_return", "gat_se",
    "sgat_return", "sgat_se",
    "optimal_return", "optimal_se",
    "gat_value", "sgat_value", "optimal_value",
    "gat_steps", "sgat_steps",
    "gat_converged", "sgat_converged",
    "gat_real_transitions", "sgat_real_transitions",
    "gat_truncated", "sgat_truncated", "optimal_truncated",
]


def parse_noise(spec: str) -> list[float]:
    """Parse ``--noise``: ``start:stop:count`` (``numpy.linspace``) or a comma list
    (:func:`common.parse.parse_values`).

    Returns:
        the noise values (probabilities), rounded to 12 decimals, in the order given.

    Raises:
        ValueError: for a malformed spec, an empty range, or a value outside [0, 1].
    """
    hint = ("expected 'start:stop:count' (e.g. 0:1:11) or a comma-separated list of "
            "probabilities (e.g. 0,0.25,0.5)")
    values = parse_values(str(spec), "--noise", hint)
    for v in values:
        if not 0.0 <= v <= 1.0:
            raise ValueError(f"--noise: {v:g} is not a probability in [0, 1] (from {spec!r})")
    return values


def _noise_key(noise: float) -> int:
    """Seed component for a noise value, so a row does not depend on the rest of the sweep."""
    return int(round(noise * 1e9))


def compare_at_noise(
    noise: float,
    *,
    episodes: int = 10_000,
    seed: int = 0,
    real_episodes: int = 10_000,
    explore: float = 0.1,
    patience: int = 2,
    max_grounding_steps: int = 30,
    max_steps: int = 1000,
) -> dict[str, Any]:
    """GAT, SGAT and the real optimum on Cliff Walking at one noise value (one x of Fig. 7).

    Both algorithms start from the policy that is optimal in the deterministic sim and run
    :func:`sgat.tabular.ground` with the same real-data generator (seeded from ``seed`` and
    ``noise``). The three policies are evaluated on the real MDP with common random numbers
    (one generator seed for all three), ``episodes`` episodes each, capped at ``max_steps``.

    Returns:
        a dict with the :data:`CSV_COLUMNS` keys: Monte-Carlo returns and standard errors
        (reward units), exact expected returns of each policy (``*_value``, from policy
        evaluation on the real MDP), grounding steps, convergence flags, real transitions used
        and truncated evaluation episodes; plus the three policies under ``"policies"``.

    Raises:
        ValueError: for a noise outside [0, 1] or non-positive counts.
    """
    sim = T.cliff_walking(0.0)
    real = T.cliff_walking(noise)
    key = _noise_key(noise)
    common = dict(real_episodes=real_episodes, explore=explore, patience=patience,
                  max_grounding_steps=max_grounding_steps, max_steps=max_steps)
    res = {m: T.ground(sim, real, m, np.random.default_rng([seed, key, 0]), **common)
           for m in ("gat", "sgat")}
    opt = T.policy_iteration(real)
    policies = {"gat": res["gat"].policy, "sgat": res["sgat"].policy, "optimal": opt.policy}
    row: dict[str, Any] = {"noise": float(noise)}
    for name, pi in policies.items():
        ev = T.evaluate_policy(real, pi, episodes, np.random.default_rng([seed, key, 1]),
                               max_steps=max_steps)
        row[f"{name}_return"] = ev.mean
        row[f"{name}_se"] = ev.se  # nan for a single episode
        row[f"{name}_value"] = float(T.policy_evaluation(real, pi)[real.start])
        row[f"{name}_truncated"] = ev.truncated
    for m in ("gat", "sgat"):
        row[f"{m}_steps"] = res[m].steps
        row[f"{m}_converged"] = res[m].converged
        row[f"{m}_real_transitions"] = res[m].real_transitions
    row["policies"] = policies
    return row


def sweep(noises: list[float], *, reporter: Reporter | None = None, **kwargs: Any) -> list[dict[str, Any]]:
    """:func:`compare_at_noise` for every noise value; ``reporter`` says each noise value as it is done
    (default: quiet)."""
    reporter = reporter or Reporter.quiet()
    rows = []
    for k, p in enumerate(noises):
        rows.append(compare_at_noise(p, **kwargs))
        reporter.say(f"noise {p:g} done ({k + 1}/{len(noises)})")
    return rows


# --------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------


def write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    """Write the sweep as CSV (columns :data:`CSV_COLUMNS`), atomically."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_COLUMNS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    _atomic_write_bytes(path, buf.getvalue().encode())


def _figure_bytes(fig) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: matplotlib

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=150)
    return buf.getvalue()


def plot_returns(rows: list[dict[str, Any]], path: Path, episodes: int) -> None:
    """Paper Fig. 7 style: mean real return vs noise for GAT, SGAT and the real optimum."""
    from matplotlib.figure import Figure  # lazy: matplotlib

    x = np.array([r["noise"] for r in rows])
    order = np.argsort(x, kind="stable")
    x = x[order]
    fig = Figure(figsize=(6.4, 4.4))
    ax = fig.add_subplot()
    get = lambda k: np.array([rows[i][k] for i in order], dtype=float)  # noqa: E731
    ax.errorbar(x, get("gat_return"), yerr=get("gat_se"), fmt="o-", color="tab:purple",
                ms=5, capsize=2, label="GAT")
    ax.errorbar(x, get("sgat_return"), yerr=get("sgat_se"), fmt="s-", color="tab:blue",
                ms=5, capsize=2, label="SGAT")
    ax.plot(x, get("optimal_return"), "--", color="tab:red", lw=1.5, zorder=5,
            label="policy iteration on real (optimum)")
    ax.set_xlabel("noise: chance per step that the transition is random")
    ax.set_ylabel('average return on "real"')
    ax.set_title(f"Cliff Walking: GAT vs SGAT ({episodes:,} episodes per point, ± s.e.)",
                 fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=9)
    fig.tight_layout()
    _atomic_write_bytes(path, _figure_bytes(fig))


def _greedy_path(mdp: T.TabularMDP, policy: np.ndarray, limit: int = 200) -> list[int]:
    """States visited by ``policy`` in the deterministic MDP from the start (stops on a loop)."""
    nxt = mdp.next_state()
    s, path = mdp.start, [mdp.start]
    while not mdp.terminal[s] and len(path) < limit:
        s = int(nxt[s, policy[s]])
        if s in path:
            break
        path.append(s)
    return path


def plot_paths(row: dict[str, Any], path: Path, rows_: int = 4, cols: int = 12) -> None:
    """Paper Fig. 6 style: the grid, the cliff and the paths GAT and SGAT take without noise."""
    from matplotlib.figure import Figure  # lazy: matplotlib
    from matplotlib.patches import Rectangle  # lazy: matplotlib

    sim = T.cliff_walking(0.0, rows=rows_, cols=cols)
    fig = Figure(figsize=(6.4, 2.6))
    ax = fig.add_subplot()
    for c in range(1, cols - 1):
        ax.add_patch(Rectangle((c - 0.5, rows_ - 1.5), 1, 1, color="tab:red", alpha=0.6))
    ax.text(0, rows_ - 1, "S", ha="center", va="center", fontsize=12, weight="bold")
    ax.text(cols - 1, rows_ - 1, "G", ha="center", va="center", fontsize=12, weight="bold")
    for name, color, off in (("gat", "tab:purple", -0.08), ("sgat", "tab:blue", 0.08)):
        states = _greedy_path(sim, row["policies"][name])
        r, c = np.divmod(np.array(states), cols)
        ax.plot(c + off, r + off, "-", color=color, lw=2.5,
                label=f"{name.upper()} (return {row[f'{name}_return']:.1f})")
    ax.set_xlim(-0.5, cols - 0.5)
    ax.set_ylim(rows_ - 0.5, -0.5)
    ax.set_xticks(np.arange(-0.5, cols, 1), minor=True)
    ax.set_yticks(np.arange(-0.5, rows_, 1), minor=True)
    ax.grid(which="minor", color="0.7", lw=0.8)
    ax.tick_params(which="both", length=0, labelbottom=False, labelleft=False)
    ax.set_aspect("equal")
    ax.set_title(f"Cliff Walking paths of the policies trained at noise {row['noise']:g}",
                 fontsize=10)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.02), ncol=2, fontsize=9,
              frameon=False)
    fig.tight_layout()
    _atomic_write_bytes(path, _figure_bytes(fig))


def policy_string(policy: np.ndarray, rows: int = 4, cols: int = 12) -> str:
    """A Cliff Walking policy as rows of ``U D L R`` letters (``.`` = terminal), '/'-separated."""
    term = T.cliff_walking(0.0, rows=rows, cols=cols).terminal
    letters = np.where(term, ".", np.array(["U", "D", "L", "R"])[np.asarray(policy)])
    return "/".join("".join(letters[r * cols:(r + 1) * cols]) for r in range(rows))


def format_table(rows: list[dict[str, Any]], episodes: int, seed: int) -> str:
    """The table ``sgatwalk cliff`` prints, from its rows (also from its ``--json`` result)."""
    head = f"{'noise':>6}  {'GAT':>16}  {'SGAT':>16}  {'optimum (real)':>16}  grounding steps"
    lines = [f"Cliff Walking 4x12, GAT vs SGAT; real return over {episodes} episodes (mean ± s.e.), seed {seed}",
             head, "-" * len(head)]
    for r in rows:
        cells = [f"{r[f'{k}_return']:8.2f} ± {r[f'{k}_se']:5.2f}" for k in ("gat", "sgat", "optimal")]
        steps = f"GAT {r['gat_steps']}{'' if r['gat_converged'] else '*'}, " \
                f"SGAT {r['sgat_steps']}{'' if r['sgat_converged'] else '*'}"
        lines.append(f"{r['noise']:6.2f}  {cells[0]:>16}  {cells[1]:>16}  {cells[2]:>16}  {steps}")
    if any(not (r["gat_converged"] and r["sgat_converged"]) for r in rows):
        lines.append("* policy still changing at the grounding-step cap (at noise 1 every action is "
                     "equally good, so sampling noise in the counts keeps re-ordering them)")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------


def run_cliff(noises, out, *, episodes: int, seed: int, real_episodes: int, explore: float, patience: int,
              max_grounding_steps: int, max_steps: int, reporter: Reporter | None = None) -> tuple[dict, list[dict]]:
    """The sweep over ``noises`` (:func:`sweep`), its files in ``out`` (``cliff.csv``, ``cliff.png``,
    ``cliff_paths.png``: the greedy paths at the noise where SGAT gains most over GAT) and its result.

    Returns:
        (the result: ``{"rows", "episodes", "seed", "params", "elapsed_s", "files"}``, the full rows).
    """
    out = Path(out)
    t0 = time.perf_counter()
    rows = sweep(noises, reporter=reporter, episodes=episodes, seed=seed, real_episodes=real_episodes, explore=explore,
                 patience=patience, max_grounding_steps=max_grounding_steps, max_steps=max_steps)
    elapsed = time.perf_counter() - t0
    csv_path, png_path, paths_path = out / "cliff.csv", out / "cliff.png", out / "cliff_paths.png"
    write_csv(rows, csv_path)
    plot_returns(rows, png_path, episodes)
    inter = [r for r in rows if 0.0 < r["noise"] < 1.0] or rows
    plot_paths(max(inter, key=lambda r: r["sgat_return"] - r["gat_return"]), paths_path)
    public = [{k: v for k, v in r.items() if k != "policies"} for r in rows]
    for r, full in zip(public, rows):
        for k in ("gat", "sgat", "optimal"):
            r[f"{k}_policy"] = policy_string(full["policies"][k])
    return ({"rows": public, "episodes": episodes, "seed": seed,
             "params": {"real_episodes": real_episodes, "explore": explore, "patience": patience,
                        "max_grounding_steps": max_grounding_steps, "max_steps": max_steps, "grid": [4, 12]},
             "elapsed_s": elapsed, "files": {"csv": str(csv_path), "png": str(png_path), "paths_png": str(paths_path)}},
            rows)
