"""The gait optimization with grounding: Algorithm 1 of the SGAT paper for the NAO walk.

For each method and grounding step i (θ_0 = the walk engine's initial parameters):

1. **Real data** -- ``real_episodes`` walks with θ_i in the PyBullet real world on fresh terrain
   seeds (the same seeds for every method: paired comparisons).
2. **Sim data** -- ``sim_episodes`` walks with θ_i in the MuJoCo sim with Gaussian exploration
   noise on the leg targets, so the inverse model covers the states the forward model proposes.
3. **Grounding** -- fit ``f_real`` (SGAT: Gaussian NLL; GAT: MSE) and ``f_sim^-1``
   (``sgat.grounding.fit_transformer``) on the walks of θ_i and, with ``aggregate`` (default),
   of every earlier θ_j, as the GARAT/GAT code accumulates data across grounding steps; the
   transformer is saved under ``models/``.
4. **Policy improvement** -- CMA-ES (pycma) over the 16 normalized gait parameters, started at
   θ_i with step size ``sigma0`` and bounded to a trust region of ±``trust_region`` around θ_i
   (the grounding models were fitted on θ_i's data and do not hold far from it: without the
   bound, CMA-ES finds 30-50 cm/s gaits in the grounded sim that fall in every real trial), in
   the grounded sim (``sgat.GroundedEnv``); each candidate's fitness is the paper's reward
   (forward speed in cm/s, −15 if it fell) averaged over ``episodes_per_candidate`` episodes on
   seeds shared by the whole generation (common random numbers). θ_{i+1} is the best of the
   distribution mean, the best candidate and θ_i itself, re-evaluated on ``select_episodes``
   fresh seeds shared by the three.
5. **Evaluation** -- ``eval_trials`` walks of θ_{i+1} in the real world on fresh seeds (shared
   by all methods): speed mean ± std and falls, the paper's Table I.

The transformed action is blended with the agent's, ã = (1 - α) a + α g(s, a), with α = 0.5 by
default (the GAT/GARAT code's value; the paper's formula is α = 1), and the models are an ensemble
of 5 forward/inverse pairs fitted on bootstrap resamples, SGAT drawing one per episode
(``experiments.runtime.grounding.DEFAULT_GROUNDING``). With a single fit the grounded sim's verdict on
every gait flipped between "walks like the plain sim" and "everything falls" depending on which 4
real walks it was fitted on, and with α between 0.3 and 0.4; with the ensemble and sim walks whose
exploration noise does not topple the robot (0.02 rad) its fitness bias moves smoothly with α and
stays within a point across draws (``sgatwalk fidelity``, README "sgatwalk fidelity").

Methods: ``sgat``, ``gat``, ``none`` (CMA-ES in the plain sim), ``ane`` (action-noise envelope:
sim with Gaussian noise of ``ane_sigma`` on the leg targets; no real data), ``identified`` (CMA-ES in
the sim with the physics ``sgatwalk diagnose`` identified from excitation logs of the real world,
``sysid.identified``), ``hybrid`` (SGAT grounding on top of that identified sim: the transformer
learns only what the physics library could not name), ``real`` (CMA-ES directly in the real world:
the upper bound, and slow). ``identified`` and ``hybrid`` share one identification per run, done
first (``experiments.runtime.identify``: engine-gap calibration, fixed-base and stepping excitation logs of
the real world, two diagnoses); its logs count as real data in ``results.json``'s ``real_data``.
``sgat+ane``, ``gat+ane``, ``identified+ane`` and ``hybrid+ane`` train in the world of their base
method with the ANE's noise (``ane_sigma``) added to the leg targets it applies: the grounding is
the base method's (the same data, fit and seeds), only the world CMA-ES and the choice of θ_{i+1}
see is noisier (robust optimization in a grounded world; the action-noise envelope: Jakobi et al.,
ECAL 1995).

Everything random comes from ``numpy.random.SeedSequence`` keyed by (seed, purpose, step,
generation), never from worker state, so the executor does not change results, and a run killed
at any point and resumed with ``--resume`` ends with the same parameters as an uninterrupted run:
the checkpoint ``cma_state.pkl`` (the CMA-ES object with its own random stream, the progress of
every method, the rows written so far) is replaced atomically after every generation.
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
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from tqdm import tqdm

from common.defaults import CONTROL_DT, EPISODE_SECONDS
from common.files import atomic_path
from common.files import atomic_write_bytes as _atomic_write
from envs import Recording
from experiments.runtime.batch import expected_generation_seconds, map_episodes
from experiments.runtime.grounding import (DEFAULT_GROUNDING, DEFAULT_HISTORY, EXPLORATION_NOISE, HYBRID_GROUNDING, IDENTIFY_BUDGET_S,
                                   IDENTIFY_ROUNDS, REAL_WALKS, SIM_WALKS, fit_nao_grounding)
from experiments.runtime.identify import ENGINE_GAP_SEED, calibrate_engines, identify_real
from experiments.runtime.tasks import IDENTIFIED_CONFOUNDED
from sgat.algorithm import grounding_loop, new_progress
from sgat.grounding import GroundingConfig
from robots import ROBOT_NAMES, get_robot
from walk_engine import params_for
from walk_engine.params import NAMES as PARAM_NAMES

METHODS = ("sgat", "gat", "none", "ane", "identified", "hybrid", "real")
#: Methods that ground the sim with a learned action transformer.
GROUNDED = ("sgat", "gat", "hybrid")
#: A method name ``<base>+ane`` trains in ``<base>``'s world with the ANE noise (``ane_sigma``) added.
ANE_SUFFIX = "+ane"
#: The base methods that take :data:`ANE_SUFFIX` (the sim's own is ``ane``; the real world takes none).
ENVELOPED = ("sgat", "gat", "identified", "hybrid")


def base_method(method: str) -> str:
    """The method whose grounding and world ``method`` uses: ``"sgat"`` for ``"sgat+ane"``, else itself."""
    return method[:-len(ANE_SUFFIX)] if method.endswith(ANE_SUFFIX) else method


def method_names() -> tuple:
    """Every method name :class:`OptimizeConfig` accepts: :data:`METHODS` and ``<base>+ane``."""
    return METHODS + tuple(m + ANE_SUFFIX for m in ENVELOPED)


def uses_identification(method: str) -> bool:
    """Whether ``method`` trains in the identified sim (``identified``, ``hybrid``, and their ``+ane``)."""
    return base_method(method) in ("identified", "hybrid")


def default_methods(robot: str = "nao") -> tuple:
    """The methods ``sgatwalk optimize`` runs when none are named: ``("hybrid",)`` for the NAO (SGAT
    grounding on the identified sim: the fittest grounded method of Table I over five optimization
    seeds and the best grounding of the fidelity panel, README), ``("sgat",)`` for the other robots,
    whose physics the diagnosis does not identify."""
    return ("hybrid",) if robot == "nao" else ("sgat",)


STATE_FILE = "cma_state.pkl"


@dataclass
class OptimizeConfig:
    """Settings of one optimization run (written to ``config.yaml``)."""

    methods: tuple = default_methods()  # hybrid since the nineteenth round (sgat before)
    grounding_steps: int = 2
    real_episodes: int = REAL_WALKS
    sim_episodes: int = SIM_WALKS
    exploration_noise: float = EXPLORATION_NOISE
    popsize: int = 12
    generations: int = 30
    sigma0: float = 0.05
    trust_region: float = 0.15
    episodes_per_candidate: int = 1
    select_episodes: int = 8
    seconds: float = EPISODE_SECONDS
    eval_trials: int = 10
    profile: str = "real"
    grounding_state: str = "legs"
    history: int = DEFAULT_HISTORY
    command_history: int = DEFAULT_GROUNDING.command_history
    matched: bool = DEFAULT_GROUNDING.matched
    local_inverse: bool = DEFAULT_GROUNDING.local_inverse
    zero_init: bool = DEFAULT_GROUNDING.zero_init
    shadow: float = DEFAULT_GROUNDING.shadow_memory * CONTROL_DT  # τ [s] of the transformer's shadow state
    alpha: float = DEFAULT_GROUNDING.alpha
    hybrid_alpha: float = HYBRID_GROUNDING.alpha
    ensemble: int = DEFAULT_GROUNDING.ensemble
    inverse_command: bool = DEFAULT_GROUNDING.inverse_command
    hidden: tuple = DEFAULT_GROUNDING.hidden
    ane_sigma: float = 0.05
    #: identified / hybrid: also build in the contact terms confounded with the uneven ground
    #: (``experiments.runtime.tasks.IDENTIFIED_CONFOUNDED``)
    identified_confounded: bool = IDENTIFIED_CONFOUNDED
    #: identified / hybrid: screen/refit rounds of each diagnosis (``experiments.runtime.grounding.IDENTIFY_ROUNDS``)
    identify_rounds: int = IDENTIFY_ROUNDS
    model_epochs: int = DEFAULT_GROUNDING.max_epochs
    aggregate: bool = True
    seed: int = 0
    params: str | None = None
    robot: str = "nao"

    def validate(self) -> None:
        """Raises ValueError naming the bad setting."""
        if self.robot not in ROBOT_NAMES:
            raise ValueError(f"unknown robot {self.robot!r}; choose from {', '.join(ROBOT_NAMES)}")
        bad = [m for m in self.methods if m not in method_names()]
        if bad or not self.methods:
            raise ValueError(f"unknown method(s) {bad or '(none given)'}; choose from {', '.join(method_names())}")
        if len(set(self.methods)) != len(self.methods):
            raise ValueError(f"a method named twice in {list(self.methods)}")
        if self.robot != "nao" and any(uses_identification(m) for m in self.methods):
            raise ValueError("methods identified and hybrid model the NAO only (sgatwalk diagnose identifies the NAO)")
        for name in ("grounding_steps", "real_episodes", "sim_episodes", "popsize", "generations",
                     "episodes_per_candidate", "select_episodes", "history", "model_epochs", "ensemble"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if any(int(h) < 1 for h in self.hidden):
            raise ValueError(f"hidden layer sizes must be >= 1 (an empty list: linear models), got {list(self.hidden)}")
        if int(self.command_history) < 0:
            raise ValueError(f"command_history must be >= 0 (0: the paper's one-step forward model), got {self.command_history}")
        if not (np.isfinite(self.shadow) and self.shadow >= 0):
            raise ValueError(f"shadow must be a finite time >= 0 [s] (0: the paper's transformer), got {self.shadow}")
        if self.shadow > 0 and self.matched:
            raise ValueError("shadow works with the paper's transformer only, not with matched")
        if not 1 <= int(self.identify_rounds) <= 100:
            raise ValueError(f"identify_rounds must be in 1..100 (screen/refit rounds per diagnosis), got {self.identify_rounds}")
        if int(self.eval_trials) < 0:
            raise ValueError(f"eval_trials must be >= 0 (0: no real evaluation), got {self.eval_trials}")
        if self.popsize < 2:
            raise ValueError("popsize must be >= 2")
        if not (0 < self.sigma0 <= 1):
            raise ValueError(f"sigma0 must be in (0, 1] (normalized parameters), got {self.sigma0}")
        if not (0 < self.trust_region <= 1):
            raise ValueError(f"trust_region must be in (0, 1] (normalized half-width), got {self.trust_region}")
        if not (self.seconds > 0):
            raise ValueError(f"seconds must be positive, got {self.seconds}")
        if self.exploration_noise < 0 or self.ane_sigma < 0:
            raise ValueError("noise levels must be >= 0")
        for name in ("alpha", "hybrid_alpha"):
            if not (0 <= getattr(self, name) <= 1):
                raise ValueError(f"{name} must be in [0, 1], got {getattr(self, name)}")

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["methods"], d["hidden"] = list(self.methods), list(self.hidden)
        return d


def config_from_state(d: dict) -> OptimizeConfig:
    """The :class:`OptimizeConfig` a saved run state holds (``state["config"]``, :meth:`OptimizeConfig.to_dict`).

    A run saved before ``identified_confounded`` existed built the contact terms confounded with the
    ground into its identified sim (the default then): it resumes with them, as it began; one saved
    before ``identify_rounds`` existed diagnosed in two rounds, and resumes so.
    """
    return OptimizeConfig(**{"identified_confounded": True, "identify_rounds": 2, **d, "methods": tuple(d["methods"]),
                             "hidden": tuple(d["hidden"])})


PRESETS = {
    "quick": {},
    "paper": {"popsize": 150, "generations": 20, "seconds": 7.5, "grounding_steps": 2, "eval_trials": 10,
              "real_episodes": 10, "sim_episodes": 10, "episodes_per_candidate": 2},
}


# ------------------------------------------------------------------------------ helpers
def _seeds(cfg: OptimizeConfig, purpose: int, *keys: int, n: int) -> list[int]:
    ss = np.random.SeedSequence([cfg.seed, purpose, *keys])
    return [int(s) for s in ss.generate_state(n, dtype=np.uint32)]


def _theta_key(theta) -> str:
    return hashlib.sha1(np.asarray(theta, dtype=np.float64).tobytes()).hexdigest()[:12]


def summarize(results: list[dict]) -> dict:
    """Speed mean/std [cm/s], falls, mean fitness of a list of episode results."""
    speed = np.array([r["speed_cm_s"] for r in results])
    fit = np.array([r["fitness"] for r in results])
    return {"trials": len(results), "speed_mean": float(speed.mean()), "speed_std": float(speed.std(ddof=1)) if len(speed) > 1 else 0.0,
            "falls": int(sum(bool(r["fell"]) for r in results)), "fitness_mean": float(fit.mean())}


class CheckpointError(ValueError):
    """The run directory's checkpoint is unreadable or from another version of cma."""


