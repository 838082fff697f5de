"""The gait optimization with grounding: Algorithm 1 of the SGAT paper for the walking humanoid.

For each method (a training world, ``experiments.runtime.worlds``) and grounding step i
(θ_0 = the walk engine's initial parameters):

1. **Real data** -- walks with θ_i in the PyBullet real world on fresh terrain seeds (the world's
   ``real`` option, 4 by default; the same seeds for every method: paired comparisons).
2. **Sim data** -- walks with θ_i in the sim the method grounds (``sim`` walks) with Gaussian
   exploration noise on the leg targets (``explore``), so the inverse model covers the states the
   forward model proposes.
3. **Grounding** -- fit ``f_real`` (SGAT: Gaussian NLL; GAT: MSE) and ``f_sim^-1`` on the walks of θ_i
   and, with ``aggregate`` (default), of every earlier θ_j, as the GARAT/GAT code accumulates data
   across grounding steps (:func:`experiments.runtime.grounding.fit_walk_grounding`); the transformer is
   saved under ``models/``.
4. **Policy improvement** -- CMA-ES (pycma) over the 16 normalized gait parameters, started at θ_i
   with step size ``sigma0`` and bounded to a trust region of ±``trust_region`` around θ_i (the
   grounding models were fitted on θ_i's data and do not hold far from it), in the training world;
   each candidate's fitness is the paper's reward (forward speed in cm/s, −15 if it fell) averaged
   over ``episodes_per_candidate`` episodes on seeds shared by the whole generation (common random
   numbers). θ_{i+1} is the best of the distribution mean, the best candidate and θ_i itself,
   re-evaluated on ``select_episodes`` fresh seeds shared by the three.
5. **Evaluation** -- ``eval_trials`` walks of θ_{i+1} in the real world on fresh seeds (shared by all
   methods): speed mean ± std and falls, the paper's Table I.

Worlds that build on the identified sim (``identified``, ``hybrid``) share one identification per run,
done first (:func:`experiments.runtime.identify.identify_real`: engine-gap calibration, fixed-base and
stepping excitation logs of the real world, two diagnoses); its logs count as real data. Everything
random comes from ``numpy.random.SeedSequence`` keyed by (seed, purpose, step, generation), never from
worker state, so the executor does not change results, and a run killed at any point and resumed
ends with the same parameters as an uninterrupted run: the checkpoint ``cma_state.pkl`` (the CMA-ES
object with its own random stream, every method's progress, the rows so far) is replaced atomically
after every generation.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import json
import os
import pickle
import time

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from common.files import atomic_path
from common.files import atomic_write_bytes as _atomic_write
from envs import Recording
from experiments.optimize.config import (CMA_RANDN, EVALUATION, GENERATION, IDENTIFICATION, REAL_WALKS, SELECTION,
                                         SIM_WALKS, STATE_FILE, OptimizeConfig)
from experiments.optimize.report import format_table, plot_progress
from experiments.optimize.results import GenerationTimes, OptimizeResult, RealData, StepRow
from experiments.runtime.batch import expected_generation_seconds, map_episodes
from experiments.runtime.grounding import (IDENTIFY_BUDGET_S, IDENTIFY_ROUNDS, fit_walk_grounding,
                                           identified_delay)
from experiments.runtime.identify import ENGINE_GAP_SEED, calibrate_engines, identify_real
from experiments.runtime.progress import Reporter
from experiments.runtime.seeds import derive_seed, derive_seeds
from experiments.runtime.tasks import EpisodeTask, episode_task
from experiments.runtime.worlds import parse_world
from robots import get_robot
from sgat.algorithm import grounding_loop, new_progress
from walk_engine import params_for
from walk_engine.params import NAMES as PARAM_NAMES


def _theta_key(theta) -> str:
    return hashlib.sha1(np.asarray(theta, dtype=np.float64).tobytes()).hexdigest()[:12]


def slug(method: str) -> str:
    """A training world's name as a file name: ``sgat:ane=0.05`` -> ``sgat_ane0.05``."""
    return method.replace(":", "_").replace("=", "")


def summarize(results: list) -> dict:
    """Speed mean/std [cm/s], falls and mean fitness of a list of episode results."""
    speed = np.array([r.speed_cm_s for r in results])
    fit = np.array([r.fitness for r in results])
    return {"trials": len(results), "speed_mean": float(speed.mean()),
            "speed_std": float(speed.std(ddof=1)) if len(speed) > 1 else 0.0,
            "falls": int(sum(bool(r.fell) for r in results)), "fitness_mean": float(fit.mean())}


