"""How faithful is the grounded sim? Held-out one-step errors of its models by state history, and θ0's
walk in it by blend α, beside the real world and the plain sim, in one run.

1. Walk θ0 ``--real`` times in the real world (PyBullet, "real" profile) and ``--sim`` times in the
   sim with the grounded world's exploration noise on the leg targets (``explore``).
2. For GAT and SGAT with the options of ``--options`` (default: none, the default grounding of the
   worlds ``gat`` and ``sgat``: linear models, ensemble of 5, α 0.5; ``experiments.runtime.worlds``),
   fit the models (``experiments.runtime.grounding.fit_walk_grounding``) on all but the last episode
   of each world, with the grounding state (leg q and dq) over each history of ``--histories``
   (default 1, the paper's, 2, and the world's own, 6 at the defaults), and report held-out one-step
   errors of the ensemble's member 0 (fitted on all the transitions: the same whatever the ensemble's
   size, so the other histories fit it alone) on the last episodes: the forward model's normalized MSE
   of Δs on real data (1.0 = no better than predicting the mean change) and the inverse model's RMS
   action error on sim data [mrad] (the exploration noise sets the scale).
3. Walk θ0 ``--trials`` times (seeds shared by every world) in the real world, the plain sim and the
   grounded sims of the world's own history for each blend α of ``--alphas`` (default 1, the paper's
   formula, and 0.5, the default): speed mean ± std and median [cm/s], its difference to the real
   world's mean, and falls.

Prints the tables, or one JSON object with ``--json`` (its ``"text"`` the tables); progress goes to
stderr. Defaults take about 1 minute on 2 idle cores.

Usage: ``python benchmarks/grounding_fidelity.py [--real 6] [--sim 6] [--trials 6] [--alphas 1 0.5] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

METHODS = ("gat", "sgat")


def heldout_errors(fit, real_h, sim_h, real_train) -> dict:
    """Member 0's one-step errors on the held-out transitions: forward nMSE of Δs on real data (scaled
    by the training rows' std per state entry) and inverse RMS action error on sim data [rad]."""
    tr = fit.transformer
    mu, _ = tr.forwards[0].predict(real_h.forward_input())
    nmse = float(np.mean(((mu - real_h.dS) / real_train.dS.std(0)) ** 2))
    inv = tr.inverses[0].predict(np.hstack([sim_h.H, sim_h.dS]))
    return {"forward_nmse": nmse, "inverse_rms_rad": float(np.sqrt(np.mean((inv - sim_h.A) ** 2)))}


