"""How faithful is the grounded sim? Grounding-state choices and the blend α, measured.

1. Walk θ0 in the real world (PyBullet, "real" profile) and in the sim with exploration noise.
2. For each grounding state -- ``legs`` (leg q, dq: the default), ``legs+imu`` (plus torso gyro,
   roll, pitch), ``legs`` with a 2-frame history -- fit GAT and SGAT models on all but the last
   episode and report held-out one-step errors: the forward model's normalized MSE of Δs on real
   data (1.0 = no better than predicting the mean change) and the inverse model's RMS action error
   on sim data [mrad] (the exploration noise sets the scale).
3. Walk θ0 in the grounded sims (default state) for each blend α of ``--alphas`` (default 1, the
   paper's formula, and 0.5) and compare speed and falls with the real world and the plain sim.

Usage: ``python benchmarks/grounding_fidelity.py [--real 6] [--sim 6] [--trials 6] [--alphas 1 0.5] [--workers 2]``.
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real", type=int, default=6, help="real episodes (the last one is held out)")
    ap.add_argument("--sim", type=int, default=6, help="sim episodes with exploration noise")
    ap.add_argument("--noise", type=float, default=0.05, help="exploration noise [rad]")
    ap.add_argument("--trials", type=int, default=6, help="θ0 walks per world")
    ap.add_argument("--alphas", type=float, nargs="+", default=[1.0, 0.5],
                    help="blend factors α of the grounded sims to walk θ0 in")
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args(argv)

    from envs import NaoSimEnv, Recording
    from experiments.runtime.executors import make_executor
    from experiments.runtime.tasks import run_episode
    from sgat.grounding import fit_transformer, recording_transitions
    from walk_engine import GaitParams

    from experiments.runtime.grounding import grounding_spec
    from sgat.transformer import ActionTransformer

    theta = GaitParams.initial().to_array().tolist()
    base = {"theta": theta, "seconds": 7.5, "profile": "real"}
    t0 = time.perf_counter()
    with make_executor(args.workers) as ex:
        res = ex.map(run_episode, [{**base, "world": "real", "seed": 100 + i, "record": True} for i in range(args.real)]
                     + [{**base, "world": "sim", "seed": 200 + i, "record": True, "action_noise": args.noise}
                        for i in range(args.sim)])
        real = [Recording(*r["recording"]) for r in res[:args.real]]
        sim = [Recording(*r["recording"]) for r in res[args.real:]]
        print(f"data: {sum(map(len, real))} real / {sum(map(len, sim))} sim transitions ({time.perf_counter() - t0:.0f} s)")
        env = NaoSimEnv()
        print("\nheld-out one-step errors (last episode of each world held out)")
        print(f"{'grounding state':22s} {'method':6s} {'forward nMSE':>12s} {'inverse RMS [mrad]':>19s}")
        fits = {}
        for variant, k in (("legs", 1), ("legs+imu", 1), ("legs", 2)):
            spec = grounding_spec(env, variant, k)
            R, Rh = recording_transitions(real[:-1], env.layout, spec), recording_transitions(real[-1:], env.layout, spec)
            S, Sh = recording_transitions(sim[:-1], env.layout, spec), recording_transitions(sim[-1:], env.layout, spec)
            for m in ("gat", "sgat"):
                f = fit_transformer(R, S, spec, method=m, alpha=1.0, seed=0, fit_kwargs={"lr": 3e-3, "max_epochs": 150})
                mu, _ = f.transformer.forward.predict(np.hstack([Rh.H, Rh.A]))
                nmse = float(np.mean(((mu - Rh.dS) / R.dS.std(0)) ** 2))
                inv = float(np.sqrt(np.mean((f.transformer.inverse.predict(np.hstack([Sh.H, Sh.dS])) - Sh.A) ** 2)))
                print(f"{variant + f' (k={k})':22s} {m:6s} {nmse:12.3f} {1000 * inv:19.1f}")
                fits[(variant, k, m)] = f
        # grounded sims with the default state
        print(f"\nθ0 walking, {args.trials} trials per world (speed mean ± std [cm/s], falls)")
        rows = [("real (PyBullet, 'real' profile)", "real", {}), ("sim (MuJoCo)", "sim", {})]
        with tempfile.TemporaryDirectory() as tmp:
            for m in ("gat", "sgat"):
                for alpha in args.alphas:
                    tr = fits[("legs", 1, m)].transformer
                    path = f"{tmp}/{m}_{alpha}"
                    ActionTransformer(tr.spec, tr.forward, tr.inverse, method=m, alpha=alpha).save(path)
                    rows.append((f"grounded {m.upper()}, alpha {alpha}", "grounded", {"transformer": path}))
            for label, world, kw in rows:
                out = ex.map(run_episode, [{**base, "world": world, "seed": 300 + i, **kw} for i in range(args.trials)])
                sp = np.array([o["speed_cm_s"] for o in out])
                print(f"{label:34s} {sp.mean():6.2f} ± {sp.std(ddof=1):5.2f}   falls {sum(o['fell'] for o in out)}/{len(out)}")
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