def identify(root: str, *, seed: int, profile="real", stochasticity: float = 0.0,
             reporter: Reporter | None = None) -> dict:
    """Identify the real world once for the worlds built on it: the testbed's engine-gap calibration,
    excitation logs in the air and stepping, two diagnoses (:func:`experiments.runtime.identify.identify_real`),
    all in ``root``; reused when there.

    Args:
        root: the folder (``RUN_DIR/identified``); seed: the run seed (the logs' seed is derived from it);
        profile: the real world's effect profile; stochasticity: its per-step randomness level;
        reporter: progress.

    Returns:
        :func:`experiments.runtime.identify.identify_real`'s result.
    """
    report = reporter or Reporter.quiet()
    t0 = time.perf_counter()
    report.say("identify: engine-gap calibration and excitation logs of the real world, then two diagnoses")
    # the engine gap (PyBullet vs MuJoCo on the real world without its effects) is a constant of the
    # testbed: the package ships it for the pinned engines and a run copies it
    cal = calibrate_engines(os.path.join(root, "calibration"), seed=ENGINE_GAP_SEED)
    res = identify_real(root, seed=derive_seed(seed, IDENTIFICATION) % 1_000_000, profile=profile, calibration=cal,
                        time_budget_s=IDENTIFY_BUDGET_S, rounds=IDENTIFY_ROUNDS, stochasticity=stochasticity)
    report.say(f"identify: {len(res['effects'])} terms, uneven ground Sq {1000 * res['terrain_rms_height']:.2f} mm "
               f"from {res['logs']} logs ({res['seconds']:.0f} s of recording; {time.perf_counter() - t0:.0f} s)"
               + "".join(f"; WARNING: the {k} diagnosis ran out of its {IDENTIFY_BUDGET_S:g} s budget, so the "
                         f"identified world depends on this machine's speed" for k in res.get("time_budget_reached", [])))
    return res


class CheckpointError(ValueError):
    """The run directory's checkpoint is unreadable, from another version of cma or of this project."""


