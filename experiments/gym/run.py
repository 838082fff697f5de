"""Sim-to-NoisySim and Sim-to-NoisyReal on gymnasium MuJoCo with TRPO (SGAT paper §IV.B, Figs. 8-9).

One run ``r`` of the experiment, for a noise level ν of the "real" actuator:

1. **sim policy** -- TRPO from scratch in the sim (``sim_steps``), seed derived from r. It is
   shared by ``sim``, ``gat``, ``sgat`` and ``ane`` of run r (identical seeds).
2. ``sim`` -- the sim policy evaluated on real (the lower bound).
3. ``gat`` / ``sgat`` -- Algorithm 1 of the paper, ``grounding_steps`` times: run the current
   policy (stochastic) on real for ``real_transitions`` steps and in the sim with exploration
   noise for ``sim_transitions`` steps (data accumulate over grounding steps); fit f_real
   (GAT: MSE, SGAT: Gaussian NLL) and f_sim^-1 (``sgat.grounding.fit_transformer``); continue
   training the policy for ``grounded_steps`` in ``sgat.GroundedEnv(sim, g)``. GAT and SGAT of
   one run see identical real data at the first step (same policy, same seeds).
4. ``ane`` -- action-noise envelope: continue training the sim policy for ``grounded_steps`` in
   the sim with Gaussian action noise σ, for every σ of ``ane_grid``. The cell reports the σ
   with the best mean real return over runs -- **privileged tuning**: σ is selected by looking
   at the real world (as the paper did with its coarse grid search), no real data is trained on.
5. ``real`` -- TRPO from scratch on the real variant (``real_steps``): the upper bound (the
   paper's red dashed line).

Every policy is evaluated on the real variant with the deterministic (mean) action over
``eval_episodes`` episodes; episode seeds (initial state and actuator noise) are common to all
methods of a run (common random numbers). A cell is the mean ± standard error over runs.

Work is split into picklable tasks (:func:`run_task`) for ``experiments.runtime.executors``: first the
sim policies, then everything else. Each finished task's rows are appended to
``results.parquet`` (one row per (noise, method, run[, ANE σ]) evaluation), so an interrupted
sweep resumes by skipping finished cells; rows are only reused when the settings they depend on
(:meth:`GymConfig.fingerprint`) match. Policies are stored as ``.npz`` (the SB3 zip bytes and
the VecNormalize statistics; loaded with ``allow_pickle=False``).
``jobs.jsonl`` logs every finished job's wall and CPU time (the CPU time does not depend on
the machine's load, so it gives runtime estimates for other machines).

Inference in evaluation and data collection runs in NumPy (:class:`NumpyPolicy`, identical to
``model.predict``), about 20x cheaper per step than a torch call.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import hashlib
import importlib.metadata as md
import io
import json
import math
import os
import sys
import time
import types
import uuid
from pathlib import Path
from typing import Any, Callable

import numpy as np

from common.files import atomic_write_bytes as _atomic_write_bytes
from common.files import atomic_write_text
from experiments.gym.config import METHODS, NO_REAL_DATA, GymConfig
from experiments.gym.envs import make_env, set_state_from_obs
from experiments.runtime.progress import Reporter
from sgat.algorithm import grounding_loop, new_progress

# Seed purposes (the first key after the base seed).
_SIM_POLICY, _REAL_POLICY, _REAL_DATA, _SIM_DATA, _RETRAIN, _FIT, _EVAL, _HELDOUT, _GROUND = range(1, 10)

ROW_KEYS = ("env", "experiment", "noise", "method", "run", "ane_sigma", "return_mean", "return_std", "return_se",
            "ep_len", "episodes", "train_steps", "wall_s", "step_err_sim", "step_err_grounded", "fwd_val_loss",
            "inv_val_loss", "n_real", "sim_return", "cpu_s", "fingerprint", "finished_at")


def seed_of(base: int, *keys: int) -> int:
    """A 32-bit seed derived from ``base`` and integer ``keys`` (``numpy.random.SeedSequence``)."""
    return int(np.random.SeedSequence([int(base), *[int(k) for k in keys]]).generate_state(1, dtype=np.uint32)[0])


def noise_key(noise: float) -> int:
    """Integer seed component of a noise value (so a cell's seeds do not depend on the sweep)."""
    return int(round(float(noise) * 1e6))


def fingerprint_hash(cfg: GymConfig, method: str) -> str:
    """Short hash of :meth:`GymConfig.fingerprint` for ``method`` (or ``"sim_policy"``)."""
    return hashlib.sha1(json.dumps(cfg.fingerprint(method), sort_keys=True).encode()).hexdigest()[:12]


def _torch_one_thread() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch  # lazy: torch

    if torch.get_num_threads() != 1:
        torch.set_num_threads(1)


# --------------------------------------------------------------------------------------------
# Policies
# --------------------------------------------------------------------------------------------

def _policy_blob(model, venv) -> dict:
    """A trained policy as plain data: SB3 zip bytes + VecNormalize statistics (or None)."""
    from stable_baselines3.common.vec_env import VecNormalize  # lazy: stable_baselines3 (torch)

    buf = io.BytesIO()
    model.save(buf)
    vn = None
    if isinstance(venv, VecNormalize):
        vn = {"obs_mean": venv.obs_rms.mean.copy(), "obs_var": venv.obs_rms.var.copy(),
              "obs_count": float(venv.obs_rms.count), "ret_mean": np.atleast_1d(venv.ret_rms.mean).copy(),
              "ret_var": np.atleast_1d(venv.ret_rms.var).copy(), "ret_count": float(venv.ret_rms.count),
              "clip_obs": float(venv.clip_obs), "epsilon": float(venv.epsilon)}
    return {"zip": buf.getvalue(), "vecnorm": vn}


def save_policy(blob: dict, path: str | os.PathLike) -> str:
    """Write a policy blob as ``.npz`` atomically (no pickles)."""
    path = os.fspath(path)
    arrays = {"zip": np.frombuffer(blob["zip"], dtype=np.uint8)}
    if blob.get("vecnorm"):
        for k, v in blob["vecnorm"].items():
            arrays[f"vn_{k}"] = np.asarray(v, dtype=np.float64)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    _atomic_write_bytes(Path(path), buf.getvalue())
    return path


def load_policy(path: str | os.PathLike) -> dict:
    """Read what :func:`save_policy` wrote.

    Raises:
        FileNotFoundError: no such file. ValueError: not a policy file.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"no policy file at {path!r}")
    try:
        with np.load(path, allow_pickle=False) as z:
            blob = {"zip": z["zip"].tobytes(), "vecnorm": None}
            vn = {k[3:]: z[k] for k in z.files if k.startswith("vn_")}
    except Exception as exc:
        raise ValueError(f"{path!r} is not a readable policy file ({type(exc).__name__}: {exc})") from None
    if vn:
        blob["vecnorm"] = {k: (float(v) if v.ndim == 0 else v) for k, v in vn.items()}
    return blob


class NumpyPolicy:
    """The Gaussian MLP policy of an SB3 ``MlpPolicy`` (TRPO/PPO) in NumPy.

    ``act(obs, deterministic=True)`` equals ``model.predict(obs, deterministic=True)`` (mean
    action, clipped to the action bounds), with the VecNormalize observation statistics of the
    blob applied first. Stochastic actions draw from an explicit ``numpy.random.Generator``.
    """

    def __init__(self, blob: dict):
        from sb3_contrib import TRPO  # lazy: sb3_contrib (torch)

        model = TRPO.load(io.BytesIO(blob["zip"]), device="cpu")
        pol = model.policy
        lin = [m for m in pol.mlp_extractor.policy_net if hasattr(m, "weight")]
        acts = [type(m).__name__ for m in pol.mlp_extractor.policy_net if not hasattr(m, "weight")]
        if any(a != "Tanh" for a in acts):
            raise ValueError(f"NumpyPolicy supports tanh MLP policies, got {acts}")
        self.W = [m.weight.detach().numpy().astype(np.float64).T.copy() for m in lin]
        self.b = [m.bias.detach().numpy().astype(np.float64).copy() for m in lin]
        self.Wa = pol.action_net.weight.detach().numpy().astype(np.float64).T.copy()
        self.ba = pol.action_net.bias.detach().numpy().astype(np.float64).copy()
        self.std = np.exp(pol.log_std.detach().numpy().astype(np.float64))
        space = model.action_space
        self.low, self.high = np.asarray(space.low, np.float64), np.asarray(space.high, np.float64)
        vn = blob.get("vecnorm")
        if vn:
            self.obs_mean, self.obs_scale = vn["obs_mean"], np.sqrt(vn["obs_var"] + vn["epsilon"])
            self.clip_obs = vn["clip_obs"]
        else:
            self.obs_mean = None

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float64)
        if self.obs_mean is None:
            return obs
        return np.clip((obs - self.obs_mean) / self.obs_scale, -self.clip_obs, self.clip_obs)

    def mean(self, obs: np.ndarray) -> np.ndarray:
        """Mean action (unclipped) for observations (..., n_obs)."""
        h = self.normalize(obs).astype(np.float32).astype(np.float64)  # SB3 feeds float32
        for W, b in zip(self.W, self.b):
            h = np.tanh(h @ W + b)
        return h @ self.Wa + self.ba

    def act(self, obs: np.ndarray, deterministic: bool = True, rng: np.random.Generator | None = None) -> np.ndarray:
        mu = self.mean(obs)
        if not deterministic:
            if rng is None:
                raise ValueError("a stochastic action needs a numpy Generator")
            mu = mu + self.std * rng.standard_normal(mu.shape)
        return np.clip(mu, self.low, self.high)


def _keep_stream_grounded_env(env, transformer, ctrl_cost_weight):
    """``sgat.GroundedEnv`` whose SGAT sampling stream keeps running across unseeded resets.

    ``GroundedEnv.reset(seed=None)`` re-seeds the transformer with its fixed seed, so every episode
    of a vectorised trainer (which resets with no seed) would replay the same sampled noise
    sequence. This subclass restores the running generator after an unseeded reset.
    """
    from sgat.transformer import GroundedEnv  # lazy: sgat.transformer loads torch

    class _StreamingGroundedEnv(GroundedEnv):
        def reset(self, *, seed=None, options=None):
            rng = self.transformer.rng
            out = super().reset(seed=seed, options=options)
            if seed is None:
                self.transformer.rng = rng
            return out

    return _StreamingGroundedEnv(env, transformer, ctrl_cost_weight=ctrl_cost_weight)


def train_policy(cfg: GymConfig, env_fn: Callable[[int], Any], steps: int, seed: int, init: dict | None = None) -> dict:
    """TRPO (sb3-contrib) for ``steps`` env steps on ``env_fn(i)`` (i = 0..n_envs-1).

    ``init`` (a policy blob) warm-starts from an earlier policy, its VecNormalize statistics
    included; otherwise the policy starts from weights drawn from ``seed``. Torch runs on one
    thread on the CPU.

    Returns:
        the policy blob (see :func:`save_policy`).
    """
    _torch_one_thread()
    from sb3_contrib import TRPO  # lazy: sb3_contrib (torch)
    from stable_baselines3.common.logger import Logger  # lazy: stable_baselines3 (torch)
    from stable_baselines3.common.monitor import Monitor  # lazy: stable_baselines3 (torch)
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize  # lazy: stable_baselines3 (torch)

    hp = cfg.trpo_params()
    n_envs, normalize = int(hp.pop("n_envs")), bool(hp.pop("normalize"))
    venv = DummyVecEnv([(lambda i=i: Monitor(env_fn(i))) for i in range(n_envs)])
    if normalize:
        venv = VecNormalize(venv, gamma=hp["gamma"])
        vn = (init or {}).get("vecnorm")
        if vn:
            venv.obs_rms.mean, venv.obs_rms.var, venv.obs_rms.count = vn["obs_mean"].copy(), vn["obs_var"].copy(), vn["obs_count"]
            venv.ret_rms.mean, venv.ret_rms.var, venv.ret_rms.count = (float(np.ravel(vn["ret_mean"])[0]),
                                                                       float(np.ravel(vn["ret_var"])[0]), vn["ret_count"])
    if init is None:
        model = TRPO("MlpPolicy", venv, seed=int(seed), device="cpu", verbose=0, **hp)
    else:
        model = TRPO.load(io.BytesIO(init["zip"]), env=venv, device="cpu")
        model.set_random_seed(int(seed))
    if steps > 0:
        # a logger that writes nothing: SB3's default makes an empty /tmp/SB3-<date> folder per training
        model.set_logger(Logger(folder=None, output_formats=[]))
        model.learn(total_timesteps=int(steps))
    blob = _policy_blob(model, venv)
    venv.close()
    return blob


# --------------------------------------------------------------------------------------------
# Data, evaluation, one-step error
# --------------------------------------------------------------------------------------------

def collect(env, policy: NumpyPolicy, n: int, seed: int, *, deterministic: bool = False, explore: float = 0.0):
    """Run ``policy`` in ``env`` for ``n`` transitions (whole episodes, the last one cut).

    The logged action is the one handed to ``env`` (the commanded action: real-world actuator
    noise happens inside ``env`` and is part of the dynamics f_real must learn); ``explore`` > 0
    adds Gaussian exploration noise (share of the action half-range) *before* logging -- sim
    data for the inverse model, which must know the action actually applied.

    Returns:
        (obs_list, act_list): per episode, observations (T+1, n_obs) and actions (T, n_act).
    """
    rng = np.random.default_rng(seed)
    half = (policy.high - policy.low) / 2.0
    eps = []
    total, k = 0, 0
    ep_seeds = np.random.SeedSequence(seed).generate_state(max(1, n), dtype=np.uint32)
    while total < n:
        obs, _ = env.reset(seed=int(ep_seeds[k % len(ep_seeds)]) + k // len(ep_seeds))
        k += 1
        O, A = [obs], []
        done = False
        while not done and total < n:
            a = policy.act(obs, deterministic, rng)
            if explore > 0:
                a = np.clip(a + explore * half * rng.standard_normal(a.shape), policy.low, policy.high)
            obs, _, term, trunc, _ = env.step(a)
            A.append(np.array(a, dtype=np.float64))
            O.append(np.array(obs, dtype=np.float64))
            total += 1
            done = term or trunc
        eps.append((np.asarray(O), np.asarray(A)))
    return eps


def episodes_to_transitions(eps, spec):
    """Per-episode (obs (T+1, n), act (T, m)) -> ``sgat.grounding.Transitions``."""
    from sgat.grounding import Transitions, trajectory_transitions  # lazy: sgat.grounding loads torch

    parts = []
    for O, A in eps:
        if len(A) >= 1:
            parts.append(trajectory_transitions(O, np.concatenate([A, A[-1:]]), spec))
    return Transitions.concat(parts)


def evaluate(env, policy: NumpyPolicy, episodes: int, seed: int) -> dict:
    """Deterministic-policy return over ``episodes`` episodes (reset seeds from ``seed``).

    Returns:
        ``{"return_mean", "return_std", "return_se", "ep_len", "episodes", "returns"}``.
    """
    seeds = np.random.SeedSequence(seed).generate_state(episodes, dtype=np.uint32)
    rets, lens = [], []
    for s in seeds:
        obs, _ = env.reset(seed=int(s))
        R, T, done = 0.0, 0, False
        while not done:
            obs, r, term, trunc, _ = env.step(policy.act(obs, True))
            R += float(r)
            T += 1
            done = term or trunc
        rets.append(R)
        lens.append(T)
    rets = np.asarray(rets)
    std = float(rets.std(ddof=1)) if len(rets) > 1 else 0.0
    return {"return_mean": float(rets.mean()), "return_std": std, "return_se": std / math.sqrt(len(rets)),
            "ep_len": float(np.mean(lens)), "episodes": int(episodes), "returns": rets.tolist()}


def one_step_errors(task: str, transformer, eps) -> dict:
    """One-step next-state error against real transitions (GARAT appendix, Desai et al., NeurIPS 2020):
    put the plain sim into each real state s_t, apply a_t (plain) or g(s_t, a_t) (grounded), and
    compare the next state with the real s_{t+1}.

    Args:
        task: the task name (the plain sim is built from it).
        transformer: a fitted ``sgat.ActionTransformer`` with ``history == 1``.
        eps: real episodes from :func:`collect` (obs (T+1, n), commanded actions (T, m)).

    Returns:
        ``{"sim": mean L2 error, "grounded": mean L2 error, "n": transitions}``.
    """
    spec = transformer.spec
    sim = make_env(task).unwrapped
    sim.reset(seed=0)
    e_sim, e_gr = [], []
    for O, A in eps:
        for t in range(len(A)):
            s, a, s1 = O[t], A[t], O[t + 1]
            set_state_from_obs(sim, s)
            o_plain = sim.step(a)[0]
            applied = np.array(a, dtype=np.float64)
            applied[spec.action_index] = transformer.transform(spec.states(s), a[spec.action_index])
            set_state_from_obs(sim, s)
            o_gr = sim.step(applied)[0]
            e_sim.append(np.linalg.norm(o_plain - s1))
            e_gr.append(np.linalg.norm(o_gr - s1))
    sim.close()
    return {"sim": float(np.mean(e_sim)), "grounded": float(np.mean(e_gr)), "n": len(e_sim)}


# --------------------------------------------------------------------------------------------
# Tasks (run in executor workers)
# --------------------------------------------------------------------------------------------

def _cfg_from(d: dict) -> GymConfig:
    d = dict(d)
    for k in ("noise", "methods", "ane_grid", "hidden"):
        d[k] = tuple(d[k])
    return GymConfig(**d)


def _real_env_fn(cfg: GymConfig, noise: float):
    return lambda i=0: make_env(cfg.env, heavy=cfg.mismatch, noise=noise, pole_factor=cfg.pole_factor,
                                mass_factor=cfg.mass_factor)


def _row(cfg: GymConfig, noise: float, method: str, run: int, ev: dict, **extra) -> dict:
    row = {k: math.nan for k in ROW_KEYS}
    row.update(env=cfg.env, experiment=cfg.experiment, noise=float(noise), method=method, run=int(run),
               fingerprint=fingerprint_hash(cfg, method), finished_at=time.strftime("%Y-%m-%dT%H:%M:%S"))
    row.update({k: ev[k] for k in ("return_mean", "return_std", "return_se", "ep_len", "episodes")})
    row.update(extra)
    return _normalize_row(row)


def _eval_real(cfg: GymConfig, policy: NumpyPolicy, noise: float, run: int) -> dict:
    env = _real_env_fn(cfg, noise)()
    try:
        return evaluate(env, policy, cfg.eval_episodes, seed_of(cfg.seed, _EVAL, noise_key(noise), run))
    finally:
        env.close()


def _task_sim_policy(cfg: GymConfig, task: dict) -> dict:
    r = task["run"]
    t0 = time.perf_counter()
    blob = train_policy(cfg, lambda i=0: make_env(cfg.env), cfg.sim_steps, seed_of(cfg.seed, _SIM_POLICY, r))
    wall = time.perf_counter() - t0
    pol = NumpyPolicy(blob)
    env = make_env(cfg.env)
    sim_ev = evaluate(env, pol, cfg.eval_episodes, seed_of(cfg.seed, _EVAL, 0, r))
    env.close()
    return {"kind": "sim_policy", "run": r, "policy": blob, "wall_s": wall, "sim_return": sim_ev["return_mean"], "rows": []}


def _task_real(cfg: GymConfig, task: dict) -> dict:
    r, noise = task["run"], task["noise"]
    t0 = time.perf_counter()
    blob = train_policy(cfg, _real_env_fn(cfg, noise), cfg.real_steps, seed_of(cfg.seed, _SIM_POLICY, r))
    wall = time.perf_counter() - t0
    ev = _eval_real(cfg, NumpyPolicy(blob), noise, r)
    row = _row(cfg, noise, "real", r, ev, train_steps=cfg.real_steps, wall_s=wall)
    return {"kind": "real", "run": r, "noise": noise, "policy": blob, "rows": [row]}


def _task_sim(cfg: GymConfig, task: dict) -> dict:
    r = task["run"]
    pol = NumpyPolicy(task["init_policy"])
    rows = []
    for noise in task["noises"]:
        t0 = time.perf_counter()
        ev = _eval_real(cfg, pol, noise, r)
        rows.append(_row(cfg, noise, "sim", r, ev, train_steps=cfg.sim_steps, wall_s=time.perf_counter() - t0,
                         sim_return=task.get("sim_return", math.nan)))
    return {"kind": "sim", "run": r, "rows": rows}


def _task_ane(cfg: GymConfig, task: dict) -> dict:
    r, sigma = task["run"], task["ane_sigma"]
    t0 = time.perf_counter()
    blob = task.get("trained_policy")  # stored by an earlier sweep that evaluated other noise values
    if blob is None:
        blob = train_policy(cfg, lambda i=0: make_env(cfg.env, noise=sigma), cfg.grounded_steps * cfg.grounding_steps,
                            seed_of(cfg.seed, _RETRAIN, r, 0), init=task["init_policy"])
    wall = time.perf_counter() - t0
    pol = NumpyPolicy(blob)
    rows = [_row(cfg, noise, "ane", r, _eval_real(cfg, pol, noise, r), ane_sigma=float(sigma),
                 train_steps=cfg.sim_steps + cfg.grounded_steps * cfg.grounding_steps, wall_s=wall)
            for noise in task["noises"]]
    return {"kind": "ane", "run": r, "policy": blob, "rows": rows}


def ground_and_train(cfg: GymConfig, method: str, noise: float, run: int, sim_policy: dict,
                     log: Callable[[str], None] | None = None) -> dict:
    """GAT or SGAT for one (noise, run): ``grounding_steps`` x (collect, fit, re-train).

    Returns:
        ``{"policy": blob, "fit": last GroundingFit, "errors": one-step errors of the last
        transformer on held-out real data, "n_real": real transitions used}``.
    """
    from sgat.grounding import Transitions, fit_transformer  # lazy: sgat.grounding loads torch
    from sgat.transformer import ActionTransformer, GroundingSpec  # lazy: sgat.transformer loads torch

    real_env = _real_env_fn(cfg, noise)()
    sim_env = make_env(cfg.env)
    spec = GroundingSpec.full(sim_env, history=1)
    nk = noise_key(noise)
    real_parts, sim_parts = [], []
    fits = []
    fit_kwargs = {"max_epochs": cfg.model_epochs, "patience": cfg.model_patience, "lr": cfg.model_lr,
                  "batch_size": cfg.model_batch}

    def ground(i, policy):  # collect real and explored sim data with π_i, fit on all data so far
        g = i - 1
        pol = NumpyPolicy(policy)
        real_eps = collect(real_env, pol, cfg.real_transitions, seed_of(cfg.seed, _REAL_DATA, nk, run, g))
        sim_eps = collect(sim_env, pol, cfg.sim_transitions, seed_of(cfg.seed, _SIM_DATA, run, g),
                          explore=cfg.explore_sigma)
        real_parts.append(episodes_to_transitions(real_eps, spec))
        sim_parts.append(episodes_to_transitions(sim_eps, spec))
        fits.append(fit_transformer(Transitions.concat(real_parts), Transitions.concat(sim_parts), spec, method=method,
                                    hidden=cfg.hidden, alpha=cfg.alpha, seed=seed_of(cfg.seed, _FIT, nk, run, g),
                                    fit_kwargs=fit_kwargs))
        return fits[-1]

    def improve(i, policy, fit, progress):  # TRPO in the grounded sim, warm-started from π_i
        g = i - 1
        tr = fit.transformer
        ground_seed = seed_of(cfg.seed, _GROUND, nk, run, g)

        def env_fn(k, tr=tr, ground_seed=ground_seed):
            t_k = ActionTransformer(spec, tr.forward, tr.inverse, method=tr.method, alpha=tr.alpha,
                                    seed=seed_of(ground_seed, k))
            return _keep_stream_grounded_env(make_env(cfg.env), t_k, cfg.ctrl_cost_weight)

        return train_policy(cfg, env_fn, cfg.grounded_steps, seed_of(cfg.seed, _RETRAIN, run, g), init=policy)

    def evaluate(i, policy, progress):
        if log:
            log(f"{method} noise {noise:g} run {run}: grounding step {i}/{cfg.grounding_steps} done")

    policy = grounding_loop(new_progress(sim_policy), cfg.grounding_steps, ground=ground, improve=improve,
                            evaluate=evaluate)["policy"]
    fit = fits[-1] if fits else None
    held = collect(real_env, NumpyPolicy(sim_policy), min(2000, cfg.real_transitions),
                   seed_of(cfg.seed, _HELDOUT, nk, run))
    tr_eval = ActionTransformer(spec, fit.transformer.forward, fit.transformer.inverse, method=method,
                                alpha=cfg.alpha, seed=seed_of(cfg.seed, _HELDOUT, nk, run, 1))
    errors = one_step_errors(cfg.env, tr_eval, held)
    real_env.close()
    sim_env.close()
    return {"policy": policy, "fit": fit, "errors": errors, "n_real": sum(len(p) for p in real_parts)}


def _task_ground(cfg: GymConfig, task: dict) -> dict:
    r, noise, method = task["run"], task["noise"], task["method"]
    t0 = time.perf_counter()
    res = ground_and_train(cfg, method, noise, r, task["init_policy"])
    wall = time.perf_counter() - t0
    ev = _eval_real(cfg, NumpyPolicy(res["policy"]), noise, r)
    fit = res["fit"]
    row = _row(cfg, noise, method, r, ev, train_steps=cfg.sim_steps + cfg.grounded_steps * cfg.grounding_steps,
               wall_s=wall, step_err_sim=res["errors"]["sim"], step_err_grounded=res["errors"]["grounded"],
               fwd_val_loss=fit.forward_report.val_loss, inv_val_loss=fit.inverse_report.val_loss,
               n_real=res["n_real"])
    return {"kind": method, "run": r, "noise": noise, "policy": res["policy"], "rows": [row]}


_TASKS = {"sim_policy": _task_sim_policy, "real": _task_real, "sim": _task_sim, "ane": _task_ane,
          "gat": _task_ground, "sgat": _task_ground}


def run_task(task: dict) -> dict:
    """Run one job of a sweep (a picklable dict; see :func:`plan_tasks`) in this process.

    If the task names a ``cell_dir`` (local executors), its rows are also written there as a
    Parquet file as soon as it finishes, so an interrupted sweep keeps them; ``policy_path``
    likewise saves a trained policy.
    """
    _torch_one_thread()
    cfg = _cfg_from(task["cfg"])
    c0, w0 = time.process_time(), time.perf_counter()
    out = _TASKS[task["kind"]](cfg, task)
    out["cpu_s"], out["job_wall_s"] = time.process_time() - c0, time.perf_counter() - w0
    for row in out["rows"]:
        row["cpu_s"] = out["cpu_s"]  # the whole job's CPU time (ANE/sim: shared by its rows)
    if task.get("policy_path") and out.get("policy") is not None:
        save_policy(out["policy"], task["policy_path"])
    if task.get("cell_dir") and out["rows"]:
        write_rows(Path(task["cell_dir"]) / f"{task['kind']}_{uuid.uuid4().hex[:12]}.parquet", out["rows"])
    return out


# --------------------------------------------------------------------------------------------
# Results table
# --------------------------------------------------------------------------------------------

def _normalize_row(r: dict) -> dict:
    out = {k: r.get(k, math.nan) for k in ROW_KEYS}
    for k in ("run", "episodes", "n_real", "train_steps"):
        v = out[k]
        out[k] = 0 if v is None or (isinstance(v, float) and math.isnan(v)) else int(v)
    for k in ROW_KEYS:
        if k not in ("env", "experiment", "method", "fingerprint", "finished_at", "run", "episodes", "n_real",
                     "train_steps"):
            v = out[k]
            out[k] = math.nan if v is None else float(v)
    return out


def write_rows(path: Path, rows: list[dict]) -> None:
    """Write result rows as one Parquet file (atomic)."""
    import pyarrow as pa  # lazy: pyarrow
    import pyarrow.parquet as pq  # lazy: pyarrow

    table = pa.Table.from_pylist([_normalize_row(r) for r in rows])
    buf = io.BytesIO()
    pq.write_table(table, buf)
    _atomic_write_bytes(Path(path), buf.getvalue())


def read_rows(path: Path) -> list[dict]:
    """Rows of a results Parquet file ([] if absent).

    Raises:
        ValueError: the file is not a readable results table.
    """
    import pyarrow.parquet as pq  # lazy: pyarrow

    path = Path(path)
    if not path.exists():
        return []
    try:
        rows = pq.read_table(path).to_pylist()
    except Exception as exc:
        raise ValueError(f"{path} is not a readable results table ({type(exc).__name__}: {exc})") from None
    missing = [k for k in ("noise", "method", "run", "fingerprint") if rows and k not in rows[0]]
    if missing:
        raise ValueError(f"{path} lacks column(s) {', '.join(missing)}")
    return [_normalize_row(r) for r in rows]


def row_key(r: dict) -> tuple:
    s = r.get("ane_sigma", math.nan)
    s = -1.0 if s is None or (isinstance(s, float) and math.isnan(s)) else round(float(s), 9)
    return (r["fingerprint"], round(float(r["noise"]), 9), r["method"], int(r["run"]), s)


class ResultTable:
    """``results.parquet`` of a sweep directory plus the ``cells/`` files workers leave behind.

    ``append`` rewrites the table atomically (it is small: one row per evaluated cell);
    duplicates of a key keep the first row.
    """

    def __init__(self, out: Path):
        self.out = Path(out)
        self.path = self.out / "results.parquet"
        self.cells = self.out / "cells"
        self.rows = read_rows(self.path)
        self._keys = {row_key(r) for r in self.rows}
        self.merge_cells()

    def append(self, rows: list[dict]) -> int:
        new = []
        for r in rows:
            r = _normalize_row(r)
            k = row_key(r)
            if k not in self._keys:
                self._keys.add(k)
                new.append(r)
        if new:
            self.rows.extend(new)
            write_rows(self.path, self.rows)
        return len(new)

    def merge_cells(self) -> int:
        if not self.cells.is_dir():
            return 0
        files = sorted(self.cells.glob("*.parquet"))
        rows = []
        for f in files:
            try:
                rows += read_rows(f)
            except ValueError:
                print(f"gym: ignoring unreadable cell file {f}", file=sys.stderr)
        n = self.append(rows)
        for f in files:
            f.unlink(missing_ok=True)
        return n

    def done(self, cfg: GymConfig, noise: float, method: str, run: int, ane_sigma: float = math.nan) -> bool:
        """Is the cell (noise, method, run[, ANE σ]) of these settings in the table?"""
        return row_key({"fingerprint": fingerprint_hash(cfg, method), "noise": noise, "method": method, "run": run,
                        "ane_sigma": ane_sigma}) in self._keys

    def current(self, cfg: GymConfig) -> list[dict]:
        """The rows computed with ``cfg``'s settings, of its runs 0 .. ``cfg.runs`` - 1 (any noise,
        method): a sweep resumed with more runs leaves a summary of fewer runs what it was."""
        fps = {m: fingerprint_hash(cfg, m) for m in METHODS}
        return [r for r in self.rows if fps.get(r["method"]) == r["fingerprint"] and int(r["run"]) < cfg.runs]


# --------------------------------------------------------------------------------------------
# Planning and running a sweep
# --------------------------------------------------------------------------------------------

def _policy_path(out: Path, cfg: GymConfig, task: dict) -> Path:
    """Where the policy a task trains is stored: ``policies/<fingerprint>/<name>.npz``."""
    kind, r = task["kind"], task["run"]
    if kind == "sim_policy":
        fp, name = fingerprint_hash(cfg, "sim_policy"), f"sim_r{r}"
    elif kind == "ane":
        fp, name = fingerprint_hash(cfg, "ane"), f"ane_s{task['ane_sigma']:g}_r{r}"
    else:
        fp, name = fingerprint_hash(cfg, kind), f"{kind}_n{task['noise']:g}_r{r}"
    return out / "policies" / fp / f"{name}.npz"


def plan_tasks(cfg: GymConfig, table: ResultTable) -> dict:
    """The jobs still to do: ``{"sim_runs": [r...], "second": [task dicts without policies]}``.

    ``sim_runs`` are the runs whose sim policy is needed (some sim/gat/sgat/ane cell of the run
    is missing); ``second`` holds real, sim, gat, sgat and ane jobs, longest first.
    """
    ms = cfg.methods
    second, sim_runs = [], []
    for r in range(cfg.runs):
        need_sim = False
        if "real" in ms:
            for nz in cfg.noise:
                if not table.done(cfg, nz, "real", r):
                    second.append({"kind": "real", "run": r, "noise": nz, "cost": cfg.real_steps})
        if "sim" in ms:
            todo = [nz for nz in cfg.noise if not table.done(cfg, nz, "sim", r)]
            if todo:
                need_sim = True
                second.append({"kind": "sim", "run": r, "noises": todo, "cost": 0})
        for m in ("gat", "sgat"):
            if m in ms:
                for nz in cfg.noise:
                    if not table.done(cfg, nz, m, r):
                        need_sim = True
                        second.append({"kind": m, "method": m, "run": r, "noise": nz,
                                       "cost": cfg.grounded_steps * cfg.grounding_steps + 1})
        if "ane" in ms:
            for s in cfg.ane_grid:
                todo = [nz for nz in cfg.noise if not table.done(cfg, nz, "ane", r, s)]
                if todo:
                    need_sim = True
                    second.append({"kind": "ane", "run": r, "ane_sigma": s, "noises": todo,
                                   "cost": cfg.grounded_steps * cfg.grounding_steps})
        if need_sim:
            sim_runs.append(r)
    second.sort(key=lambda t: -t["cost"])  # longest first: better packing on a pool
    return {"sim_runs": sim_runs, "second": second}


def _execute(executor, tasks: list[dict], table: ResultTable, local: bool, bar, on_result=None) -> list[dict]:
    """Run tasks; append their rows as they become available (local: worker cell files; Ray:
    chunks of 2x the worker count)."""
    results = []
    if not tasks:
        return results
    step = len(tasks) if local else max(1, 2 * int(getattr(executor, "workers", 1)))
    for k in range(0, len(tasks), step):
        chunk = tasks[k:k + step]
        out = executor.map(run_task, chunk, progress=(lambda n: bar.update(n)) if bar is not None else None)
        for res, t in zip(out, chunk):
            table.append(res["rows"])
            _log_job(table.out / "jobs.jsonl", t, res)
            if on_result:
                on_result(res, t)
        results += out
    table.merge_cells()
    return results


def _log_job(path: Path, task: dict, res: dict) -> None:
    cfg = task["cfg"]
    rec = {"kind": task["kind"], "run": task.get("run"), "noise": task.get("noise"), "noises": task.get("noises"),
           "ane_sigma": task.get("ane_sigma"), "env": cfg["env"], "wall_s": res.get("job_wall_s"),
           "cpu_s": res.get("cpu_s"), "at": time.strftime("%Y-%m-%dT%H:%M:%S"),
           "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None}
    with open(path, "a") as f:
        f.write(json.dumps(rec) + "\n")


def run_sweep(cfg: GymConfig, out: str | os.PathLike, executor, *, reporter: Reporter | None = None,
              log: Callable[..., None] = print) -> dict:
    """Run (or resume) a sweep into directory ``out``; write the table, summary and figure.

    ``reporter`` counts the jobs (a bar in a terminal, a line with the count and an ETA otherwise;
    default: quiet).

    Returns:
        ``{"summary": [...], "paired": [...] (:func:`paired_differences`), "table": text, "files": {...},
        "new_rows": n, "fingerprints": {...}, "wall_s": s, "tasks": n}``.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    fps = {m: fingerprint_hash(cfg, m) for m in ("sim_policy", *cfg.methods)}
    _write_json(out / "config.json", {**cfg.to_dict(), "fingerprints": fps, "versions": _versions()})
    table = ResultTable(out)
    n0 = len(table.rows)
    plan = plan_tasks(cfg, table)
    local = getattr(executor, "name", "serial") in ("serial", "process")
    cfg_d = dataclasses.asdict(cfg)
    t0 = time.perf_counter()
    n_tasks = len(plan["second"]) + len(plan["sim_runs"])
    reporter = reporter or Reporter.quiet()
    reporter.say(f"{cfg.env} {cfg.experiment}: {n_tasks} jobs to run or load ({len(plan['sim_runs'])} sim policies "
                 f"first), noise {', '.join(f'{v:g}' for v in cfg.noise)}, {cfg.runs} runs per cell")
    with contextlib.ExitStack() as counting:
        bar = types.SimpleNamespace(update=counting.enter_context(reporter.count(n_tasks, "jobs")))
        cell_dir = str(table.cells) if local else None

        # 1. sim policies (reuse stored ones)
        sim = {}
        todo = []
        for r in plan["sim_runs"]:
            t = {"kind": "sim_policy", "run": r, "cfg": cfg_d}
            p = _policy_path(out, cfg, t)
            if p.exists():
                sim[r] = load_policy(p)
                bar.update(1)
            else:
                todo.append({**t, "policy_path": str(p) if local else None})
        sim_returns = {}

        def keep(res, t):
            if res.get("policy") is not None:
                p = _policy_path(out, cfg, t)
                if not p.exists():
                    save_policy(res["policy"], p)
            if res["kind"] == "sim_policy":
                sim[res["run"]] = res["policy"]
                sim_returns[res["run"]] = res["sim_return"]

        _execute(executor, todo, table, local, bar, keep)

        # 2. everything else
        tasks = []
        for t in plan["second"]:
            t = {**t, "cfg": cfg_d, "cell_dir": cell_dir}
            if t["kind"] != "sim":
                t["policy_path"] = str(_policy_path(out, cfg, t)) if local else None
            if t["kind"] != "real":
                t["init_policy"] = sim[t["run"]]
            if t["kind"] == "ane" and _policy_path(out, cfg, t).exists():
                t["trained_policy"] = load_policy(_policy_path(out, cfg, t))
            if t["kind"] == "sim":  # the sim policy's own return (unknown for a policy trained before a resume)
                t["sim_return"] = sim_returns.get(t["run"], math.nan)
            tasks.append(t)

        _execute(executor, tasks, table, local, bar, keep)
    wall = time.perf_counter() - t0
    rows = table.current(cfg)
    summary = summarize(rows, cfg)
    paired = paired_differences(rows, cfg)
    text = format_table(summary, cfg, paired)
    fig_path = out / f"gym_{cfg.env}_{cfg.experiment}.png"
    if summary:
        plot_bars(summary, cfg, fig_path)
    _write_text(out / "table.txt", text + "\n")
    write_summary_csv(summary, out / "summary.csv")
    return {"summary": summary, "paired": paired, "table": text, "new_rows": len(table.rows) - n0, "tasks": n_tasks,
            "fingerprints": fps, "wall_s": wall,
            "files": {"results": str(table.path), "summary": str(out / "summary.csv"), "table": str(out / "table.txt"),
                      "figure": str(fig_path) if summary else None, "config": str(out / "config.json")}}


