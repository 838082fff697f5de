"""Cart-table (LIPM) model and Kajita's ZMP preview control.

Model (Kajita et al., "Biped walking pattern generation
by using preview control of zero-moment point", ICRA 2003, eqs. 7-9): per horizontal axis the CoM
at constant height z_c with state x = (c, ċ, c̈), input u = CoM jerk, output the ZMP
p = c - (z_c / g) c̈; discretised with period T:

    x_{k+1} = A x_k + B u_k,   p_k = C x_k,
    A = [[1, T, T²/2], [0, 1, T], [0, 0, 1]],  B = [T³/6, T²/2, T]ᵀ,  C = [1, 0, -z_c/g].

Controller (Kajita 2003 eqs. 16-20, servo form of Katayama et al. 1985): augment the state with the
ZMP tracking error, solve the discrete algebraic Riccati equation (``scipy.linalg.solve_discrete_are``)
with weights Q_e on the error and R on the jerk, and apply

    u_k = -G_i Σ_{i<=k} (p_i - p^ref_i) - G_x x_k - Σ_{j=1..N} G_p(j) p^ref_{k+j}.

Gains are cached per (z_c, R, T, N) (computing them takes ≈10 ms, measured by this project).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import scipy.linalg

from common.defaults import CONTROL_DT

GRAVITY = 9.81


def cart_table(z_c: float, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Discrete cart-table model (A (3, 3), B (3,), C (3,)) for CoM height ``z_c`` [m], period ``dt`` [s]."""
    A = np.array([[1.0, dt, dt * dt / 2.0], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    B = np.array([dt ** 3 / 6.0, dt * dt / 2.0, dt])
    C = np.array([1.0, 0.0, -z_c / GRAVITY])
    return A, B, C


@functools.lru_cache(maxsize=64)
def preview_gains(z_c: float, R: float, dt: float, n_preview: int, Qe: float = 1.0
                  ) -> tuple[float, np.ndarray, np.ndarray]:
    """Kajita preview gains (Kajita 2003 eqs. 17-20).

    Args:
        z_c: CoM height [m] (> 0).
        R: weight on the jerk (the error weight is ``Qe``).
        dt: sample period [s].
        n_preview: number N of future ZMP references used.

    Returns:
        (G_i (scalar), G_x (3,), G_p (N,)); ``G_p[j - 1]`` multiplies ``p_ref[k + j]``. The arrays
        are read-only (shared by the cache).

    Raises:
        ValueError: non-positive z_c, R, dt or n_preview.
    """
    if not (z_c > 0 and R > 0 and dt > 0 and n_preview > 0):
        raise ValueError(f"preview gains need z_c, R, dt, n_preview > 0; got {z_c}, {R}, {dt}, {n_preview}")
    A, B, C = cart_table(z_c, dt)
    At = np.zeros((4, 4))
    At[0, 0] = 1.0
    At[0, 1:] = C @ A
    At[1:, 1:] = A
    Bt = np.concatenate([[C @ B], B])[:, None]
    Qt = np.zeros((4, 4))
    Qt[0, 0] = Qe
    Rm = np.array([[R]])
    P = scipy.linalg.solve_discrete_are(At, Bt, Qt, Rm)
    S = float(R + (Bt.T @ P @ Bt)[0, 0])
    K = (Bt.T @ P @ At)[0] / S
    Gi, Gx = float(K[0]), K[1:].copy()
    Ac = At - Bt @ K[None, :]
    I1 = np.array([1.0, 0.0, 0.0, 0.0])
    X = -Ac.T @ P @ I1
    Gp = np.empty(n_preview)
    Gp[0] = -Gi
    for j in range(1, n_preview):
        Gp[j] = float(Bt[:, 0] @ X) / S
        X = Ac.T @ X
    Gx.setflags(write=False)
    Gp.setflags(write=False)
    return Gi, Gx, Gp


class ZmpPreview:
    """Kajita ZMP preview controller on both horizontal axes at once.

    Args:
        z_c: LIPM height [m].
        log10_R: log10 of the jerk weight R (error weight Q_e = 1).
        dt: period [s] (the walk engine's 10 ms control period).
        horizon: preview horizon [s] (N = round(horizon / dt)).

    State: ``x`` of shape (3, 2): rows (position [m], velocity [m/s], acceleration [m/s²]),
    columns (x, y); ``err_sum`` (2,) the summed ZMP error [m].
    """

    def __init__(self, z_c: float, log10_R: float = -6.0, dt: float = CONTROL_DT, horizon: float = 1.0):
        self.z_c, self.dt = float(z_c), float(dt)
        self.R = 10.0 ** float(log10_R)
        self.n = int(round(horizon / dt))
        self.A, self.B, self.C = cart_table(self.z_c, self.dt)
        self.Gi, self.Gx, self.Gp = preview_gains(self.z_c, self.R, self.dt, self.n)
        self._CG = np.vstack([self.C, self.Gx])  # one product gives the ZMP and G_x x
        self._Bc = self.B[:, None]
        self.x = np.zeros((3, 2))
        self.err_sum = np.zeros(2)

    def reset(self, com_xy) -> None:
        """CoM at rest at ``com_xy`` [m], shape (2,); zero integral error."""
        self.x = np.zeros((3, 2))
        self.x[0] = com_xy
        self.err_sum = np.zeros(2)

    def zmp(self) -> np.ndarray:
        """ZMP of the current state, p = c - z_c/g c̈ [m], shape (2,)."""
        return self.C @ self.x

    def step(self, ref: np.ndarray) -> np.ndarray:
        """Advance one period.

        Args:
            ref: ZMP references [m], shape (N + 1, 2): ``ref[0]`` for the current sample k,
                ``ref[1:]`` for k + 1 .. k + N.

        Returns:
            The new state x_{k+1}, shape (3, 2) (a view of the controller's state).
        """
        cg = self._CG @ self.x  # rows: C x (the ZMP), G_x x
        self.err_sum += cg[0] - ref[0]
        u = -self.Gi * self.err_sum - cg[1] - self.Gp @ ref[1:self.n + 1]
        self.x = self.A @ self.x + self._Bc * u
        return self.x

    def plan(self, ref: np.ndarray, com0=None) -> tuple[np.ndarray, np.ndarray]:
        """Run the controller over a whole reference (held at its last value beyond the end).

        Args:
            ref: ZMP reference [m], shape (M, 2).
            com0: initial CoM position (2,) at rest (default ``ref[0]``).

        Returns:
            (com states (M, 3, 2) at samples 0..M-1, ZMP from the cart-table output (M, 2)).
        """
        ref = np.asarray(ref, dtype=float)
        M = len(ref)
        padded = np.concatenate([ref, np.repeat(ref[-1:], self.n + 1, axis=0)])
        self.reset(ref[0] if com0 is None else com0)
        X = np.empty((M, 3, 2))
        for k in range(M):
            X[k] = self.x
            self.step(padded[k:k + self.n + 1])
        return X, np.einsum("i,kij->kj", self.C, X)


def lipm_period_sway(z_c: float, step_period: float, half_width: float) -> float:
    """Peak lateral CoM excursion [m] of a LIPM switching its ZMP between ±``half_width`` every
    ``step_period`` [s] (periodic orbit, no double support): half_width * (1 - 1/cosh(ωT/2)) with
    ω = sqrt(g / z_c). A quick sanity number for tests and reports."""
    w = math.sqrt(GRAVITY / z_c)
    return half_width * (1.0 - 1.0 / math.cosh(w * step_period / 2.0))