class Optimizer:
    """Runs (or resumes) an optimization in ``run_dir`` with ``executor`` (see the module docstring).

    Args:
        cfg: the settings (ignored on resume: the run's own config is used).
        run_dir: output directory (created).
        executor: an ``experiments.runtime.executors`` executor.
        reporter: where stage lines and progress go (default: quiet).
        rerun: log selected candidates and real trials as ``.rrd`` files (Rerun).
        identification: the real world's identification (:func:`identify`) to build the identified
            worlds on, made elsewhere (a Table I seed's methods share one); None: made in the run.
    """

    def __init__(self, cfg: OptimizeConfig, run_dir: str, executor, *, reporter: Reporter | None = None,
                 rerun: bool = False, identification: dict | None = None):
        # absolute: the tasks name its models and recordings, and a Ray worker may run elsewhere
        self.cfg, self.run_dir, self.ex, self.rerun = cfg, os.path.abspath(run_dir), executor, rerun
        self.identification = identification
        self.report = reporter or Reporter.quiet()
        os.makedirs(run_dir, exist_ok=True)
        for sub in ("data", "models", "thetas"):
            os.makedirs(os.path.join(run_dir, sub), exist_ok=True)
        self.state: dict = {}

    @property
    def params_class(self):
        """The run robot's :class:`walk_engine.GaitParams` class (``walk_engine.params_for``)."""
        return params_for(get_robot(self.cfg.robot))

    # ---------------------------------------------------------------- checkpoint
    @property
    def state_path(self) -> str:
        return os.path.join(self.run_dir, STATE_FILE)

    def _save(self) -> None:
        _atomic_write(self.state_path, pickle.dumps(self.state))
        self._write_tables()

    @classmethod
    def load_state(cls, run_dir: str) -> dict:
        """Read ``cma_state.pkl`` of ``run_dir``.

        Raises:
            FileNotFoundError: no checkpoint. CheckpointError: corrupted, or written by another cma or
                by a version of this project whose settings differ.
        """
        import cma  # lazy: cma

        path = os.path.join(run_dir, STATE_FILE)
        if not os.path.exists(path):
            raise FileNotFoundError(f"no {STATE_FILE} in {run_dir!r}: nothing to resume")
        try:
            with open(path, "rb") as f:
                state = pickle.load(f)
            state["config"], state["progress"]  # noqa: B018 - shape check
        except Exception as exc:
            raise CheckpointError(f"{path!r} is corrupted ({type(exc).__name__}: {exc}); "
                                  "delete the run directory to start over") from None
        if state.get("cma_version") != cma.__version__:
            raise CheckpointError(f"{path!r} was written with cma {state.get('cma_version')}, this is "
                                  f"{cma.__version__}; CMA-ES states do not carry across versions")
        try:
            OptimizeConfig.from_dict(state["config"])
        except ValueError as exc:
            raise CheckpointError(f"{path!r}: {exc}") from None
        return state

    # ---------------------------------------------------------------- episodes
    def _seeds(self, purpose: int, *keys: int, n: int) -> list[int]:
        return derive_seeds(self.cfg.seed, purpose, *keys, n=n)

    def _reports(self) -> tuple:
        return tuple(self.state["identification"]["reports"]) if self.state.get("identification") else ()

    def _world_tasks(self, method: str, step: int, theta, seeds, **kw) -> list[EpisodeTask]:
        """Episodes of θ in ``method``'s training world at grounding step ``step``."""
        spec = parse_world(method)
        model = os.path.join(self.run_dir, "models", f"{slug(method)}_step{step}") if spec.grounded else None
        return [episode_task(spec, theta, s, seconds=self.cfg.seconds, robot=self.cfg.robot, profile=self.cfg.profile,
                             stochasticity=self.cfg.stochasticity, transformer=model, identified=self._reports() if spec.needs_identification else (), **kw)
                for s in seeds]

    def _real_tasks(self, theta, seeds, **kw) -> list[EpisodeTask]:
        return self._world_tasks("real", 0, theta, seeds, **kw)

    def _map(self, tasks: list[EpisodeTask], desc: str) -> list:
        with self.report.count(len(tasks), desc) as update:
            return map_episodes(self.ex, tasks, progress=update)

    def _recordings(self, world: str, theta, seeds, *, action_noise: float = 0.0, identified=()) -> list:
        """Recordings of θ in ``world`` (sim, real, identified) on ``seeds``, cached as Parquet under ``data/``."""
        tag = f"{world}_{_theta_key(theta)}_n{action_noise:g}"
        paths = [os.path.join(self.run_dir, "data", f"{tag}_{s}.parquet") for s in seeds]
        todo = [s for s, p in zip(seeds, paths) if not os.path.exists(p)]
        if todo:
            tasks = [EpisodeTask(world, tuple(theta), s, self.cfg.seconds, robot=self.cfg.robot, profile=self.cfg.profile,
                                 stochasticity=self.cfg.stochasticity if world == "real" else 0.0,
                                 identified=tuple(identified), action_noise=action_noise, record=True) for s in todo]
            for s, r in zip(todo, self._map(tasks, f"{world} data")):
                Recording(*r.recording).to_parquet(os.path.join(self.run_dir, "data", f"{tag}_{s}.parquet"))
        return [Recording.from_parquet(p) for p in paths]

    # ---------------------------------------------------------------- grounding
    def _ground(self, method: str, step: int, theta) -> str:
        """The grounding step (Algorithm 1, "ground"): real and sim walks of θ_i (and of every earlier
        θ_j with ``aggregate``), the forward and inverse models fitted, the transformer saved."""
        cfg, spec = self.cfg, parse_world(method)
        out = os.path.join(self.run_dir, "models", f"{slug(method)}_step{step}")
        if os.path.exists(os.path.join(out, "transformer.json")):
            return out
        hybrid = spec.needs_identification  # the transformer grounds the identified sim: its inverse model is of that sim
        real, sim = [], []
        for j, th in self._data_thetas(method, step, theta):
            real += self._recordings("real", th, self._seeds(REAL_WALKS, j, n=int(spec.get("real"))))
            sim += self._recordings("identified" if hybrid else "sim", th, self._seeds(SIM_WALKS, j, n=int(spec.get("sim"))),
                                    action_noise=float(spec.get("explore")), identified=self._reports() if hybrid else ())
        used = self.state.setdefault("real_used", {}).setdefault(method, {})
        for r in real:
            used[f"{_theta_key(list(r.meta['params'].values()))}_{r.meta['seed']}"] = len(r) * r.meta["control_dt"]
        t0 = time.perf_counter()
        gcfg = spec.grounding_config(delay=identified_delay(self._reports()) if spec.get("delay") == "auto" else None)
        fit = fit_walk_grounding(real, sim, gcfg, history=int(spec.get("history")), seed=cfg.seed + step, robot=cfg.robot,
                                 map_fn=self.ex.map)  # the ensemble's members side by side on the workers
        fit.transformer.save(out)
        self.report.say(f"{method} step {step}: grounded on {fit.info['n_real']} real / {fit.info['n_sim']} sim transitions "
                        f"(forward val loss {fit.forward_report.val_loss:.3f}, inverse {fit.inverse_report.val_loss:.3f}, "
                        f"{time.perf_counter() - t0:.0f} s)")
        return out

    def _data_thetas(self, method: str, step: int, theta) -> list[tuple[int, np.ndarray]]:
        """(grounding step j, θ_{j-1}) pairs whose walks ground step ``step``: only θ_i's own with
        ``aggregate=False``; with ``aggregate=True`` (default) every earlier step's too, as the
        GARAT/GAT code accumulates its data across grounding steps (``rl_gat/gat.py``, Desai et al.,
        NeurIPS 2020). Earlier steps' recordings are cached under ``data/``, so aggregation costs no
        new walks."""
        if not self.cfg.aggregate:
            return [(step, np.asarray(theta))]
        thetas = {0: np.asarray(self.state["theta0"])}
        for r in self.state["rows"]:
            if r["method"] == method and r["step"] >= 1:
                thetas[r["step"]] = np.asarray(r["theta"])
        return [(j, thetas[j - 1]) for j in range(1, step)] + [(step, np.asarray(theta))]

    # ---------------------------------------------------------------- policy improvement
    def _improve(self, method: str, step: int, prog: dict) -> list:
        """Policy improvement of a grounding step: CMA-ES in the training world, then the choice of
        θ_{i+1} (:meth:`_select`); the CMA-ES state lives in ``prog`` (``es``, ``gen``) so that a
        killed run resumes mid-generation loop."""
        self._cma(method, step, prog)
        return self._select(method, step, prog).tolist()

    def _start_cma(self, step: int, prog: dict) -> None:
        import cma  # lazy: cma

        x0 = self.params_class.from_array(prog["policy"]).to_vector()
        r = self.cfg.trust_region  # the models are fitted on θ_i's data: search near θ_i
        lo, hi = np.clip(x0 - r, 0.0, 1.0), np.clip(x0 + r, 0.0, 1.0)
        opts = {"bounds": [lo.tolist(), hi.tolist()], "popsize": self.cfg.popsize, "verbose": -9, "verb_log": 0,
                "verb_disp": 0, "randn": np.random.RandomState(self._seeds(CMA_RANDN, step, n=1)[0]).randn,
                "tolflatfitness": 100}
        prog["es"] = cma.CMAEvolutionStrategy(x0, self.cfg.sigma0, opts)
        prog["gen"] = 0

    def _estimate(self, method: str, step: int, prog: dict) -> dict:
        """The expected time of a generation, timed on a trial batch (and said)."""
        cfg = self.cfg
        workers = getattr(self.ex, "workers", 1)
        est = expected_generation_seconds(self._world_tasks(method, step, prog["policy"], [0])[0],
                                          cfg.popsize * cfg.episodes_per_candidate, workers)
        self.state.setdefault("estimates", {})[f"{method}|{step}"] = est
        self.report.say(f"{method} step {step}: a generation is {cfg.popsize} candidates x {cfg.episodes_per_candidate} "
                        f"episode(s) of {cfg.seconds:g} s: expected ~{est['expected_s']:.0f} s on {workers} worker(s) if "
                        f"none falls ({est['rounds']} batch(es) of {est['batch']} per worker; a trial batch of θ_i here: "
                        f"{est['step_ms']:.1f} ms per control step, {est['batch_fixed_s']:.2f} s per batch besides)")
        return est

    def _cma(self, method: str, step: int, prog: dict) -> None:
        cfg = self.cfg
        if prog.get("es") is None:
            self._start_cma(step, prog)
        es = prog["es"]
        est = self._estimate(method, step, prog)
        k = cfg.episodes_per_candidate
        while prog["gen"] < cfg.generations:
            gen = prog["gen"]
            t0 = time.perf_counter()
            X = es.ask()
            seeds = self._seeds(GENERATION, step, gen, n=k)
            thetas = [self.params_class.from_vector(x, clip=True).to_array() for x in X]
            res = self._map([t for th in thetas for t in self._world_tasks(method, step, th, seeds)], f"gen {gen}")
            fit = np.array([np.mean([r.fitness for r in res[i * k:(i + 1) * k]]) for i in range(len(X))])
            es.tell(X, list(-fit))
            wall = time.perf_counter() - t0
            self._record_generation(method, step, gen, thetas, res, fit, es, wall)
            if self.rerun:
                self._log_generation(method, step, gen, thetas, fit, seeds[0])
            prog["gen"] = gen + 1
            self._save()
            done = [g["wall_s"] for g in self.state["generations"] if g["method"] == method and g["step"] == step]
            self.report.say(f"{method} step {step}: generation {gen + 1}/{cfg.generations}: best {fit.max():.1f}, median "
                            f"{np.median(fit):.1f}, sigma {es.sigma:.3f} (measured {wall:.0f} s, expected "
                            f"~{est['expected_s']:.0f} s; step ETA {np.mean(done) * (cfg.generations - gen - 1):.0f} s)")

    def _record_generation(self, method, step, gen, thetas, res, fit, es, wall) -> None:
        """A generation's episodes and summary into the run's state (``evals.parquet``, ``generations.csv``)."""
        k = self.cfg.episodes_per_candidate
        for i, th in enumerate(thetas):
            for j in range(k):
                r = res[i * k + j]
                self.state["evals"].append({"method": method, "step": step, "gen": gen, "candidate": i, "seed": r.seed,
                                            "fitness": r.fitness, "speed_cm_s": r.speed_cm_s, "fell": bool(r.fell),
                                            **{f"theta.{n}": float(v) for n, v in zip(PARAM_NAMES, th)}})
        self.state["generations"].append({"method": method, "step": step, "gen": gen, "best": float(fit.max()),
                                          "median": float(np.median(fit)), "worst": float(fit.min()),
                                          "mean": float(fit.mean()), "sigma": float(es.sigma), "evals": len(res),
                                          "wall_s": wall})

    def _select(self, method: str, step: int, prog: dict) -> np.ndarray:
        """θ_{i+1}: the best of the CMA-ES mean, the best candidate and the incumbent θ_i in the
        training world, on ``select_episodes`` fresh seeds shared by the three (common random
        numbers). Keeping θ_i when neither beats it means a step the grounded sim cannot confirm
        changes nothing; re-evaluating on fresh seeds removes the best candidate's winner's curse."""
        es = prog["es"]
        names = ["CMA-ES mean", "best candidate", "incumbent θ_i"]
        cands = [self.params_class.from_vector(es.result.xfavorite, clip=True).to_array(),
                 self.params_class.from_vector(es.result.xbest, clip=True).to_array(), np.asarray(prog["policy"], dtype=float)]
        seeds = self._seeds(SELECTION, step, n=self.cfg.select_episodes)
        res = self._map([t for th in cands for t in self._world_tasks(method, step, th, seeds)], "select")
        n = len(seeds)
        scores = [float(np.mean([r.fitness for r in res[i * n:(i + 1) * n]])) for i in range(len(cands))]
        k = int(np.argmax(scores))
        self.report.say(f"{method} step {step}: selected the {names[k]} (fitness in the training world over {n} episodes: "
                        + ", ".join(f"{nm} {sc:.1f}" for nm, sc in zip(names, scores)) + ")")
        prog["select_scores"] = dict(zip(("mean", "best", "incumbent"), scores))
        return cands[k]

    # ---------------------------------------------------------------- evaluation
    def _evaluate(self, theta, step: int, label: str) -> dict:
        if self.cfg.eval_trials == 0:
            return {"trials": 0}
        res = self._map(self._real_tasks(theta, self._seeds(EVALUATION, step, n=self.cfg.eval_trials)), f"{label} real eval")
        if self.rerun:
            self._log_eval(label, step, theta)
        return {**summarize(res), "episodes": [{"seed": r.seed, "speed_cm_s": r.speed_cm_s, "fell": r.fell,
                                                "fall_reason": r.fall_reason, "fitness": r.fitness} for r in res]}

    def _record_step(self, method: str, step: int, theta, prog: dict) -> None:
        """Real trials of θ_{i+1}, its θ file and its Table I row; then the CMA-ES state is dropped."""
        theta = np.asarray(theta, dtype=float)
        ev = self._evaluate(theta, step, method)
        self.params_class.from_array(theta).save(os.path.join(self.run_dir, "thetas", f"{slug(method)}_step{step}.json"))
        self.state["rows"].append({"method": method, "step": step, **ev, "theta": theta.tolist(),
                                   "select_scores": prog.get("select_scores")})
        if ev["trials"]:
            self.report.say(f"{method} step {step}: real {ev['speed_mean']:.2f} ± {ev['speed_std']:.2f} cm/s, "
                            f"falls {ev['falls']}/{ev['trials']}")
        prog.update(es=None, gen=0)

    # ---------------------------------------------------------------- rerun hooks
    def _log_generation(self, method, step, gen, thetas, fit, seed) -> None:
        """Log the best, median and worst candidates of selected generations (first, every 5th, last)
        to ``rerun/``."""
        if not (gen == 0 or gen == self.cfg.generations - 1 or gen % 5 == 0):
            return
        order = np.argsort(fit)
        picks = {"best": order[-1], "median": order[len(order) // 2], "worst": order[0]}
        tasks = [self._world_tasks(method, step, thetas[i], [seed], record=True, meta={"world": name})[0]
                 for name, i in picks.items()]
        self._to_rrd(tasks, f"{slug(method)}_step{step}_gen{gen:03d}")

    def _log_eval(self, label, step, theta) -> None:
        seeds = self._seeds(EVALUATION, step, n=min(3, self.cfg.eval_trials))
        tasks = [t.replace(meta={"world": f"real seed {t.seed}"}) for t in self._real_tasks(theta, seeds, record=True)]
        self._to_rrd(tasks, f"{slug(label)}_step{step}_real_eval")

    def _to_rrd(self, tasks, name) -> None:
        from experiments.viz import log_rollouts_to_rrd  # lazy: rerun

        res = map_episodes(self.ex, tasks)
        recs = {r.recording[1]["world"]: Recording(*r.recording) for r in res}
        os.makedirs(os.path.join(self.run_dir, "rerun"), exist_ok=True)
        log_rollouts_to_rrd(recs, os.path.join(self.run_dir, "rerun", f"{name}.rrd"))

    # ---------------------------------------------------------------- driver
    def run(self, resume: bool = False, add_methods=()) -> OptimizeResult:
        """Run the optimization, or with ``resume`` continue the run saved in the run directory (its own
        settings; ``add_methods``: methods it does not have yet, added to it and run on its seeds, real
        grounding walks and identification, so a finished run grows without redoing anything).

        Raises:
            ValueError: a new run over a saved one, or a bad method in ``add_methods``.
            FileNotFoundError, CheckpointError: ``resume`` without a readable checkpoint.
        """
        t0 = time.perf_counter()
        if resume:
            self._resume(add_methods)
        else:
            self._start()
        if any(s.needs_identification for s in self.cfg.specs) and not self.state.get("identification"):
            self.state["identification"] = self.identification or identify(
                os.path.join(self.run_dir, "identified"), seed=self.cfg.seed, profile=self.cfg.profile,
                stochasticity=self.cfg.stochasticity, reporter=self.report)
            self._save()
        if not any(r["method"] == "theta0" for r in self.state["rows"]):
            self.state["rows"].append({"method": "theta0", "step": 0, **self._evaluate(self.state["theta0"], 0, "theta0")})
            self._save()
        for method in self.cfg.methods:  # Algorithm 1 per method (sgat.algorithm), checkpointed after every stage
            grounded = parse_world(method).grounded
            grounding_loop(self.state["progress"][method], self.cfg.grounding_steps,
                           ground=lambda i, theta, m=method, g=grounded: self._ground(m, i, theta) if g else None,
                           improve=lambda i, theta, model, prog, m=method: self._improve(m, i, prog),
                           evaluate=lambda i, theta, prog, m=method: self._record_step(m, i, theta, prog),
                           save=self._save)
        plot_progress(self.state["generations"], self.cfg.methods, os.path.join(self.run_dir, "fitness.png"))
        return dataclasses.replace(self.result(), wall_s=time.perf_counter() - t0)

    def _start(self) -> None:
        import cma  # lazy: cma

        if os.path.exists(self.state_path):
            raise ValueError(f"{self.run_dir!r} already holds a run; use --resume {self.run_dir} or another --out")
        self.cfg.validate()
        P = self.params_class
        theta0 = (P.load(self.cfg.params) if self.cfg.params else P.initial()).to_array()
        self.state = {"config": self.cfg.to_dict(), "cma_version": cma.__version__, "theta0": theta0.tolist(),
                      "rows": [], "evals": [], "generations": [],
                      "progress": {m: {**new_progress(theta0.tolist()), "es": None, "gen": 0} for m in self.cfg.methods}}
        self._write_config()
        self._save()

    def _resume(self, add_methods) -> None:
        self.state = self.load_state(self.run_dir)
        self.cfg = OptimizeConfig.from_dict(self.state["config"])
        self.report.say(f"resuming {self.run_dir}")
        new = [m for m in dict.fromkeys(parse_world(m).name for m in add_methods) if m not in self.cfg.methods]
        if new:
            cfg = dataclasses.replace(self.cfg, methods=self.cfg.methods + tuple(new))
            cfg.validate()
            self.cfg, self.state["config"] = cfg, cfg.to_dict()
            for m in new:
                self.state["progress"][m] = {**new_progress(self.state["theta0"]), "es": None, "gen": 0}
            self.report.say(f"adding method(s) {', '.join(new)} to {self.run_dir}")
            self._write_config()
            self._save()

    # ---------------------------------------------------------------- outputs
    def real_data(self) -> dict[str, RealData]:
        """Real data each method learned from: grounding walks (count, seconds of recording) and
        excitation logs of the identification (count, seconds)."""
        out = {}
        ident = self.state.get("identification") or {}
        for method in self.cfg.methods:
            used = self.state.get("real_used", {}).get(method, {})
            uses_id = parse_world(method).needs_identification
            out[method] = RealData(len(used), float(sum(used.values())), ident.get("logs", 0) if uses_id else 0,
                                   ident.get("seconds", 0.0) if uses_id else 0.0)
        return out

    def result(self) -> OptimizeResult:
        rows = [StepRow.from_dict({k: v for k, v in r.items() if k != "episodes"}) for r in self.state["rows"]]
        scored = [r for r in rows if r.method != "theta0" and r.trials]
        best = max(scored, key=lambda r: r.fitness_mean, default=None)
        return OptimizeResult(self.run_dir, self.cfg.robot, list(self.state["theta0"]), rows, best, self.real_data(),
                              format_table(self.state["rows"]), self.generation_times())

    def generation_times(self) -> list[GenerationTimes]:
        """Per method and grounding step: the CMA-ES generations' measured wall time (median and range
        [s]) beside the estimate made before them (:func:`experiments.runtime.batch.expected_generation_seconds`,
        none falling)."""
        out = []
        est = self.state.get("estimates", {})
        steps = dict.fromkeys((g["method"], g["step"]) for g in self.state.get("generations", []))
        for method, step in steps:
            wall = [g["wall_s"] for g in self.state["generations"] if (g["method"], g["step"]) == (method, step)]
            e = est.get(f"{method}|{step}")
            out.append(GenerationTimes(method, step, len(wall), float(np.median(wall)), float(min(wall)), float(max(wall)),
                                       None if e is None else float(e["expected_s"])))
        return out

    def _write_config(self) -> None:
        import yaml  # lazy: yaml

        _atomic_write(os.path.join(self.run_dir, "config.yaml"), yaml.safe_dump(self.cfg.to_dict(), sort_keys=False).encode())

    def _write_tables(self) -> None:
        gens = self.state.get("generations", [])
        if gens:
            buf = io.StringIO()
            w = csv.DictWriter(buf, fieldnames=list(gens[0]))
            w.writeheader()
            w.writerows(gens)
            _atomic_write(os.path.join(self.run_dir, "generations.csv"), buf.getvalue().encode())
        if self.state.get("evals"):
            with atomic_path(os.path.join(self.run_dir, "evals.parquet"), suffix=".parquet") as tmp:
                pq.write_table(pa.Table.from_pylist(self.state["evals"]), tmp)
        if self.state.get("rows"):
            from common.files import jsonable

            _atomic_write(os.path.join(self.run_dir, "results.json"),
                          json.dumps(jsonable({"rows": self.state["rows"], "real_data": self.real_data()}), indent=1).encode())
            _atomic_write(os.path.join(self.run_dir, "table.txt"), (format_table(self.state["rows"]) + "\n").encode())


__all__ = ["CheckpointError", "Optimizer", "identify", "slug", "summarize"]