def _versions() -> dict:
    v = {}
    for p in ("sb3-contrib", "stable-baselines3", "gymnasium", "mujoco", "torch", "numpy"):
        try:
            v[p] = md.version(p)
        except md.PackageNotFoundError:  # pragma: no cover
            v[p] = None
    return v


def _write_json(path: Path, obj) -> None:
    _atomic_write_bytes(path, (json.dumps(obj, indent=1, default=str) + "\n").encode())


def _write_text(path: Path, text: str) -> None:
    atomic_write_text(path, text)


# --------------------------------------------------------------------------------------------
# Summary, table, figure
# --------------------------------------------------------------------------------------------

def _mean_se(x) -> tuple[float, float]:
    x = np.asarray(x, dtype=float)
    if len(x) == 0:
        return math.nan, math.nan
    se = float(x.std(ddof=1) / math.sqrt(len(x))) if len(x) > 1 else math.nan
    return float(x.mean()), se


def summarize(rows: list[dict], cfg: GymConfig) -> list[dict]:
    """One entry per (noise, method): mean ± s.e. over runs of the per-run mean real return,
    normalised by the real-trained mean at that noise. ANE reports the grid σ with the best
    mean real return (privileged selection) and its runs only.
    """
    out = []
    for nz in cfg.noise:
        at = [r for r in rows if abs(r["noise"] - nz) < 1e-9]
        real = [r["return_mean"] for r in at if r["method"] == "real"]
        ref = float(np.mean(real)) if real else math.nan
        for m in cfg.methods:
            mr = [r for r in at if r["method"] == m]
            sigma = math.nan
            if m == "ane" and mr:
                by = {}
                for r in mr:
                    by.setdefault(round(r["ane_sigma"], 9), []).append(r["return_mean"])
                sigma = max(by, key=lambda s: (np.mean(by[s]), -s))
                mr = [r for r in mr if round(r["ane_sigma"], 9) == sigma]
            if not mr:
                continue
            mean, se = _mean_se([r["return_mean"] for r in mr])
            norm = mean / ref if ref and math.isfinite(ref) and ref > 0 else math.nan
            norm_se = se / ref if ref and math.isfinite(ref) and ref > 0 else math.nan
            err = [r["step_err_grounded"] for r in mr if math.isfinite(r["step_err_grounded"])]
            err0 = [r["step_err_sim"] for r in mr if math.isfinite(r["step_err_sim"])]
            out.append({"noise": nz, "method": m, "runs": len(mr), "return_mean": mean, "return_se": se,
                        "normalized": norm, "normalized_se": norm_se, "ane_sigma": sigma,
                        "privileged": m == "ane", "uses_real_data": m not in NO_REAL_DATA,
                        "step_err_sim": float(np.mean(err0)) if err0 else math.nan,
                        "step_err_grounded": float(np.mean(err)) if err else math.nan,
                        "wall_s_mean": float(np.mean([r["wall_s"] for r in mr]))})
    return out