def build_parser() -> argparse.ArgumentParser:
    """The command line: episodes, world options, histories, trials, blends, episode length, workers."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="About 1 minute at the defaults on 2 idle cores.")
    ap.add_argument("--real", type=int, default=6, help="real episodes of θ0 (the last one held out; default 6)")
    ap.add_argument("--sim", type=int, default=6, help="sim episodes of θ0 with exploration noise (the last one held out; default 6)")
    ap.add_argument("--options", default="",
                    help="world options of both grounded worlds, e.g. hidden=64x64:explore=0.05 (default: none)")
    ap.add_argument("--histories", type=int, nargs="+", default=None,
                    help="state histories [frames] to fit (default 1 2; the world's own, which the walks use, always)")
    ap.add_argument("--trials", type=int, default=6, help="θ0 walks per world (default 6)")
    ap.add_argument("--alphas", type=float, nargs="+", default=[1.0, 0.5],
                    help="blend factors α of the grounded sims to walk θ0 in (default 1 0.5)")
    ap.add_argument("--seconds", type=float, default=7.5, help="episode length [s] (default 7.5, the paper's)")
    ap.add_argument("--workers", type=int, default=None, help="worker processes (default: one per core)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (its \"text\": the tables)")
    return ap


def grounded_worlds(options: str, histories: list[int] | None) -> tuple[dict, int, list[int], float]:
    """The grounded worlds of :data:`METHODS` with ``options``, their own state history [frames], the
    histories to fit (``histories``, default 1 and 2, with the own one always; sorted) and the
    exploration noise of their sim walks [rad].

    Raises:
        ValueError: options the worlds do not take, a delay (it grounds the identified sim), or a
            history below 1.
    """
    from experiments.runtime.worlds import parse_world

    specs = {m: parse_world(f"{m}:{options}" if options else m) for m in METHODS}
    if any(s.get("delay") for s in specs.values()):
        raise ValueError("--options: a delay grounds the identified sim (hybrid), not the plain sim")
    own = int(specs["sgat"].get("history"))
    histories = sorted(set(histories if histories else [1, 2, own]) | {own})
    if min(histories) < 1:
        raise ValueError("--histories must be >= 1")
    return specs, own, histories, float(specs["sgat"].get("explore"))


def progress(t0: float):
    """A function that prints a message to stderr after the seconds since ``t0`` (``time.perf_counter``)."""

    def say(msg):
        print(f"[grounding_fidelity {time.perf_counter() - t0:5.0f} s] {msg}", file=sys.stderr, flush=True)

    return say


def record_walks(ex, theta, n_real: int, n_sim: int, seconds: float, noise: float) -> tuple[list, list]:
    """Record θ0 (``theta``, GaitParams array) ``n_real`` times in the real world (seeds 100, 101, ...)
    and ``n_sim`` times in the sim with ``noise`` [rad] of exploration noise (seeds 200, ...), episodes
    of ``seconds``, on executor ``ex``: (real recordings, sim recordings)."""
    from envs import Recording
    from experiments.runtime.batch import map_episodes
    from experiments.runtime.tasks import EpisodeTask

    res = map_episodes(ex, [EpisodeTask("real", theta, 100 + i, seconds, record=True) for i in range(n_real)]
                       + [EpisodeTask("sim", theta, 200 + i, seconds, record=True, action_noise=noise)
                          for i in range(n_sim)])
    return [Recording(*r.recording) for r in res[:n_real]], [Recording(*r.recording) for r in res[n_real:]]


def measure_heldout(ex, real: list, sim: list, specs: dict, histories: list[int], own: int, say) -> tuple:
    """Fit each world's grounding on all but the last real and sim recording with each state history
    (``own``, the world's: its ensemble; the others: one member) and measure the held-out errors
    (:func:`heldout_errors`) on the last ones.

    Returns:
        ({"<method> history <k>": {"world", "history", "forward_nmse", "inverse_rms_rad"}}, the table's
        rows, {method: the fit with the world's own history}).
    """
    import dataclasses

    from envs import ObservationLayout
    from experiments.runtime.grounding import fit_walk_grounding, walk_spec
    from robots import get_robot
    from sgat.grounding import recording_transitions

    layout = ObservationLayout(get_robot("nao"))
    heldout: dict = {}
    lines: list[str] = []
    fits = {}
    for h in histories:
        spec = walk_spec(h, "nao")
        R, Rh = recording_transitions(real[:-1], layout, spec), recording_transitions(real[-1:], layout, spec)
        Sh = recording_transitions(sim[-1:], layout, spec)
        for m, s in specs.items():
            cfg = s.grounding_config()
            if h != own:
                cfg = dataclasses.replace(cfg, ensemble=1)
            say(f"fitting {m} with history {h} ({cfg.ensemble} member(s))")
            fit = fit_walk_grounding(real[:-1], sim[:-1], cfg, history=h, seed=0, map_fn=ex.map)
            err = heldout_errors(fit, Rh, Sh, R)
            heldout[f"{m} history {h}"] = {"world": s.name, "history": h, **err}
            lines.append(f"{f'legs q, dq (k={h})':22s} {s.name:28s} {err['forward_nmse']:12.3f} "
                         f"{1000 * err['inverse_rms_rad']:19.1f}")
            if h == own:
                fits[m] = fit
    return heldout, lines, fits


def walk_worlds(ex, theta, fits: dict, alphas: list[float], own: int, trials: int, seconds: float, say) -> tuple:
    """Walk θ0 ``trials`` times (seeds 300, 301, ..., shared by the worlds) in the real world, the plain
    sim and the grounded sim of each fit at each blend of ``alphas``.

    Returns:
        ([(label, world, transformer path or None)] per world, the episode results, ``trials`` per
        world in that order).
    """
    from experiments.runtime.batch import map_episodes
    from experiments.runtime.tasks import EpisodeTask
    from sgat.transformer import ActionTransformer

    rows = [("real (PyBullet, 'real' profile)", "real", None), ("sim (MuJoCo)", "sim", None)]
    with tempfile.TemporaryDirectory() as tmp:
        for m in METHODS:
            tr = fits[m].transformer
            for alpha in alphas:
                path = os.path.join(tmp, f"{m}_{alpha:g}")
                ActionTransformer(tr.spec, tr.forwards, tr.inverses, method=m, alpha=alpha, seed=tr.seed).save(path)
                rows.append((f"grounded {m.upper()} (k={own}), alpha {alpha:g}", "sim", path))
        say(f"walking θ0 {trials} times in {len(rows)} worlds")
        tasks = [EpisodeTask(world, theta, 300 + i, seconds, transformer=path)
                 for _, world, path in rows for i in range(trials)]
        walked = map_episodes(ex, tasks)
    return rows, walked


def walk_table(rows: list, walked: list, trials: int) -> tuple[dict, list[str]]:
    """Speed mean, std and median [cm/s], the mean's difference to the first (real) world's and falls
    per world: ({label: figures}, the table's rows)."""
    walks: dict = {}
    lines: list[str] = []
    real_mean = None
    for j, (label, _, _) in enumerate(rows):
        ep = walked[j * trials:(j + 1) * trials]
        sp = np.array([e.speed_cm_s for e in ep])
        real_mean = float(sp.mean()) if real_mean is None else real_mean
        std = float(sp.std(ddof=1)) if len(sp) > 1 else 0.0
        falls = int(sum(e.fell for e in ep))
        walks[label] = {"speed_mean": float(sp.mean()), "speed_std": std, "speed_median": float(statistics.median(sp)),
                        "speed_minus_real": float(sp.mean()) - real_mean, "falls": falls, "trials": len(ep)}
        lines.append(f"{label:36s} {sp.mean():6.2f} ± {std:5.2f} {statistics.median(sp):7.2f} "
                     f"{sp.mean() - real_mean:+7.2f} {falls:>3d}/{len(ep)}")
    return walks, lines


def measure(args, specs: dict, own: int, histories: list[int], noise: float) -> dict:
    """Run the benchmark with the parsed command line ``args`` and :func:`grounded_worlds`' figures;
    progress on stderr.

    Returns:
        {"real", "sim", "explore_rad", "trials", "seconds", "worlds", "histories", "heldout" (see
        :func:`measure_heldout`), "walks" (see :func:`walk_table`), "wall_s", "text": the tables}.
    """
    from experiments.runtime.batch import map_episodes  # noqa: F401  (loads torch and the engines before the thread limit)
    from experiments.runtime.executors import limit_blas_threads, make_executor
    from walk_engine import GaitParams

    limit_blas_threads()
    t0 = time.perf_counter()
    say = progress(t0)
    theta = GaitParams.initial().to_array()
    out: dict = {"real": args.real, "sim": args.sim, "explore_rad": noise, "trials": args.trials, "seconds": args.seconds,
                 "worlds": {m: s.name for m, s in specs.items()}, "histories": histories, "heldout": {}, "walks": {}}
    with make_executor(args.workers) as ex:
        say(f"recording {args.real} real and {args.sim} sim walks of θ0")
        real, sim = record_walks(ex, theta, args.real, args.sim, args.seconds, noise)
        lines = [(f"data: {sum(map(len, real))} real / {sum(map(len, sim))} sim transitions of θ0 "
                  f"(sim exploration noise {noise:g} rad)")]
        lines += ["", "held-out one-step errors (last episode of each world held out; ensemble member 0)",
                  f"{'grounding state':22s} {'world':28s} {'forward nMSE':>12s} {'inverse RMS [mrad]':>19s}"]
        out["heldout"], heldout_lines, fits = measure_heldout(ex, real, sim, specs, histories, own, say)
        lines += heldout_lines
        rows, walked = walk_worlds(ex, theta, fits, args.alphas, own, args.trials, args.seconds, say)
    lines += ["", f"θ0 walking, {args.trials} trials per world on shared seeds (speed [cm/s]; Δ real: the mean's "
                  "difference to the real world's)",
              f"{'world':36s} {'mean ± std':>14s} {'median':>7s} {'Δ real':>7s} {'falls':>6s}"]
    out["walks"], walk_lines = walk_table(rows, walked, args.trials)
    lines += walk_lines
    out["wall_s"] = time.perf_counter() - t0
    say(f"done ({out['wall_s']:.0f} s)")
    out["text"] = "\n".join(lines)
    return out


def main(argv=None) -> dict:
    """Parse the command line, run the benchmark, print its tables (or JSON with ``--json``); returns
    :func:`measure`'s dict. Errors in the options exit through ``argparse`` (status 2)."""
    ap = build_parser()
    args = ap.parse_args(argv)
    if min(args.real, args.sim) < 2 or args.trials < 1 or not args.seconds > 0:
        ap.error("--real and --sim must be >= 2 (one is held out), --trials >= 1, --seconds > 0")
    if any(not 0.0 <= a <= 1.0 for a in args.alphas):
        ap.error("--alphas must lie in [0, 1]")
    try:
        specs, own, histories, noise = grounded_worlds(args.options, args.histories)
    except ValueError as exc:
        ap.error(str(exc))
    out = measure(args, specs, own, histories, noise)
    print(json.dumps(out) if args.json else out["text"], flush=True)
    return out


if __name__ == "__main__":
    main()
