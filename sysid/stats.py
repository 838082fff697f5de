"""Localisation statistics on replay residuals (the localisation step of the :mod:`sysid` pipeline): descriptive only.

All functions take residuals ``e = y_real - y_sim`` per window, shape (L, k), and the matching
replay outputs; row 0 of each window (the measured start state) is skipped.
"""

from __future__ import annotations

import mujoco
import numpy as np

from sysid.data import Log
from sysid.replay import Window

#: Time after a foot's contact onset that counts as a touchdown window [s] (a project choice).
TOUCHDOWN_S = 0.1
#: Foot force that counts as contact [N].
CONTACT_N = 2.0


def noise_sigma(residuals: list[np.ndarray], cmds: list[np.ndarray] | None = None) -> np.ndarray:
    """Per-channel white-noise level σ [signal units] from the high-frequency part of residuals.

    Third differences suppress the smooth model error (a 4 Hz motion at 100 Hz loses ~98 %) while
    white noise of std σ gives std σ·sqrt(20); the median absolute deviation keeps the estimate
    robust to the samples where a mismatch is fast. Where ``cmds`` are given, samples with a
    moving command are left out when at least 100 still samples remain.

    Args:
        residuals: per window, (L, k).  cmds: per window, (L, k) commands (same channels) or None.

    Returns:
        (k,) σ estimates (0 where a channel is constant).
    """
    d3 = []
    for i, e in enumerate(residuals):
        if len(e) < 8:
            continue
        d = np.diff(e[1:], n=3, axis=0)
        if cmds is not None:
            c = cmds[i]
            still = np.all(np.abs(np.diff(c[1:], axis=0)) < 1e-9, axis=1)
            keep = still[:-2] & still[1:-1] & still[2:]
            if keep.sum() >= 100:
                d = d[keep]
        d3.append(d)
    d3 = np.concatenate(d3)
    mad = np.median(np.abs(d3 - np.median(d3, axis=0)), axis=0)
    return mad / 0.6745 / np.sqrt(20.0)


def _acf(x: np.ndarray, lags: int) -> np.ndarray:
    x = x - x.mean()
    v = float(x @ x)
    if v <= 0:
        return np.zeros(lags)
    return np.array([float(x[:-k] @ x[k:]) / v for k in range(1, lags + 1)])


def integrated_autocorr(residuals: list[np.ndarray], max_lag: int = 50) -> float:
    """Integrated autocorrelation time [samples] of residuals (1 for white noise): 1 + 2 Σ ρ_k up to
    the first non-positive ρ, averaged over channels with energy. Used to inflate Gauss-Newton
    intervals (:func:`sysid.identify.confidence`)."""
    taus = []
    for e in residuals:
        for j in range(e.shape[1]):
            x = e[1:, j]
            if len(x) < 4 * max_lag or np.std(x) == 0:
                continue
            r = _acf(x, max_lag)
            cut = np.argmax(r <= 0) if np.any(r <= 0) else max_lag
            taus.append(1.0 + 2.0 * r[:cut].sum())
    return float(np.median(taus)) if taus else 1.0


def _lag(real: np.ndarray, sim: np.ndarray, dt: float, max_lag_s: float = 0.12) -> float:
    """Lag [s] of ``real`` behind ``sim`` at the peak of the velocity cross-correlation (parabolic)."""
    a = np.diff(real)
    b = np.diff(sim)
    a, b = a - a.mean(), b - b.mean()
    K = int(round(max_lag_s / dt))
    if len(a) <= 2 * K + 2 or np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    c = np.array([a[K + k:len(a) - K + k] @ b[K:len(b) - K] for k in range(-K, K + 1)])
    i = int(np.argmax(c))
    frac = 0.0
    if 0 < i < len(c) - 1:
        den = c[i - 1] - 2 * c[i] + c[i + 1]
        frac = 0.5 * (c[i - 1] - c[i + 1]) / den if den != 0 else 0.0
    return (i - K + frac) * dt


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    den = np.sqrt((a @ a) * (b @ b))
    return float(a @ b / den) if den > 0 else 0.0