#: Method pairs compared run by run (:func:`paired_differences`): SGAT against GAT (the paper's question)
#: and against the plain sim's policy.
PAIRS = (("sgat", "gat"), ("sgat", "sim"))


def paired_differences(rows: list[dict], cfg: GymConfig, pairs=PAIRS) -> list[dict]:
    """Real-return differences a - b per noise level, paired by run: both methods of a run start from
    that run's sim policy and are evaluated on the same real episode seeds. The interval and test are a
    one-sample t-test of the per-run differences against 0 (:func:`experiments.runtime.stats.seed_level_test`;
    Student 1908); with 3 runs it has 2 degrees of freedom.

    Returns:
        one dict per (noise, pair) with both methods present in at least 2 runs: ``noise``, ``a``, ``b``,
        ``runs``, ``mean_diff`` [return], ``ci`` ([lo, hi], 95 %; [d, d] when every run's difference is
        the same d) and ``p_value`` (None without spread).
    """
    from experiments.runtime.stats import seed_level_test  # lazy: scipy.stats

    out = []
    for nz in cfg.noise:
        at = {(r["method"], r["run"]): r["return_mean"] for r in rows
              if abs(r["noise"] - nz) < 1e-9 and r["method"] != "ane"}
        for a, b in pairs:
            runs = sorted(r for m, r in at if m == a and (b, r) in at)
            if len(runs) < 2:
                continue
            d = np.array([at[(a, r)] - at[(b, r)] for r in runs])
            t = seed_level_test(d)
            out.append({"noise": nz, "a": a, "b": b, "runs": len(runs), "mean_diff": float(d.mean()),
                        "ci": t["ci"] if t else [float(d[0]), float(d[0])],
                        "p_value": t["p_value"] if t else None})
    return out