class Optimizer:
    """Runs (or resumes) an optimization in ``run_dir`` with ``executor`` (see module docstring).

    Args:
        cfg: the settings (ignored on resume: the run's own config is used).
        run_dir: output directory (created).
        executor: an ``experiments.runtime.executors`` executor.
        progress: show tqdm bars (driver process only).
        log: a callable for one-line messages (default ``print``).
    """

    def __init__(self, cfg: OptimizeConfig, run_dir: str, executor, *, progress: bool = True, log=print,
                 rerun: bool = False):
        self.cfg, self.run_dir, self.ex, self.progress, self.log, self.rerun = cfg, run_dir, executor, progress, log, rerun
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
            FileNotFoundError: no checkpoint. CheckpointError: corrupted, or cma version differs.
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
        for prog in state["progress"].values():  # checkpoints from before sgat.algorithm: old key and stage names
            if "theta" in prog and "policy" not in prog:
                prog["policy"] = prog.pop("theta")
                prog["candidate"] = prog.pop("selected", None)
                prog["model"] = None
                prog["stage"] = {"fit": "ground", "cma": "improve", "eval": "evaluate"}.get(prog["stage"], prog["stage"])
        if state.get("cma_version") != cma.__version__:
            raise CheckpointError(f"{path!r} was written with cma {state.get('cma_version')}, this is "
                                  f"{cma.__version__}; CMA-ES states do not carry across versions")
        return state

    # ---------------------------------------------------------------- episodes
    def _tasks(self, world: str, theta, seeds, **kw) -> list[dict]:
        base = {"world": world, "theta": list(map(float, theta)), "seconds": self.cfg.seconds,
                "profile": self.cfg.profile}
        if self.cfg.robot != "nao":
            base["robot"] = self.cfg.robot
        return [{**base, "seed": s, **kw} for s in seeds]

    def _map(self, tasks: list[dict], desc: str) -> list[dict]:
        bar = None
        if self.progress:
            bar = tqdm(total=len(tasks), desc=desc, leave=False, disable=None)
        try:
            return map_episodes(self.ex, tasks, progress=(bar.update if bar else None))
        finally:
            if bar:
                bar.close()

    def _recordings(self, world: str, theta, seeds, **kw) -> list:
        """Recordings of θ in ``world`` on ``seeds``, cached as Parquet under ``data/``."""
        tag = f"{world}_{_theta_key(theta)}_n{kw.get('action_noise', 0):g}"
        paths = [os.path.join(self.run_dir, "data", f"{tag}_{s}.parquet") for s in seeds]
        todo = [s for s, p in zip(seeds, paths) if not os.path.exists(p)]
        if todo:
            res = self._map(self._tasks(world, theta, todo, record=True, **kw), f"{world} data")
            for s, r in zip(todo, res):
                cols, meta = r["recording"]
                Recording(cols, meta).to_parquet(os.path.join(self.run_dir, "data", f"{tag}_{s}.parquet"))
        return [Recording.from_parquet(p) for p in paths]

    # ---------------------------------------------------------------- the stages
    def grounding_config(self, method: str):
        """The model settings (``sgat.grounding.GroundingConfig``) of ``method``'s grounding steps."""
        cfg = self.cfg
        method = base_method(method)
        alpha = cfg.hybrid_alpha if method == "hybrid" else cfg.alpha
        return GroundingConfig(alpha=alpha, method="sgat" if method == "hybrid" else method, hidden=tuple(cfg.hidden),
                               ensemble=cfg.ensemble,
                               inverse_command=cfg.inverse_command, max_epochs=cfg.model_epochs,
                               command_history=int(cfg.command_history), matched=bool(cfg.matched),
                               local_inverse=bool(cfg.local_inverse), zero_init=bool(cfg.zero_init),
                               shadow_memory=float(cfg.shadow) / CONTROL_DT)

    def _fit(self, method: str, step: int, theta) -> str:
        cfg = self.cfg
        out = os.path.join(self.run_dir, "models", f"{method}_step{step}")
        if os.path.exists(os.path.join(out, "transformer.json")):
            return out
        real, sim = [], []
        sim_world, sim_kw = "sim", {"action_noise": cfg.exploration_noise}
        if base_method(method) == "hybrid":  # the transformer grounds the identified sim: its inverse model is of that sim
            sim_world, sim_kw["identified"] = "identified", self.state["identification"]["reports"]
            sim_kw["identified_confounded"] = bool(cfg.identified_confounded)
        for j, th in self._data_thetas(method, step, theta):
            real += self._recordings("real", th, _seeds(cfg, 1, j, n=cfg.real_episodes))
            sim += self._recordings(sim_world, th, _seeds(cfg, 2, j, n=cfg.sim_episodes), **sim_kw)
        used = self.state.setdefault("real_used", {}).setdefault(method, {})
        for r in real:
            used[f"{_theta_key(list(r.meta['params'].values()))}_{r.meta['seed']}"] = len(r) * r.meta["control_dt"]
        t0 = time.perf_counter()
        fit = fit_nao_grounding(real, sim, self.grounding_config(method), state=cfg.grounding_state,
                                history=cfg.history, seed=cfg.seed + step, robot=cfg.robot,
                                map_fn=self.ex.map)  # the ensemble's members side by side on the workers
        fit.transformer.save(out)
        self.log(f"[{method} step {step}] grounded on {fit.info['n_real']} real / {fit.info['n_sim']} sim transitions "
                 f"(forward val loss {fit.forward_report.val_loss:.3f}, inverse {fit.inverse_report.val_loss:.3f}, "
                 f"{time.perf_counter() - t0:.0f} s)")
        return out

    def _data_thetas(self, method: str, step: int, theta) -> list[tuple[int, np.ndarray]]:
        """(grounding step j, θ_{j-1}) pairs whose walks ground step ``step``: only θ_i's own with
        ``aggregate=False``; with ``aggregate=True`` (default) every earlier step's too, as the
        GARAT/GAT code accumulates its data across grounding steps (``rl_gat/gat.py``, Desai et al., NeurIPS 2020).
        Earlier steps' recordings are cached under ``data/``, so aggregation costs no new walks."""
        if not self.cfg.aggregate:
            return [(step, np.asarray(theta))]
        thetas = {0: np.asarray(self.state["theta0"])}
        for r in self.state["rows"]:
            if r["method"] == method and r["step"] >= 1:
                thetas[r["step"]] = np.asarray(r["theta"])
        return [(j, thetas[j - 1]) for j in range(1, step)] + [(step, np.asarray(theta))]

    def _world_kw(self, method: str, step: int) -> tuple[str, dict]:
        """The training world of ``method`` at grounding step ``step``: an ``experiments.runtime.tasks`` world
        name and the task keys that build it (a ``<base>+ane`` method: its base's, with ``action_noise``)."""
        world, kw = self._base_world_kw(method, step)
        if method.endswith(ANE_SUFFIX):
            kw["action_noise"] = self.cfg.ane_sigma
        return world, kw

    def _base_world_kw(self, method: str, step: int) -> tuple[str, dict]:
        base = base_method(method)
        if base in GROUNDED:
            kw = {"transformer": os.path.join(self.run_dir, "models", f"{method}_step{step}")}
            if base == "hybrid":
                kw.update(identified=self.state["identification"]["reports"],
                          identified_confounded=bool(self.cfg.identified_confounded))
            return "grounded", kw
        if base == "identified":
            return "identified", {"identified": self.state["identification"]["reports"],
                                  "identified_confounded": bool(self.cfg.identified_confounded)}
        if base == "ane":
            return "sim", {"action_noise": self.cfg.ane_sigma}
        return ("real" if base == "real" else "sim"), {}

    def _cma(self, method: str, step: int, prog: dict) -> None:
        import cma  # lazy: cma

        cfg = self.cfg
        world, kw = self._world_kw(method, step)
        if prog.get("es") is None:
            x0 = self.params_class.from_array(prog["policy"]).to_vector()
            r = cfg.trust_region  # the models are fitted on θ_i's data: search near θ_i
            lo, hi = np.clip(x0 - r, 0.0, 1.0), np.clip(x0 + r, 0.0, 1.0)
            opts = {"bounds": [lo.tolist(), hi.tolist()], "popsize": cfg.popsize, "verbose": -9, "verb_log": 0, "verb_disp": 0,
                    "randn": np.random.RandomState(_seeds(cfg, 3, step, n=1)[0]).randn, "tolflatfitness": 100}
            prog["es"] = cma.CMAEvolutionStrategy(x0, cfg.sigma0, opts)
            prog["gen"] = 0
        es = prog["es"]
        n_ep = cfg.popsize * cfg.episodes_per_candidate
        est = expected_generation_seconds(self._tasks(world, prog["policy"], [0], **kw)[0], n_ep,
                                          getattr(self.ex, "workers", 1))
        self.state.setdefault("estimates", {})[f"{method}|{step}"] = est
        self.log(f"[{method} step {step}] a generation is {cfg.popsize} candidates x {cfg.episodes_per_candidate} "
                 f"episode(s) of {cfg.seconds:g} s in the {world} world: expected ~{est['expected_s']:.0f} s on "
                 f"{getattr(self.ex, 'workers', 1)} worker(s) if none falls ({est['rounds']} batch(es) of {est['batch']} "
                 f"per worker; a trial batch of θ_i here: {est['step_ms']:.1f} ms per control step, "
                 f"{est['batch_fixed_s']:.2f} s per batch besides)")
        bar = None
        if self.progress:
            bar = tqdm(total=cfg.generations, initial=prog["gen"], desc=f"{method} step {step} CMA-ES", disable=None)
        while prog["gen"] < cfg.generations:
            gen = prog["gen"]
            t0 = time.perf_counter()
            X = es.ask()
            seeds = _seeds(cfg, 4, step, gen, n=cfg.episodes_per_candidate)
            thetas = [self.params_class.from_vector(x, clip=True).to_array() for x in X]
            tasks = [t for th in thetas for t in self._tasks(world, th, seeds, **kw)]
            res = self._map(tasks, f"gen {gen}")
            k = cfg.episodes_per_candidate
            fit = np.array([np.mean([r["fitness"] for r in res[i * k:(i + 1) * k]]) for i in range(len(X))])
            es.tell(X, list(-fit))
            wall = time.perf_counter() - t0
            for i, th in enumerate(thetas):
                for j in range(k):
                    r = res[i * k + j]
                    self.state["evals"].append({"method": method, "step": step, "gen": gen, "candidate": i, "seed": r["seed"],
                                                "fitness": r["fitness"], "speed_cm_s": r["speed_cm_s"], "fell": bool(r["fell"]),
                                                **{f"theta.{n}": float(v) for n, v in zip(PARAM_NAMES, th)}})
            self.state["generations"].append({"method": method, "step": step, "gen": gen, "best": float(fit.max()),
                                              "median": float(np.median(fit)), "worst": float(fit.min()),
                                              "mean": float(fit.mean()), "sigma": float(es.sigma), "evals": len(res),
                                              "wall_s": wall})
            if self.rerun:
                self._log_generation(method, step, gen, world, kw, thetas, fit, seeds[0])
            prog["gen"] = gen + 1
            self._save()
            if bar is not None and not bar.disable:
                bar.update(1)
                bar.set_postfix(best=f"{fit.max():.1f}", median=f"{np.median(fit):.1f}", sigma=f"{es.sigma:.3f}",
                                took=f"{wall:.0f}s (expected {est['expected_s']:.0f}s)")
            else:  # no terminal: a line per generation with elapsed time and an estimate of the rest
                done = [g["wall_s"] for g in self.state["generations"] if g["method"] == method and g["step"] == step]
                self.log(f"[{method} step {step}] generation {gen + 1}/{cfg.generations}: best {fit.max():.1f}, median "
                         f"{np.median(fit):.1f}, sigma {es.sigma:.3f} (measured {wall:.0f} s, expected ~{est['expected_s']:.0f} s; step ETA "
                         f"{np.mean(done) * (cfg.generations - gen - 1):.0f} s)")
        if bar:
            bar.close()

    def _select(self, method: str, step: int, prog: dict) -> np.ndarray:
        """θ_{i+1}: the best of the CMA-ES mean, the best candidate and the incumbent θ_i in the
        training world, on ``select_episodes`` fresh seeds shared by the three (common random
        numbers). Keeping θ_i when neither beats it means a step the grounded sim cannot confirm
        changes nothing; re-evaluating on fresh seeds removes the best candidate's winner's curse."""
        cfg = self.cfg
        es = prog["es"]
        world, kw = self._world_kw(method, step)
        names = ["CMA-ES mean", "best candidate", "incumbent θ_i"]
        cands = [self.params_class.from_vector(es.result.xfavorite, clip=True).to_array(),
                 self.params_class.from_vector(es.result.xbest, clip=True).to_array(), np.asarray(prog["policy"], dtype=float)]
        seeds = _seeds(cfg, 5, step, n=cfg.select_episodes)
        res = self._map([t for th in cands for t in self._tasks(world, th, seeds, **kw)], "select")
        n = len(seeds)
        scores = [float(np.mean([r["fitness"] for r in res[i * n:(i + 1) * n]])) for i in range(len(cands))]
        k = int(np.argmax(scores))
        self.log(f"[{method} step {step}] selected the {names[k]} (fitness in the training world over {n} episodes: "
                 + ", ".join(f"{nm} {sc:.1f}" for nm, sc in zip(names, scores)) + ")")
        prog["select_scores"] = dict(zip(("mean", "best", "incumbent"), scores))
        return cands[k]

    def _evaluate(self, theta, step: int, label: str) -> dict:
        if self.cfg.eval_trials == 0:
            return {"trials": 0}
        res = self._map(self._tasks("real", theta, _seeds(self.cfg, 6, step, n=self.cfg.eval_trials)), f"{label} real eval")
        if self.rerun:
            self._log_eval(label, step, theta)
        return {**summarize(res), "episodes": [{k: r[k] for k in ("seed", "speed_cm_s", "fell", "fall_reason", "fitness")}
                                               for r in res]}

    # ---------------------------------------------------------------- rerun hooks
    def _log_generation(self, method, step, gen, world, kw, thetas, fit, seed) -> None:
        """Log the best, median and worst candidates of selected generations (first, every
        5th, last) to ``rerun/``."""
        if not (gen == 0 or gen == self.cfg.generations - 1 or gen % 5 == 0):
            return
        order = np.argsort(fit)
        picks = {"best": order[-1], "median": order[len(order) // 2], "worst": order[0]}
        tasks = [self._tasks(world, thetas[i], [seed], record=True, meta={"world": f"{name}"}, **kw)[0]
                 for name, i in picks.items()]
        self._to_rrd(tasks, f"{method}_step{step}_gen{gen:03d}")

    def _log_eval(self, label, step, theta) -> None:
        seeds = _seeds(self.cfg, 6, step, n=min(3, self.cfg.eval_trials))
        tasks = [dict(t, meta={"world": f"real seed {t['seed']}"}) for t in self._tasks("real", theta, seeds, record=True)]
        self._to_rrd(tasks, f"{label}_step{step}_real_eval")

    def _to_rrd(self, tasks, name) -> None:
        try:
            from experiments.viz import log_rollouts_to_rrd  # lazy: optional (ImportError handled here)
        except ImportError as exc:  # pragma: no cover - visualization not available
            self.log(f"rerun logging skipped: {exc}")
            return
        res = map_episodes(self.ex, tasks)
        recs = {r["recording"][1]["world"]: Recording(*r["recording"]) for r in res}
        os.makedirs(os.path.join(self.run_dir, "rerun"), exist_ok=True)
        log_rollouts_to_rrd(recs, os.path.join(self.run_dir, "rerun", f"{name}.rrd"))

    # ---------------------------------------------------------------- driver
    def run(self, resume: bool = False, add_methods=()) -> dict:
        """Run the optimization, or with ``resume`` continue the run saved in the run directory (its own
        settings; ``add_methods``: methods it does not have yet, added to it and run on its seeds, real
        grounding walks and identification, so a finished run grows without redoing anything).

        Raises:
            ValueError: a new run over a saved one, or an unknown method in ``add_methods``.
            FileNotFoundError, CheckpointError: ``resume`` without a readable checkpoint.
        """
        import cma  # lazy: cma

        if resume:
            self.state = self.load_state(self.run_dir)
            self.cfg = config_from_state(self.state["config"])
            self.log(f"resuming {self.run_dir}")
            new = [m for m in dict.fromkeys(add_methods) if m not in self.cfg.methods]
            if new:
                cfg = dataclasses.replace(self.cfg, methods=self.cfg.methods + tuple(new))
                cfg.validate()
                self.cfg, self.state["config"] = cfg, cfg.to_dict()
                for m in new:
                    self.state["progress"][m] = {**new_progress(self.state["theta0"]), "es": None, "gen": 0}
                self.log(f"adding method(s) {', '.join(new)} to {self.run_dir}")
                self._write_config()
                self._save()
        else:
            if os.path.exists(self.state_path):
                raise ValueError(f"{self.run_dir!r} already holds a run; use --resume {self.run_dir} or another --out")
            theta0 = (self.params_class.load(self.cfg.params) if self.cfg.params else self.params_class.initial()).to_array()
            self.state = {"config": self.cfg.to_dict(), "cma_version": cma.__version__, "theta0": theta0.tolist(),
                          "rows": [], "evals": [], "generations": [],
                          "progress": {m: {**new_progress(theta0.tolist()), "es": None, "gen": 0}
                                       for m in self.cfg.methods}}
            self._write_config()
            self._save()
        cfg = self.cfg
        if any(uses_identification(m) for m in cfg.methods) and not self.state.get("identification"):
            self.state["identification"] = self._identify()
            self._save()
        if not any(r["method"] == "theta0" for r in self.state["rows"]):
            ev = self._evaluate(self.state["theta0"], 0, "theta0")
            self.state["rows"].append({"method": "theta0", "step": 0, **ev})
            self._save()
        for method in cfg.methods:  # Algorithm 1 per method (sgat.algorithm), checkpointed after every stage
            grounding_loop(self.state["progress"][method], cfg.grounding_steps,
                           ground=lambda i, theta, m=method: self._fit(m, i, theta) if base_method(m) in GROUNDED else None,
                           improve=lambda i, theta, model, prog, m=method: self._improve(m, i, prog),
                           evaluate=lambda i, theta, prog, m=method: self._record_step(m, i, theta, prog),
                           save=self._save)
        self._figure()
        return self.result()

    def _improve(self, method: str, step: int, prog: dict) -> list:
        """Policy improvement of a grounding step: CMA-ES in the training world, then the choice of
        θ_{i+1} (:meth:`_select`); the CMA-ES state lives in ``prog`` (``es``, ``gen``) so that a
        killed run resumes mid-generation loop."""
        self._cma(method, step, prog)
        return self._select(method, step, prog).tolist()

    def _record_step(self, method: str, step: int, theta, prog: dict) -> None:
        """Real trials of θ_{i+1}, its θ file and its Table I row; then the CMA-ES state is dropped."""
        theta = np.asarray(theta, dtype=float)
        ev = self._evaluate(theta, step, method)
        self.params_class.from_array(theta).save(os.path.join(self.run_dir, "thetas", f"{method}_step{step}.json"))
        self.state["rows"].append({"method": method, "step": step, **ev, "theta": theta.tolist(),
                                   "select_scores": prog.get("select_scores")})
        if ev["trials"]:
            self.log(f"[{method} step {step}] real: {ev['speed_mean']:.2f} ± {ev['speed_std']:.2f} cm/s, "
                     f"falls {ev['falls']}/{ev['trials']}")
        prog.update(es=None, gen=0)

    def _identify(self) -> dict:
        """Identify the real world once for ``identified`` and ``hybrid`` (``experiments.runtime.identify``)."""
        t0 = time.perf_counter()
        root = os.path.join(self.run_dir, "identified")
        self.log("[identify] engine-gap calibration and excitation logs of the real world, then two diagnoses")
        # the engine gap (PyBullet vs MuJoCo on the real world without its effects) is a constant of the
        # testbed, as in sgatwalk fidelity: the package ships it for the pinned engines and a run copies it
        # (a run saved before keeps the calibration of its own seed that it finds in its directory)
        cal = calibrate_engines(os.path.join(root, "calibration"), seed=ENGINE_GAP_SEED)
        res = identify_real(root, seed=_seeds(self.cfg, 8, n=1)[0] % 1_000_000, profile=self.cfg.profile, calibration=cal,
                            time_budget_s=IDENTIFY_BUDGET_S, rounds=self.cfg.identify_rounds)
        self.log(f"[identify] {len(res['effects'])} terms, uneven ground Sq {1000 * res['terrain_rms_height']:.2f} mm "
                 f"from {res['logs']} logs ({res['seconds']:.0f} s of recording; {time.perf_counter() - t0:.0f} s)"
                 + "".join(f"; WARNING: the {k} diagnosis ran out of its {IDENTIFY_BUDGET_S:g} s budget, so the identified "
                           f"world depends on this machine's speed" for k in res.get("time_budget_reached", [])))
        return res

    def real_data(self) -> dict:
        """Real data each method learned from: grounding walks (count, seconds of recording) and
        excitation logs of the identification (count, seconds)."""
        out = {}
        ident = self.state.get("identification") or {}
        for method in self.cfg.methods:
            used = self.state.get("real_used", {}).get(method, {})
            uses_id = uses_identification(method)
            out[method] = {"walks": len(used), "walk_seconds": float(sum(used.values())),
                           "excitation_logs": ident.get("logs", 0) if uses_id else 0,
                           "excitation_seconds": ident.get("seconds", 0.0) if uses_id else 0.0}
        return out

    # ---------------------------------------------------------------- outputs
    def result(self) -> dict:
        rows = [{k: v for k, v in r.items() if k not in ("episodes",)} for r in self.state["rows"]]
        scored = [r for r in rows if r["method"] != "theta0" and r.get("trials")]
        best = max(scored, key=lambda r: r["fitness_mean"], default=None)
        return {"run_dir": self.run_dir, "rows": rows, "best": best, "real_data": self.real_data(),
                "table": format_table(self.state["rows"]), "generation_s": self.generation_times()}

    def generation_times(self) -> list[dict]:
        """Per method and grounding step: the CMA-ES generations' measured wall time (median and range
        [s]) beside the estimate made before them (:func:`experiments.runtime.batch.expected_generation_seconds`,
        none falling; None for a step whose generations ran before estimates were kept)."""
        out = []
        est = self.state.get("estimates", {})
        steps = dict.fromkeys((g["method"], g["step"]) for g in self.state.get("generations", []))
        for method, step in steps:
            wall = [g["wall_s"] for g in self.state["generations"] if (g["method"], g["step"]) == (method, step)]
            e = est.get(f"{method}|{step}")
            out.append({"method": method, "step": step, "generations": len(wall), "median_s": float(np.median(wall)),
                        "min_s": float(min(wall)), "max_s": float(max(wall)),
                        "expected_s": None if e is None else float(e["expected_s"])})
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
            res = self.result()
            _atomic_write(os.path.join(self.run_dir, "results.json"),
                          json.dumps({"rows": self.state["rows"], "real_data": self.real_data()}, indent=1).encode())
            _atomic_write(os.path.join(self.run_dir, "table.txt"), (res["table"] + "\n").encode())

    def _figure(self) -> None:
        import matplotlib  # lazy: matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # lazy: matplotlib

        gens = self.state["generations"]
        if not gens:
            return
        fig, ax = plt.subplots(figsize=(8, 4.5))
        keys = sorted({(g["method"], g["step"]) for g in gens}, key=lambda k: (self.cfg.methods.index(k[0]), k[1]))
        offset = {}
        for m, s in keys:
            rows = [g for g in gens if g["method"] == m and g["step"] == s]
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
        with atomic_path(os.path.join(self.run_dir, "fitness.png"), suffix=".png") as tmp:
            fig.savefig(tmp, dpi=120)
        plt.close(fig)


def format_table(rows: list[dict]) -> str:
    """The paper's Table I: a row per method and grounding step (θ0 first)."""
    lines = [f"{'method':10s} {'step':>4s} {'speed [cm/s]':>16s} {'falls':>7s}", "-" * 40]
    for r in rows:
        if not r.get("trials"):
            continue
        name = "θ0" if r["method"] == "theta0" else r["method"].upper()
        step = "-" if r["method"] == "theta0" else str(r["step"])
        lines.append(f"{name:10s} {step:>4s} {r['speed_mean']:8.2f} ± {r['speed_std']:5.2f} "
                     f"{r['falls']:>3d}/{r['trials']:<3d}")
    return "\n".join(lines)
