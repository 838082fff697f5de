"""Forward model of the real world and inverse model of the sim (SGAT paper §III, Algorithm 1).

* :class:`ForwardModel` ``f_real(s_t, a_t)`` predicts the state change ``s_{t+1} - s_t``.
  SGAT: a diagonal Gaussian (mean and log standard deviation per dimension, log sigma clamped
  to ``[LOG_STD_MIN, LOG_STD_MAX]``), trained by Gaussian negative log-likelihood, or a mixture of
  ``components`` diagonal Gaussians (a mixture density network, Bishop 1994; the SGAT paper's
  footnote on multi-modal transitions); GAT: the same network with a mean head only, trained by
  mean squared error.
* :class:`InverseModel` ``f_sim^-1(s_t, s_{t+1})`` predicts the action from ``[s_t, s_{t+1} - s_t]``
  by mean squared error.

Both are MLPs with two hidden layers of 64 tanh units (the paper's size; configurable) plus a
linear skip path from input to output (as ``Net`` in ``rl_gat/gat.py`` of the GARAT code, Desai et
al., NeurIPS 2020), with input and output
normalisation stored inside the model, so weights and statistics travel together. ``fit`` trains
with Adam, mini-batches, a validation split and early stopping that restores the best epoch.
``save``/``load`` use plain tensors and a JSON-able config: ``torch.load(weights_only=True)``.

Inference for the per-step action transformer runs in NumPy (:meth:`numpy_params`): for one
sample a 2x64 MLP costs a few microseconds, far less than a torch call.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
import torch
from scipy.special import log_softmax, ndtr
from torch import nn
from common.files import atomic_path

LOG_STD_MIN, LOG_STD_MAX = -10.0, 2.0


class ModelFileError(ValueError):
    """A saved model is corrupted, of the wrong kind or of the wrong shape."""


class _MLP(nn.Module):
    def __init__(self, n_in: int, n_out: int, hidden: tuple[int, ...]):
        super().__init__()
        layers, d = [], n_in
        for h in hidden:
            layers += [nn.Linear(d, h), nn.Tanh()]
            d = h
        layers.append(nn.Linear(d, n_out))
        self.body = nn.Sequential(*layers)
        self.skip = nn.Linear(n_in, n_out, bias=False)
        nn.init.zeros_(self.skip.weight)

    def forward(self, x):
        return self.body(x) + self.skip(x)


@dataclass
class FitReport:
    """What :meth:`_Model.fit` did: epochs run, best epoch, train/validation loss at the best epoch."""

    epochs: int
    best_epoch: int
    train_loss: float
    val_loss: float
    n_train: int
    n_val: int


class _Model(nn.Module):
    """Common part: normalisers (buffers), MLP, training loop, save/load, NumPy export."""

    kind = "model"

    def __init__(self, n_in: int, n_out: int, hidden=(64, 64), n_heads: int = 1, n_extra: int = 0):
        super().__init__()
        self.n_in, self.n_out, self.hidden, self.n_heads = int(n_in), int(n_out), tuple(int(h) for h in hidden), n_heads
        self.net = _MLP(self.n_in, self.n_out * n_heads + int(n_extra), self.hidden)
        self.register_buffer("x_mean", torch.zeros(self.n_in, dtype=torch.float64))
        self.register_buffer("x_std", torch.ones(self.n_in, dtype=torch.float64))
        self.register_buffer("y_mean", torch.zeros(self.n_out, dtype=torch.float64))
        self.register_buffer("y_std", torch.ones(self.n_out, dtype=torch.float64))
        self.register_buffer("fitted", torch.zeros((), dtype=torch.bool))
        self.double()

    # -- normalisation -------------------------------------------------------------------
    def _set_stats(self, X: np.ndarray, Y: np.ndarray) -> None:
        def stats(A):
            m, s = A.mean(0), A.std(0)
            return torch.as_tensor(m), torch.as_tensor(np.where(s > 1e-8, s, 1.0))
        self.x_mean, self.x_std = stats(X)
        self.y_mean, self.y_std = stats(Y)

    def _loss(self, out, y):  # pragma: no cover - abstract
        raise NotImplementedError

    # -- training --------------------------------------------------------------------------
    def fit(self, X: np.ndarray, Y: np.ndarray, *, val_fraction: float = 0.2, batch_size: int = 128,
            lr: float = 1e-3, weight_decay: float = 0.0, max_epochs: int = 300, patience: int = 15,
            seed: int = 0, progress=None) -> FitReport:
        """Train on inputs ``X`` (N, n_in) and targets ``Y`` (N, n_out) (unnormalised).

        A random ``val_fraction`` of the rows (seeded) is held out; training stops after
        ``patience`` epochs without a better validation loss and restores the best weights.

        Raises:
            ValueError: wrong shapes, non-finite data, fewer than 10 rows.
        """
        X = np.asarray(X, dtype=np.float64)
        Y = np.asarray(Y, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != self.n_in or Y.ndim != 2 or Y.shape[1] != self.n_out or len(X) != len(Y):
            raise ValueError(f"{self.kind}: expected X (N, {self.n_in}) and Y (N, {self.n_out}), got {X.shape}, {Y.shape}")
        if len(X) < 10:
            raise ValueError(f"{self.kind}: need at least 10 samples, got {len(X)}")
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(Y))):
            raise ValueError(f"{self.kind}: training data contain NaN or infinite values")
        g = torch.Generator().manual_seed(int(seed))
        torch.manual_seed(int(seed))
        for m in self.net.modules():  # initial weights from the seed, not from earlier torch use
            if isinstance(m, nn.Linear):
                m.reset_parameters()
        nn.init.zeros_(self.net.skip.weight)
        perm = np.random.default_rng(seed).permutation(len(X))
        n_val = max(1, int(round(val_fraction * len(X))))
        vi, ti = perm[:n_val], perm[n_val:]
        self._set_stats(X[ti], Y[ti])
        Xn = (torch.as_tensor(X) - self.x_mean) / self.x_std
        Yn = (torch.as_tensor(Y) - self.y_mean) / self.y_std
        Xt, Yt, Xv, Yv = Xn[ti], Yn[ti], Xn[vi], Yn[vi]
        opt = torch.optim.Adam(self.net.parameters(), lr=lr, weight_decay=weight_decay)
        best, best_state, best_epoch, bad, train_loss = math.inf, None, 0, 0, math.inf
        epoch = 0
        for epoch in range(1, max_epochs + 1):
            self.train()
            order = torch.randperm(len(Xt), generator=g)
            total = 0.0
            for k in range(0, len(Xt), batch_size):
                idx = order[k:k + batch_size]
                loss = self._loss(self.net(Xt[idx]), Yt[idx])
                opt.zero_grad()
                loss.backward()
                opt.step()
                total += float(loss.detach()) * len(idx)
            self.eval()
            with torch.no_grad():
                val = float(self._loss(self.net(Xv), Yv))
            if progress is not None:
                progress(epoch, total / len(Xt), val)
            if val < best - 1e-9:
                best, best_epoch, bad, train_loss = val, epoch, 0, total / len(Xt)
                best_state = {k: v.detach().clone() for k, v in self.net.state_dict().items()}
            else:
                bad += 1
                if bad >= patience:
                    break
        self.net.load_state_dict(best_state)
        self.fitted = torch.ones((), dtype=torch.bool)
        self._np = None
        return FitReport(epoch, best_epoch, train_loss, best, len(ti), len(vi))

    # -- inference ---------------------------------------------------------------------------
    def numpy_params(self) -> dict:
        """Weights and normalisers as NumPy arrays for :func:`mlp_forward` (cached)."""
        if getattr(self, "_np", None) is None:
            lin = [m for m in self.net.body if isinstance(m, nn.Linear)]
            self._np = {
                "W": [m.weight.detach().numpy().T.copy() for m in lin],
                "b": [m.bias.detach().numpy().copy() for m in lin],
                "S": self.net.skip.weight.detach().numpy().T.copy(),
                "x_mean": self.x_mean.numpy().copy(), "x_std": self.x_std.numpy().copy(),
                "y_mean": self.y_mean.numpy().copy(), "y_std": self.y_std.numpy().copy(),
            }
        return self._np

    def _raw(self, X: np.ndarray) -> np.ndarray:
        """Normalised network output for unnormalised inputs X (..., n_in)."""
        p = self.numpy_params()
        return mlp_forward(p, (np.asarray(X, dtype=np.float64) - p["x_mean"]) / p["x_std"])

    # -- persistence ---------------------------------------------------------------------------
    def config(self) -> dict:
        return {"kind": self.kind, "n_in": self.n_in, "n_out": self.n_out, "hidden": list(self.hidden)}

    def save(self, path: str | os.PathLike) -> str:
        """Write config + state dict atomically; loadable with ``torch.load(weights_only=True)``."""
        path = os.fspath(path)
        with atomic_path(path) as tmp:
            torch.save({"config": self.config(), "state_dict": self.state_dict()}, tmp)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike, expect_in: int | None = None, expect_out: int | None = None):
        """Load a model saved by :meth:`save`.

        Raises:
            FileNotFoundError: no such file.
            ModelFileError: not a model file, another kind of model, or a shape that differs from
                ``expect_in``/``expect_out`` or from its own config.
        """
        path = os.fspath(path)
        if not os.path.exists(path):
            raise FileNotFoundError(f"no model file at {path!r}")
        try:
            blob = torch.load(path, weights_only=True, map_location="cpu")
            cfg, sd = blob["config"], blob["state_dict"]
        except Exception as exc:  # torch raises many types for corrupt files
            raise ModelFileError(f"{path!r} is not a readable sgatwalk model file ({type(exc).__name__}: {exc})") from None
        if cfg.get("kind") != cls.kind:
            raise ModelFileError(f"{path!r} holds a {cfg.get('kind')!r} model, expected {cls.kind!r}")
        for name, want, have in (("inputs", expect_in, cfg["n_in"]), ("outputs", expect_out, cfg["n_out"])):
            if want is not None and want != have:
                raise ModelFileError(f"{path!r}: model has {have} {name}, this setting needs {want}")
        model = cls.from_config(cfg)
        try:
            model.load_state_dict(sd)
        except RuntimeError as exc:
            raise ModelFileError(f"{path!r}: weights do not match the model's shape ({exc})") from None
        return model


def mlp_forward(p: dict, x: np.ndarray) -> np.ndarray:
    """NumPy forward pass of :class:`_MLP` (tanh hidden layers + linear skip), x (..., n_in)."""
    h = x
    for W, b in zip(p["W"][:-1], p["b"][:-1]):
        h = np.tanh(h @ W + b)
    return h @ p["W"][-1] + p["b"][-1] + x @ p["S"]


class ForwardModel(_Model):
    """``f_real``: (state history, action) -> distribution of the state change.

    Args:
        state_dim: grounding-state size S; history: frames k (input holds the last k states).
        action_dim: grounded-action size A.
        stochastic: True for SGAT (Gaussian, NLL), False for GAT (mean, MSE).
        hidden: hidden layer sizes (paper: (64, 64)).
        components: K diagonal Gaussians in a mixture (a mixture density network, Bishop 1994,
            "Mixture Density Networks", eq. 22-26; the SGAT paper's footnote: a multi-modal
            transition, such as a swing foot that now and then catches a bump, is not one Gaussian).
            1 (default): one Gaussian. Only with ``stochastic``.
        commands: c, the actions commanded before ``a_t`` the model also sees (a command history:
            with an actuation latency the real state change answers commands given a few steps
            ago, which the one-step model of the paper cannot represent). 0 (default): none.

    Input layout: ``[s_{t-k+1}, ..., s_t, a_{t-c}, ..., a_{t-1}, a_t]`` of size k*S + (c+1)*A;
    output: Δs of size S. Network
    output (normalised units): K means (K*S), K log standard deviations (K*S) and, for K > 1, K
    mixture logits.

    Raises:
        ValueError: components < 1, or > 1 without ``stochastic``; commands < 0.
    """

    kind = "forward"

    def __init__(self, state_dim: int, action_dim: int, *, history: int = 1, stochastic: bool = True,
                 hidden=(64, 64), components: int = 1, commands: int = 0):
        self.state_dim, self.action_dim, self.history, self.stochastic = int(state_dim), int(action_dim), int(history), bool(stochastic)
        self.components = int(components)
        self.commands = int(commands)
        if self.components < 1 or (self.components > 1 and not self.stochastic):
            raise ValueError(f"components must be >= 1 (and 1 for a deterministic model), got {components}")
        if self.commands < 0:
            raise ValueError(f"commands must be >= 0, got {commands}")
        K = self.components
        super().__init__(self.history * self.state_dim + (self.commands + 1) * self.action_dim, self.state_dim, hidden,
                         n_heads=2 * K if self.stochastic else 1, n_extra=K if K > 1 else 0)

    @property
    def noise_dim(self) -> int:
        """Standard normal draws one sample takes: S, plus one that picks the mixture component."""
        return self.state_dim + (1 if self.components > 1 else 0)

    def config(self) -> dict:
        cfg = {**super().config(), "state_dim": self.state_dim, "action_dim": self.action_dim,
               "history": self.history, "stochastic": self.stochastic}
        if self.components > 1:
            cfg["components"] = self.components
        if self.commands:
            cfg["commands"] = self.commands
        return cfg

    @classmethod
    def from_config(cls, cfg: dict) -> "ForwardModel":
        return cls(cfg["state_dim"], cfg["action_dim"], history=cfg["history"], stochastic=cfg["stochastic"],
                   hidden=tuple(cfg["hidden"]), components=int(cfg.get("components", 1)),
                   commands=int(cfg.get("commands", 0)))

    def _split(self, out):
        """(means (..., K, S), log stds (..., K, S), log weights (..., K)) of normalised outputs
        (torch tensors or NumPy arrays)."""
        K, S = self.components, self.n_out
        lead = out.shape[:-1]
        mu = out[..., :K * S].reshape(*lead, K, S)
        log_std = out[..., K * S:2 * K * S].reshape(*lead, K, S)
        if isinstance(out, torch.Tensor):
            log_std = log_std.clamp(LOG_STD_MIN, LOG_STD_MAX)
            logw = torch.log_softmax(out[..., 2 * K * S:], -1) if K > 1 else torch.zeros(*lead, 1, dtype=out.dtype)
        else:
            log_std = np.clip(log_std, LOG_STD_MIN, LOG_STD_MAX)
            logw = log_softmax(out[..., 2 * K * S:], -1) if K > 1 else np.zeros((*lead, 1))
        return mu, log_std, logw

    def _loss(self, out, y):
        if not self.stochastic:
            return ((out - y) ** 2).mean()
        if self.components == 1:  # the plain Gaussian NLL (written as before: the same fits to the bit)
            mu, log_std = out[:, :self.n_out], out[:, self.n_out:].clamp(LOG_STD_MIN, LOG_STD_MAX)
            return (0.5 * ((y - mu) / log_std.exp()) ** 2 + log_std).mean() + 0.5 * math.log(2 * math.pi)
        mu, log_std, logw = self._split(out)
        # per-dimension negative log-likelihood (the mean over S, so K = 1 is the plain Gaussian NLL)
        lp = -(0.5 * ((y[:, None, :] - mu) / log_std.exp()) ** 2 + log_std).sum(-1)
        return -torch.logsumexp(logw + lp, -1).mean() / self.n_out + 0.5 * math.log(2 * math.pi)

    def mixture(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Weights (..., K), means (..., K, S) and standard deviations (..., K, S) of Δs
        (unnormalised); one Gaussian is a mixture of K = 1.

        Raises:
            ValueError: the model is deterministic (GAT).
        """
        if not self.stochastic:
            raise ValueError("a deterministic (GAT) forward model has no distribution")
        p = self.numpy_params()
        mu, log_std, logw = self._split(self._raw(X))
        return np.exp(logw), mu * p["y_std"] + p["y_mean"], np.exp(log_std) * p["y_std"]

    def predict(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and standard deviation of Δs (unnormalised), each (..., S); std is 0 for GAT. For a
        mixture: its mean and the standard deviation of the whole mixture (law of total variance)."""
        if self.components == 1:  # GAT or one Gaussian: the per-step hot path, plain slices
            out, p = self._raw(X), self.numpy_params()
            mu = out[..., :self.n_out] * p["y_std"] + p["y_mean"]
            if not self.stochastic:
                return mu, np.zeros_like(mu)
            return mu, np.exp(np.clip(out[..., self.n_out:], LOG_STD_MIN, LOG_STD_MAX)) * p["y_std"]
        w, mu, sd = self.mixture(X)
        m = np.einsum("...k,...ks->...s", w, mu)
        var = np.einsum("...k,...ks->...s", w, sd ** 2 + mu ** 2) - m ** 2
        return m, np.sqrt(np.maximum(var, 0.0))

    def sample_with(self, X: np.ndarray, z: np.ndarray) -> np.ndarray:
        """A sample of Δs from standard normal draws ``z`` (..., :attr:`noise_dim`): μ + σ z for one
        Gaussian; for a mixture, the component whose cumulative weight first exceeds Φ(z[..., 0])
        (inverse-CDF sampling) and then its μ_k + σ_k z[..., 1:]. The mean for GAT."""
        if self.components == 1:
            mu, sd = self.predict(X)
            return mu if not self.stochastic else mu + sd * np.asarray(z, dtype=np.float64)
        w, mu, sd = self.mixture(X)
        z = np.asarray(z, dtype=np.float64)
        u = ndtr(z[..., 0])  # uniform on (0, 1)
        k = np.minimum((np.cumsum(w, -1) <= u[..., None]).sum(-1), self.components - 1)
        pick = np.take_along_axis
        mu_k = pick(mu, k[..., None, None], -2)[..., 0, :]
        sd_k = pick(sd, k[..., None, None], -2)[..., 0, :]
        return mu_k + sd_k * z[..., 1:]

    def sample(self, X: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A sample of Δs (SGAT; :meth:`sample_with` of ``rng``'s standard normals); the mean for GAT."""
        mu = self.predict(X)[0]
        if not self.stochastic:
            return mu
        return self.sample_with(X, rng.standard_normal((*mu.shape[:-1], self.noise_dim)))


class InverseModel(_Model):
    """``f_sim^-1``: (state history, state change) -> action applied in the sim.

    Args:
        state_dim, action_dim, history, hidden: as :class:`ForwardModel`.
        commands: d, the actions applied before ``a_t`` that the model also sees, for a sim with an
            actuation delay of d control steps (``GroundingConfig.delay``): there ``a_t`` first moves the
            state d + 1 steps later, while the d actions applied before it are still on their way, so
            the model answers ``s_{t+d+1} - s_t`` given those (:func:`sgat.grounding.command_visibility`
            measures the lead at which a sim shows its commands). 0 (default): the paper's one-step model.

    Input layout: ``[s_{t-k+1}, ..., s_t, a_{t-d}, ..., a_{t-1}, s_{t+d+1} - s_t]``, size k*S + d*A + S;
    output: action (A).

    Raises:
        ValueError: commands < 0.
    """

    kind = "inverse"

    def __init__(self, state_dim: int, action_dim: int, *, history: int = 1, hidden=(64, 64),
                 commands: int = 0):
        self.state_dim, self.action_dim, self.history = int(state_dim), int(action_dim), int(history)
        self.commands = int(commands)
        if self.commands < 0:
            raise ValueError(f"commands must be >= 0, got {commands}")
        super().__init__((self.history + 1) * self.state_dim + self.commands * self.action_dim,
                         self.action_dim, hidden)

    def config(self) -> dict:
        cfg = {**super().config(), "state_dim": self.state_dim, "action_dim": self.action_dim, "history": self.history}
        if self.commands:  # left out at 0, so models saved before it load unchanged
            cfg["commands"] = self.commands
        return cfg

    @classmethod
    def from_config(cls, cfg: dict) -> "InverseModel":
        if cfg.get("command_input"):
            raise ModelFileError("an inverse model that sees the commanded action: this version does not have it")
        return cls(cfg["state_dim"], cfg["action_dim"], history=cfg["history"], hidden=tuple(cfg["hidden"]),
                   commands=int(cfg.get("commands", 0)))

    def _loss(self, out, y):
        return ((out - y) ** 2).mean()

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Action (unnormalised), (..., A)."""
        p = self.numpy_params()
        return self._raw(X) * p["y_std"] + p["y_mean"]