def format_table(summary: list[dict], cfg: GymConfig, paired: list[dict] = ()) -> str:
    """Plain-text table: real return mean ± s.e. per noise and method (normalised to the real-trained
    policy's when ``real`` is among the methods), then the paired differences
    (:func:`paired_differences`), if given."""
    name = {"noisyreal": "Sim-to-NoisyReal", "noisysim": "Sim-to-NoisySim"}[cfg.experiment]
    mass = (f"pole x{cfg.pole_factor:g}" if cfg.env == "InvertedPendulum" else f"mass x{cfg.mass_factor:.4g}") \
        if cfg.mismatch else "no mass change"
    lines = [f"{cfg.env} {name} ({mass}), TRPO, {cfg.runs} runs/cell; return on real over {cfg.eval_episodes} "
             f"episodes, mean ± s.e. over runs" + (" (normalized to real-trained)" if "real" in cfg.methods else "")]
    ms = [m for m in METHODS if m in cfg.methods]
    head = f"{'noise':>5}  " + "  ".join(f"{m.upper() if m != 'sim' else 'SIM-ONLY':>22}" for m in ms)
    lines += [head, "-" * len(head)]
    for nz in cfg.noise:
        cells = []
        for m in ms:
            e = next((s for s in summary if s["method"] == m and abs(s["noise"] - nz) < 1e-9), None)
            if e is None:
                cells.append(f"{'-':>22}")
                continue
            se = "  n/a" if not math.isfinite(e["return_se"]) else f"{e['return_se']:5.0f}"
            norm = "" if not math.isfinite(e["normalized"]) else f" ({e['normalized']:.2f})"
            cells.append(f"{e['return_mean']:7.1f} ±{se}{norm}".rjust(22))
        lines.append(f"{nz:5.2f}  " + "  ".join(cells))
    ane = [s for s in summary if s["method"] == "ane"]
    if ane:
        lines.append("ANE σ (best on real, privileged): " +
                     ", ".join(f"noise {s['noise']:g}: {s['ane_sigma']:g}" for s in ane))
    err = [s for s in summary if s["method"] in ("gat", "sgat") and math.isfinite(s["step_err_grounded"])]
    if err:
        lines.append("one-step next-state error vs real (plain sim -> grounded): " +
                     "; ".join(f"{s['method'].upper()}@{s['noise']:g}: {s['step_err_sim']:.4f} -> "
                               f"{s['step_err_grounded']:.4f}" for s in err))
    for a, b in dict.fromkeys((p["a"], p["b"]) for p in paired):
        name_b = "SIM-ONLY" if b == "sim" else b.upper()
        lines.append(f"{a.upper()} - {name_b} real return, paired by run (mean [95 % t-interval], t-test p): " +
                     "; ".join(f"noise {p['noise']:g}: {p['mean_diff']:+.0f} [{p['ci'][0]:+.0f}, {p['ci'][1]:+.0f}]"
                               + (f" p={p['p_value']:.2g}" if p["p_value"] is not None else " (no spread)")
                               for p in paired if (p["a"], p["b"]) == (a, b)))
    return "\n".join(lines)


