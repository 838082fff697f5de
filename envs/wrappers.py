"""Action-level "real" effects as gymnasium wrappers, for any Box-action env.

:class:`ActionMismatch` turns a sim into a "real" world with a known joint-level difference:
``a_applied = ref + gain * (a - ref) + offset + N(0, noise_std^2)`` on selected action entries,
clipped to the action space. It always works on a copy: the agent's (and the logger's) array is
never modified in place -- the trap that silently turned logged actions into noisy ones in the
GARAT code (Desai et al., NeurIPS 2020: ``NoisyRealEnv.action`` in ``rl_gat/gat.py`` adds the noise
in place). The applied action is reported as
``info["applied_action"]``.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np


class ActionMismatch(gym.Wrapper):
    """A known actuator mismatch: gain, offset and Gaussian noise on selected action entries.

    Args:
        env: a gymnasium env with a Box action space.
        gain: scale of the command's deviation from ``reference`` (scalar or per selected entry).
        offset: added to the selected entries [action units].
        noise_std: standard deviation of Gaussian noise on the selected entries [action units].
        index: which action entries are affected (default: all).
        reference: the point the gain scales around (default: zeros).
        seed: noise seed when ``reset`` gets none; ``reset(seed=s)`` re-seeds from s.
    """

    def __init__(self, env: gym.Env, *, gain=1.0, offset=0.0, noise_std=0.0, index=None, reference=None, seed: int = 0):
        super().__init__(env)
        n = env.action_space.shape[0]
        self.index = np.arange(n) if index is None else np.asarray(index)
        self.gain = np.broadcast_to(np.asarray(gain, dtype=float), self.index.shape).copy()
        self.offset = np.broadcast_to(np.asarray(offset, dtype=float), self.index.shape).copy()
        self.noise_std = np.broadcast_to(np.asarray(noise_std, dtype=float), self.index.shape).copy()
        if np.any(self.noise_std < 0):
            raise ValueError("noise_std must be >= 0")
        self.reference = np.zeros(n) if reference is None else np.asarray(reference, dtype=float)
        self.seed = seed
        self.rng = np.random.default_rng(seed)

    def reset(self, *, seed=None, options=None):
        self.reseed(seed)
        return self.env.reset(seed=seed, options=options)

    def reseed(self, seed=None) -> None:
        """The noise generator of an episode with ``seed`` (what :meth:`reset` does before the env's reset)."""
        self.rng = np.random.default_rng(self.seed if seed is None else np.random.SeedSequence([int(seed), 0xA71]))

    def perturb(self, action) -> np.ndarray:
        """The applied action for ``action`` (a new array; ``action`` is untouched)."""
        out = np.array(action, dtype=np.float64)  # copy
        i = self.index
        out[i] = self.reference[i] + self.gain * (out[i] - self.reference[i]) + self.offset
        if np.any(self.noise_std > 0):
            out[i] += self.rng.standard_normal(len(i)) * self.noise_std
        return np.clip(out, self.action_space.low, self.action_space.high)

    def step(self, action):
        applied = self.perturb(action)
        obs, r, term, trunc, info = self.env.step(applied)
        info = dict(info)
        info["applied_action"] = applied
        return obs, r, term, trunc, info
