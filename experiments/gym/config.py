"""Configuration of the MuJoCo gym sim-to-real experiments (SGAT paper §IV.B, Figs. 8-9).

Everything a ``sgatwalk gym`` run depends on lives here: the two tasks and their "real"
variants, the TRPO hyperparameters (with their source), the training budgets of the ``quick``
and ``paper`` presets, and :class:`GymConfig`, the one object a sweep is run from.

TRPO hyperparameters
--------------------
The paper used stable-baselines (TF1) TRPO "with their hyperparameters for the respective
domains". Its modern successor is ``sb3_contrib.TRPO`` with rl-baselines3-zoo's
``hyperparams/trpo.yml`` (DLR-RM/rl-baselines3-zoo, commit 13a3fe7):

* **HalfCheetah** -- the zoo's tuned ``HalfCheetah-v4`` entry (``&mujoco-defaults`` =
  ``&pybullet-defaults`` + ``target_kl: 0.04``): VecNormalize on observations and rewards,
  2 envs, n_steps 1024, batch 128, γ 0.99, λ 0.95, cg 25 steps / damping 0.1, 20 critic
  updates, lr 1e-3, 1e6 steps. The zoo has no ``-v5`` key; v5 differs from v4 only in
  bookkeeping (same model and reward), so the v4 values are used unchanged.
* **InvertedPendulum** -- the zoo has no InvertedPendulum entry, so the zoo falls back to its
  ``default:`` block (MlpPolicy, 1e6 steps, i.e. sb3-contrib's constructor defaults: lr 1e-3,
  n_steps 2048, batch 128, γ 0.99, λ 0.95, cg 15 / 0.1, 10 critic updates, target_kl 0.01, no
  normalisation). Those are used here. (The GARAT/SGAT code took the SB2 zoo's *Pendulum* entry
  for InvertedPendulum -- batch 5000, γ 0.98, λ 0.9, ... from rl-baselines-zoo's ``trpo.yml``; with
  SB3 the defaults solve InvertedPendulum-v5 in ≈3·10⁴ steps.)

The policy is SB3's ``MlpPolicy`` (2×64 tanh, separate policy and value networks), as in the
paper's stable-baselines setup. Torch runs with one thread per process.

"Real" variants (SGAT paper §IV.B; GARAT code and appendix)
-----------------------------------------------------------
* InvertedPendulum: the pole (body ``pole``, 5.02 kg) is ``pole_factor`` times heavier; mass
  and rotational inertia are scaled together. The SGAT paper says **10×** (the default); the
  GARAT code's XML uses 100 kg (≈20×): ``--pole-factor 20`` reproduces that.
* HalfCheetah: every body's mass and inertia × ``mass_factor`` = 20/14 (total 14 -> 20 kg, the
  paper's "43 % heavier").
* Noise: zero-mean Gaussian on a copy of the commanded action with σ = ``noise`` × half the
  action range (InvertedPendulum: range [-3, 3], so noise 0.1 is 0.3 force units; HalfCheetah:
  [-1, 1]), then clipped to the bounds. This keeps noise values comparable with the paper, which
  states both action spaces as [-1, 1] (true for HalfCheetah only).
* Sim-to-NoisySim = noise only; Sim-to-NoisyReal = noise + the mass change.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

#: Known tasks: gymnasium id, mass change of the "real" variant, control-cost weight of the
#: reward (``-w·|a|²``, recomputed on the agent's action), and the TRPO settings.
TASKS: dict[str, dict] = {
    "InvertedPendulum": {
        "env_id": "InvertedPendulum-v5",
        "ctrl_cost_weight": None,  # reward = 1 per step upright, no control cost
    },
    "HalfCheetah": {
        "env_id": "HalfCheetah-v5",
        "ctrl_cost_weight": 0.1,
    },
}

#: rl-baselines3-zoo ``hyperparams/trpo.yml`` values (see the module docstring). ``n_envs`` and
#: ``normalize`` are zoo keys (vectorised envs, VecNormalize); the rest go to ``TRPO(...)``.
TRPO_HYPERPARAMS: dict[str, dict] = {
    "InvertedPendulum": {
        # zoo ``default:`` block -> sb3-contrib 2.9.2 constructor defaults, spelled out
        "n_envs": 1,
        "normalize": False,
        "learning_rate": 1e-3,
        "n_steps": 2048,
        "batch_size": 128,
        "gamma": 0.99,
        "gae_lambda": 0.95,
        "cg_max_steps": 15,
        "cg_damping": 0.1,
        "n_critic_updates": 10,
        "target_kl": 0.01,
        "sub_sampling_factor": 1,
    },
    "HalfCheetah": {
        # zoo ``HalfCheetah-v4`` (tuned)
        "n_envs": 2,
        "normalize": True,
        "learning_rate": 1e-3,
        "n_steps": 1024,
        "batch_size": 128,
        "gamma": 0.99,
        "gae_lambda": 0.95,
        "cg_max_steps": 25,
        "cg_damping": 0.1,
        "n_critic_updates": 20,
        "target_kl": 0.04,
        "sub_sampling_factor": 1,
    },
}

METHODS = ("sim", "gat", "sgat", "ane", "real")
#: Methods that use no real-world data during training (hatched bars, as in the paper).
NO_REAL_DATA = ("sim", "ane")
EXPERIMENTS = ("noisyreal", "noisysim")

#: Budgets per task and preset. ``sim_steps``: the initial sim policy (shared by sim, GAT, SGAT
#: and ANE of one run); ``grounded_steps``: the policy-improvement step per grounding step
#: (GAT/SGAT in the grounded sim, ANE in the noisy sim), warm-started from the sim policy;
#: ``real_steps``: the real-trained upper bound, from scratch on the real variant;
#: ``real_transitions`` / ``sim_transitions``: data per grounding step for f_real and f_sim^-1.
#: ``paper`` follows the GARAT/SGAT code (GARAT scripts, Desai et al., NeurIPS 2020): initial sim policy 1e6 (IP)
#: / 2e6 (HC) steps, re-training 1e5 (IP) / 1e6 (HC) per grounding step, 1 (IP) / 5 (HC)
#: grounding steps, the real upper bound with the initial policy's budget, 10 runs, 20 evaluation
#: episodes. The amount of real data is not stated in the paper (the appendix says 1 M steps,
#: the scripts 1-5 k transitions); 2·10⁴ (IP) / 5·10⁴ (HC) transitions per step are used.
PRESETS: dict[str, dict[str, dict]] = {
    "quick": {
        "InvertedPendulum": dict(sim_steps=30_000, grounded_steps=20_000, real_steps=50_000, grounding_steps=1,
                                 real_transitions=5_000, sim_transitions=10_000, eval_episodes=10, runs=2,
                                 ane_grid=(0.1, 0.3), model_epochs=40, noise=(0.0, 0.3)),
        "HalfCheetah": dict(sim_steps=100_000, grounded_steps=50_000, real_steps=150_000, grounding_steps=1,
                            real_transitions=10_000, sim_transitions=20_000, eval_episodes=5, runs=2,
                            ane_grid=(0.1, 0.3), model_epochs=40, noise=(0.0, 0.3)),
    },
    "paper": {
        "InvertedPendulum": dict(sim_steps=1_000_000, grounded_steps=100_000, real_steps=1_000_000, grounding_steps=1,
                                 real_transitions=20_000, sim_transitions=40_000, eval_episodes=20, runs=10,
                                 ane_grid=(0.1, 0.2, 0.3, 0.5), model_epochs=200, model_batch=256,
                                 model_lr=1e-3, noise=(0.0, 0.1, 0.2, 0.3)),
        "HalfCheetah": dict(sim_steps=2_000_000, grounded_steps=1_000_000, real_steps=2_000_000, grounding_steps=5,
                            real_transitions=50_000, sim_transitions=100_000, eval_episodes=20, runs=10,
                            ane_grid=(0.1, 0.2, 0.3, 0.5), model_epochs=200, model_batch=256,
                            model_lr=1e-3, noise=(0.0, 0.1, 0.2, 0.3)),
    },
}


def canonical_env(name: str) -> str:
    """``"InvertedPendulum"``, ``"invertedpendulum"``, ``"InvertedPendulum-v5"``, ``"ip"`` -> the task key.

    Raises:
        ValueError: unknown task.
    """
    key = str(name).strip().lower().split("-v")[0]
    aliases = {"invertedpendulum": "InvertedPendulum", "ip": "InvertedPendulum", "pendulum": "InvertedPendulum",
               "halfcheetah": "HalfCheetah", "hc": "HalfCheetah", "cheetah": "HalfCheetah"}
    if key not in aliases:
        raise ValueError(f"unknown --env {name!r}; choose InvertedPendulum or HalfCheetah")
    return aliases[key]


@dataclass
class GymConfig:
    """One sweep of ``sgatwalk gym``: a task, noise values, methods, runs and budgets.

    Attributes (units: steps are environment steps; noise and ANE σ are shares of the action
    half-range; masses are factors):
        env: ``"InvertedPendulum"`` or ``"HalfCheetah"``.
        experiment: ``"noisyreal"`` (noise + mass change) or ``"noisysim"`` (noise only).
        noise: the real world's action-noise levels.
        methods: subset of :data:`METHODS`.
        runs: independent training runs per (noise, method) cell (paper: 10).
        seed: base seed; run r of every method uses the same derived seeds.
        pole_factor: InvertedPendulum pole mass/inertia factor of the "real" pendulum (paper 10).
        mass_factor: HalfCheetah mass/inertia factor (paper 20/14).
        ane_grid: the ANE noise values tried (coarse grid search; the best on real is reported,
            which is privileged knowledge -- ANE uses no real data for training, but its σ is
            selected by looking at real returns).
        explore_sigma: exploration noise on the sim data for the inverse model.
        alpha: blend of raw and grounded action (1 = the paper's formulation).
        hidden: hidden sizes of the forward and inverse models (paper 64, 64).
        model_epochs / model_patience / model_lr / model_batch: model fitting (Adam, mini-batches,
            early stopping on a 20 % validation split).
        trpo: overrides of :data:`TRPO_HYPERPARAMS` for this task.
    """

    env: str = "InvertedPendulum"
    experiment: str = "noisyreal"
    preset: str = "quick"
    noise: tuple[float, ...] = (0.0, 0.3)
    methods: tuple[str, ...] = METHODS
    runs: int = 2
    seed: int = 0
    sim_steps: int = 30_000
    grounded_steps: int = 20_000
    real_steps: int = 50_000
    grounding_steps: int = 1
    real_transitions: int = 5_000
    sim_transitions: int = 10_000
    eval_episodes: int = 10
    ane_grid: tuple[float, ...] = (0.1, 0.3)
    pole_factor: float = 10.0
    mass_factor: float = 20.0 / 14.0
    explore_sigma: float = 0.3
    alpha: float = 1.0
    hidden: tuple[int, ...] = (64, 64)
    model_epochs: int = 40
    model_patience: int = 10
    model_lr: float = 3e-3
    model_batch: int = 512
    trpo: dict = field(default_factory=dict)

    @classmethod
    def from_preset(cls, env: str = "InvertedPendulum", preset: str = "quick", **overrides) -> "GymConfig":
        """The preset's values for ``env``, then ``overrides`` (None values are ignored).

        Raises:
            ValueError: unknown env, preset or field; invalid values (see :meth:`validate`).
        """
        env = canonical_env(env)
        if preset not in PRESETS:
            raise ValueError(f"unknown --preset {preset!r}; choose {', '.join(PRESETS)}")
        kw = dict(PRESETS[preset][env])
        names = {f.name for f in dataclasses.fields(cls)}
        for k, v in overrides.items():
            if k not in names:
                raise ValueError(f"unknown gym setting {k!r}")
            if v is not None:
                kw[k] = v
        cfg = cls(env=env, preset=preset, **kw)
        cfg.noise = tuple(float(x) for x in cfg.noise)
        cfg.ane_grid = tuple(float(x) for x in cfg.ane_grid)
        cfg.methods = tuple(cfg.methods)
        cfg.hidden = tuple(int(h) for h in cfg.hidden)
        cfg.validate()
        return cfg

    @property
    def env_id(self) -> str:
        return TASKS[self.env]["env_id"]

    @property
    def ctrl_cost_weight(self) -> float | None:
        return TASKS[self.env]["ctrl_cost_weight"]

    def trpo_params(self) -> dict:
        """The TRPO settings for this task: zoo values, then :attr:`trpo` overrides."""
        return {**TRPO_HYPERPARAMS[self.env], **self.trpo}

    @property
    def mismatch(self) -> bool:
        """True for Sim-to-NoisyReal (mass change), False for Sim-to-NoisySim."""
        return self.experiment == "noisyreal"

    def validate(self) -> None:
        """Raises ValueError naming the first invalid value."""
        self.env = canonical_env(self.env)
        if self.experiment not in EXPERIMENTS:
            raise ValueError(f"unknown --experiment {self.experiment!r}; choose {', '.join(EXPERIMENTS)}")
        bad = [m for m in self.methods if m not in METHODS]
        if bad or not self.methods:
            raise ValueError(f"unknown method(s) {', '.join(bad) or '(none given)'}; choose from {', '.join(METHODS)}")
        if len(set(self.methods)) != len(self.methods):
            raise ValueError(f"--methods lists a method twice: {','.join(self.methods)}")
        if not self.noise:
            raise ValueError("--noise: give at least one value")
        for v in (*self.noise, *self.ane_grid, self.explore_sigma):
            if not (math.isfinite(v) and 0.0 <= v <= 5.0):
                raise ValueError(f"noise values are shares of the action half-range in [0, 5], got {v!r}")
        if len(set(self.noise)) != len(self.noise):
            raise ValueError("--noise lists a value twice")
        if "ane" in self.methods and not self.ane_grid:
            raise ValueError("--ane-grid: give at least one value for the ane method")
        for name in ("runs", "sim_steps", "real_steps", "real_transitions", "sim_transitions", "eval_episodes",
                     "grounding_steps", "model_epochs", "model_patience", "model_batch"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 1:
                raise ValueError(f"--{name.replace('_', '-')} must be a positive integer, got {v!r}")
        if not isinstance(self.grounded_steps, int) or self.grounded_steps < 0:
            raise ValueError(f"--grounded-steps must be a non-negative integer, got {self.grounded_steps!r}")
        if self.seed < 0:
            raise ValueError(f"--seed must be non-negative, got {self.seed}")
        for name in ("pole_factor", "mass_factor"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"--{name.replace('_', '-')} must be positive, got {v!r}")
        if not 0.0 <= self.alpha <= 1.0:
            raise ValueError(f"--alpha must be in [0, 1], got {self.alpha}")
        if not (math.isfinite(self.model_lr) and self.model_lr > 0):
            raise ValueError(f"model_lr must be positive, got {self.model_lr}")

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        for k, v in d.items():
            if isinstance(v, tuple):
                d[k] = list(v)
        d["env_id"] = self.env_id
        d["trpo_resolved"] = self.trpo_params()
        return d

    def fingerprint(self, method: str) -> dict:
        """The settings a stored result row of ``method`` depends on (besides noise, run and ANE
        σ): a sweep only reuses rows whose fingerprint matches, so changing a budget never mixes
        results, and only the methods that depend on a changed setting are re-run. ``"sim_policy"``
        is the initial sim policy's own fingerprint.

        Raises:
            ValueError: unknown method.
        """
        sim = ("env", "seed", "sim_steps")
        common = ("env", "experiment", "seed", "eval_episodes", "pole_factor", "mass_factor")
        ground = ("grounded_steps", "grounding_steps")
        model = ("real_transitions", "sim_transitions", "explore_sigma", "alpha", "hidden", "model_epochs",
                 "model_patience", "model_lr", "model_batch")
        keys = {"sim_policy": sim, "sim": common + ("sim_steps",), "real": common + ("real_steps",),
                "ane": common + ("sim_steps",) + ground, "gat": common + ("sim_steps",) + ground + model,
                "sgat": common + ("sim_steps",) + ground + model}
        if method not in keys:
            raise ValueError(f"unknown method {method!r}")
        d = {k: getattr(self, k) for k in keys[method]}
        if "hidden" in d:
            d["hidden"] = list(self.hidden)
        if method in ("gat", "sgat"):
            d["method"] = method
        d["trpo"] = self.trpo_params()
        return d