def write_summary_csv(summary: list[dict], path: Path) -> None:
    cols = ["noise", "method", "runs", "return_mean", "return_se", "normalized", "normalized_se", "ane_sigma",
            "privileged", "uses_real_data", "step_err_sim", "step_err_grounded", "wall_s_mean"]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for s in summary:
        w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in s.items()})
    _write_text(path, buf.getvalue())


_STYLE = {"sim": ("sim only", "0.6", "//"), "ane": ("ANE (σ tuned on real)", "tab:orange", "//"),
          "gat": ("GAT", "tab:purple", None), "sgat": ("SGAT", "tab:blue", None), "real": ("real-trained", "tab:red", None)}


def plot_bars(summary: list[dict], cfg: GymConfig, path: Path) -> None:
    """Bars in the style of the paper's Figs. 8-9: per noise, the real return of each method
    normalised to the real-trained return (red dashed line at 1); hatched bars used no real
    data; error bars = standard error over runs. Without real-trained results, raw returns."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: matplotlib
    from matplotlib.figure import Figure  # lazy: matplotlib

    have_real = any(s["method"] == "real" and math.isfinite(s["return_mean"]) for s in summary)
    bars = [m for m in ("sim", "ane", "gat", "sgat") if m in cfg.methods]
    if not have_real and "real" in cfg.methods:
        bars.append("real")
    key = "normalized" if have_real else "return_mean"
    key_se = "normalized_se" if have_real else "return_se"
    fig = Figure(figsize=(3.2 + 1.6 * len(cfg.noise), 4.8))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    width = 0.8 / max(1, len(bars))
    x = np.arange(len(cfg.noise))

    def entry(m, nz):
        return next((s for s in summary if s["method"] == m and abs(s["noise"] - nz) < 1e-9), None)

    for j, m in enumerate(bars):
        es = [entry(m, nz) for nz in cfg.noise]
        vals = [e[key] if e else np.nan for e in es]
        errs = [e[key_se] if e and math.isfinite(e[key_se]) else 0.0 for e in es]
        label, color, hatch = _STYLE[m]
        xs = x + (j - (len(bars) - 1) / 2) * width
        ax.bar(xs, vals, width, yerr=errs, color=color, hatch=hatch, edgecolor="black", linewidth=0.6, capsize=2,
               label=label, alpha=0.85 if hatch is None else 0.55)
        if m == "ane":
            for xi, e in zip(xs, es):
                if e and math.isfinite(e[key]):
                    ax.text(xi, 0.01, f"σ={e['ane_sigma']:g}", rotation=90, ha="center", va="bottom", fontsize=7,
                            transform=ax.get_xaxis_transform())
    labels = []
    for nz in cfg.noise:
        e = entry("real", nz)
        labels.append(f"{nz:g}" + (f"\n(real-trained {e['return_mean']:.0f})" if have_real and e else ""))
    if have_real:
        ax.axhline(1.0, color="tab:red", ls="--", lw=1.5, label="real-trained (= 1)")
        ax.set_ylabel('return on "real" / real-trained return')
    else:
        ax.set_ylabel('return on "real"')
    ax.set_xticks(x, labels, fontsize=8)
    ax.set_xlabel("action noise σ (share of the action half-range)")
    name = {"noisyreal": "Sim-to-NoisyReal", "noisysim": "Sim-to-NoisySim"}[cfg.experiment]
    mass = (f"pole ×{cfg.pole_factor:g}" if cfg.env == "InvertedPendulum" else f"mass ×{cfg.mass_factor:.3g}") \
        if cfg.mismatch else "noise only"
    runs = max((s["runs"] for s in summary), default=0)
    ax.set_title(f"{cfg.env} {name} ({mass})\nTRPO, {runs} runs per bar, mean ± s.e.; hatched: no real data",
                 fontsize=9)
    ax.set_ylim(bottom=min(0.0, ax.get_ylim()[0]))
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3, frameon=False)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=130, bbox_inches="tight")
    _atomic_write_bytes(Path(path), buf.getvalue())