def gravity_torque(model: mujoco.MjModel, qadr: np.ndarray, dadr: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Gravity torque [N m] on each joint at angles ``q`` (L, n), zero velocity: shape (L, n), n = the
    robot's joint count (``len(qadr)``)."""
    d = mujoco.MjData(model)
    out = np.empty_like(q)
    for k in range(len(q)):
        d.qpos[qadr] = q[k]
        d.qvel[:] = 0.0
        mujoco.mj_fwdPosition(model, d)
        mujoco.mj_fwdVelocity(model, d)
        out[k] = d.qfrc_bias[dadr]
    return out


def phases(log: Log, w: Window) -> np.ndarray:
    """Gait-phase label per row of a window: 0 in air / no contact, 1 double support, 2 left single,
    3 right single, plus 10 for rows within :data:`TOUCHDOWN_S` after a foot's contact onset."""
    L = w.length
    if log.fsr is None or log.fixed_base:
        return np.zeros(L, dtype=int)
    f = log.fsr[w.k0:w.k1] > CONTACT_N
    lab = np.where(f[:, 0] & f[:, 1], 1, np.where(f[:, 0], 2, np.where(f[:, 1], 3, 0)))
    onset = np.zeros(L, dtype=bool)
    full = log.fsr[:, :] > CONTACT_N
    n_td = int(round(TOUCHDOWN_S / log.control_dt))
    for s in range(2):
        on = np.flatnonzero(full[1:, s] & ~full[:-1, s]) + 1
        for k in on:
            a, b = max(k, w.k0), min(k + n_td, w.k1)
            if a < b:
                onset[a - w.k0:b - w.k0] = True
    return lab + 10 * onset


PHASE_NAMES = {0: "in air / no contact", 1: "double support", 2: "left single support", 3: "right single support"}


def localisation(logs: list[Log], wins: list[Window], y_sim: list[np.ndarray], floor: np.ndarray,
                 names: list[str], model: mujoco.MjModel | None = None, qadr=None, dadr=None) -> dict:
    """Per-channel statistics of the nominal replay residual (descriptive; see the module docstring).

    Args:
        logs: the recordings.  wins: the replayed windows, each naming its log by index into
            ``logs`` (a log cut into several windows has several).  y_sim: per window, (L, k)
            nominal predictions.
        floor: (k,) noise floor per channel (σ, with the engine gap where calibrated).
        names: k channel names (the robot's n joints, then IMU channels if any; n = the logs'
            joint count, ``Log.q.shape[1]``).
        model, qadr, dadr: a replay model for gravity torques (joints only); skipped when None.

    Returns:
        dict with ``channels`` (name -> rms, rms_over_floor, lag_ms, bias, corr_sign_v, corr_v,
        corr_acc, corr_tracking, corr_gravity, whiteness), ``groups`` (encoders / imu ->
        rms_over_floor) and ``phases`` (label -> residual energy / floor² per sample, samples,
        and touchdown/other ratio).

    Raises:
        ValueError: a different number of windows and predictions.
    """
    k = len(names)
    nj = logs[0].q.shape[1]  # joint channels come first
    E, S, Y, C, G, P = [], [], [], [], [], []
    from sysid.replay import measured

    if len(wins) != len(y_sim):
        raise ValueError(f"{len(wins)} windows but {len(y_sim)} predictions")
    for w, ys in zip(wins, y_sim):
        lg = logs[w.log]  # windows name their log: a log cut into several windows has one per window
        ym = measured(lg, w, with_imu=k > nj)
        E.append((ym - ys)[1:])
        S.append(ys[1:])
        Y.append(ym[1:])
        C.append(lg.cmd[w.k0:w.k1][1:])
        P.append(phases(lg, w)[1:])
        if model is not None:
            G.append(gravity_torque(model, qadr, dadr, ys[1:, :nj]))
    dt = logs[0].control_dt
    e_all = np.concatenate(E)
    chans = {}
    for j in range(k):
        ej = e_all[:, j]
        rms = float(np.sqrt(np.mean(ej ** 2)))
        lags = [_lag(y[:, j], s[:, j], dt) for y, s in zip(Y, S)]
        lags = [v for v in lags if np.isfinite(v)]
        v = np.concatenate([np.gradient(s[:, j], dt) for s in S])
        a = np.concatenate([np.gradient(np.gradient(s[:, j], dt), dt) for s in S])
        st = {"rms": rms, "rms_over_floor": rms / floor[j] if floor[j] > 0 else float("inf"),
              "lag_ms": 1000 * float(np.median(lags)) if lags else float("nan"),
              "bias": float(ej.mean()),
              "corr_sign_v": _corr(ej, np.sign(v)), "corr_v": _corr(ej, v), "corr_acc": _corr(ej, a),
              "whiteness": [float(x) for x in np.mean([_acf(e[:, j], 5) for e in E], axis=0)]}
        if j < nj:
            st["corr_tracking"] = _corr(ej, np.concatenate([c[:, j] - s[:, j] for c, s in zip(C, S)]))
            if G:
                st["corr_gravity"] = _corr(ej, np.concatenate([g[:, j] for g in G]))
        chans[names[j]] = st
    fl2 = floor ** 2
    groups = {"encoders": float(np.sqrt(np.mean(e_all[:, :nj] ** 2 / fl2[:nj])))}
    if k > nj:
        groups["imu"] = float(np.sqrt(np.mean(e_all[:, nj:] ** 2 / fl2[nj:])))
    p_all = np.concatenate(P)
    en = np.mean(e_all ** 2 / fl2, axis=1)
    ph = {}
    for lab, nm in PHASE_NAMES.items():
        sel = (p_all % 10) == lab
        if sel.any():
            ph[nm] = {"energy": float(en[sel].mean()), "samples": int(sel.sum())}
    td = p_all >= 10
    if td.any() and (~td).any():
        ph["touchdown/other"] = float(en[td].mean() / en[~td].mean())
    return {"channels": chans, "groups": groups, "phases": ph}
