"""Replay: drive MuJoCo with a recording's commands from its measured state, many models at once.

Timing (calibrated against ``envs.recording``'s convention, see ``tests/test_sysid_replay.py``):
row ``k`` of a log is the state after ``k * substeps`` physics steps; the command of row ``k`` is
held for the ``substeps`` physics steps that follow. :func:`mujoco.rollout.rollout` reports the
sensor values computed at the start of each step, so sensor row ``i * substeps`` is log row
``k0 + i`` of a replay started at row ``k0``.

A :class:`Window` is a stretch of one log replayed from the measured state at its first row (for a
floating base: the log's ``gt.*`` ground truth if it carries it, else the state estimated from IMU,
encoders and foot forces, :mod:`sysid.estimate`).
Single shooting uses one window per log; windowed replay (multiple shooting, Ribeiro et al., "On the
smoothness of nonlinear system identification", Automatica 2020) cuts floating-base logs into short
windows, each restarted from the measured state. All
(parameter set, window) pairs of one model layout and length go through one batched, threaded
``rollout`` call (MuJoCo documentation, Python bindings, "rollout"), in chunks that bound memory.
"""

from __future__ import annotations

import collections
import copy
import os
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from common.spatial import quat_roll_pitch
from sysid.candidates import Term, apply_terms, readout, series_structure
from sysid.data import Log, has_ground_truth
from sysid.model import Structure, replay_model

#: (parameter set, window) pairs per batched ``rollout`` call (bounds memory).
_CHUNK = 24
#: Names of the IMU channels that follow the joint channels of a floating-base replay with IMU.
IMU_CHANNELS = ("angle.roll", "angle.pitch", "gyro.x", "gyro.y", "gyro.z")


def n_threads() -> int:
    """Rollout threads: ``SGATWALK_SYSID_THREADS`` or the CPU count (at most 8)."""
    env = os.environ.get("SGATWALK_SYSID_THREADS")
    if env:
        return max(1, int(env))
    return max(1, min(8, os.cpu_count() or 1))


_POOL: dict = {}
#: MuJoCo's own warnings (``mju_warning``) raised during replays, counted by message: probe models
#: and diverging candidates make the solver warn thousands of times ("Linesearch objective is not
#: convex", "Nan, Inf or huge value in QACC"), which MuJoCo's default handler prints to stdout (it
#: would break ``--json`` output) and appends to ``MUJOCO_LOG.TXT`` in the working directory. A
#: diverged replay is already handled (its prediction holds its last value, non-finite ones are NaN).
MUJOCO_WARNINGS: collections.Counter = collections.Counter()


def _count_warning(msg: str) -> None:
    MUJOCO_WARNINGS.update([msg.split(". Time =")[0]])


class _CountedMujocoWarnings:
    """Context: MuJoCo warnings go to :data:`MUJOCO_WARNINGS` (``mujoco.set_mju_user_warning``) while
    replays run; the process's previous handler (or MuJoCo's default) is restored afterwards."""

    def __enter__(self):
        self.prev = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(_count_warning)

    def __exit__(self, *exc):
        mujoco.set_mju_user_warning(self.prev)
        return False


def _pool():
    nt = n_threads()
    if _POOL.get("n") != nt:
        if _POOL.get("pool") is not None:
            _POOL["pool"].close()
        _POOL["pool"] = mj_rollout.Rollout(nthread=nt)
        _POOL["n"] = nt
    return _POOL["pool"], nt


@dataclass(frozen=True)
class Window:
    """Rows ``[k0, k1)`` of log ``log`` (an index into the log list), replayed from row ``k0``."""

    log: int
    k0: int
    k1: int

    @property
    def length(self) -> int:
        return self.k1 - self.k0


def whole_logs(logs: list[Log], idx=None) -> list[Window]:
    """One window per log (single shooting)."""
    idx = range(len(logs)) if idx is None else idx
    return [Window(i, 0, len(logs[i])) for i in idx]


def windows(logs: list[Log], idx, seconds: float) -> list[Window]:
    """Cut logs ``idx`` into consecutive windows of ``seconds`` (the last partial one dropped if < half)."""
    out = []
    for i in idx:
        w = max(2, int(round(seconds / logs[i].control_dt)))
        n = len(logs[i])
        for k0 in range(0, n - 1, w):
            k1 = min(n, k0 + w)
            if k1 - k0 >= max(2, w // 2):
                out.append(Window(i, k0, k1))
    return out


def measured(log: Log, w: Window, with_imu: bool) -> np.ndarray:
    """Measured outputs of a window, shape (L, n) for the robot's n joints, or (L, n + 5) with IMU
    (roll, pitch, gyro x y z: :data:`IMU_CHANNELS`)."""
    y = log.q[w.k0:w.k1]
    if with_imu:
        y = np.concatenate([y, log.imu["angle"][w.k0:w.k1], log.imu["gyro"][w.k0:w.k1]], axis=1)
    return y


def _cmd_history(log: Log, k0: int, nsample: int) -> np.ndarray:
    """(nsample, n) commands active at physics times -(nsample..1)*physics_dt before row k0."""
    sub = log.substeps
    back = np.arange(nsample, 0, -1)  # physics steps before the start
    rows = k0 - (back + sub - 1) // sub
    return log.cmd[np.clip(rows, 0, None)]


def _start_velocity(log: Log, k: int) -> np.ndarray:
    if log.dq is not None:
        return log.dq[k]
    if k == 0:
        return np.zeros(log.q.shape[1])
    k1 = min(len(log) - 1, k + 1)
    return (log.q[k1] - log.q[k - 1]) / ((k1 - k + 1) * log.control_dt)


def _base_state(log: Log, k: int) -> dict | None:
    """The floating base's state at row ``k``: the log's ``gt.*`` ground truth when it carries it
    (:func:`sysid.data.has_ground_truth`; :func:`sysid.data.load_logs` and :func:`sysid.diagnose.diagnose`
    drop it unless asked), else the estimate of :func:`sysid.estimate.base_state`."""
    if has_ground_truth(log):
        g = log.gt
        return {"pos": g["gt.base"][k], "quat": g["gt.quat"][k], "linvel": g["gt.vel"][k],
                "angvel": g["gt.angvel"][k]}
    from sysid.estimate import base_state  # floating logs without ground truth
    return base_state(log, k)


def build_models(values_list: list[dict[Term, float]], structure: Structure) -> list[tuple]:
    """Compile/copy one model per parameter set for the robot ``structure.robot`` (n joints): (replay
    model, edited MjModel copy, (n,) log offsets [rad], (meas, servo offsets)) with ``meas`` the
    (n, nsensordata) sensor-to-log map and the (n,) offsets [rad] the servos see
    (:func:`sysid.candidates.readout`)."""
    out = []
    for vals in values_list:
        rm = replay_model(series_structure(structure, vals))
        m = copy.copy(rm.model)
        bias = apply_terms(rm, m, vals)
        out.append((rm, m, bias, readout(rm, vals)))
    return out


def _unpack(model_entry) -> tuple:
    """(rm, m, log offsets, meas, servo offsets) of a :func:`build_models` entry (a 3-tuple without
    its readout reads with ``rm.meas`` and no servo offset)."""
    rm, m, bias = model_entry[:3]
    if len(model_entry) > 3:
        meas, servo = model_entry[3]
    else:
        meas, servo = rm.meas, np.zeros(len(bias))
    return rm, m, bias, meas, servo


def predict(logs: list[Log], wins: list[Window], values_list: list[dict[Term, float]], *,
            with_imu: bool = False, models=None) -> list[np.ndarray]:
    """Replay every window under every parameter set.

    Args:
        logs: the recordings.  wins: windows to replay.
        values_list: parameter sets (term -> physical value); ``{}`` is the plain sim.
        with_imu: also predict torso roll/pitch and gyro (floating base only).
        models: optional prebuilt :func:`build_models` output (same order as ``values_list``).

    Returns:
        One array per window, shape (n_sets, L, ny), ny = n (+5 with IMU), n = the joint count of the
        logs' robot (``Log.robot``): predicted measured outputs at the window's rows (row 0 is the
        measured start state). Diverged replays hold their last value (MuJoCo's rollout padding);
        NaN marks a non-finite prediction.
    """
    lg0 = logs[wins[0].log]
    structure = Structure(fixed_base=lg0.fixed_base, physics_dt=lg0.physics_dt, robot=lg0.robot_name)
    if models is None:
        models = build_models(values_list, structure)
    ny = lg0.q.shape[1] + (len(IMU_CHANNELS) if with_imu else 0)
    out = [np.empty((len(values_list), w.length, ny)) for w in wins]
    # group (set, window) pairs by model size signature and window length
    groups: dict = {}
    for s, entry in enumerate(models):
        rm = entry[0]
        for wi, w in enumerate(wins):
            key = (rm.structure.size_key, w.length)
            groups.setdefault(key, []).append((s, wi))
    pool, nt = _pool()
    for (_, L), pairs in groups.items():
        for c0 in range(0, len(pairs), _CHUNK):
            chunk = pairs[c0:c0 + _CHUNK]
            sub = lg0.substeps
            nstep = (L - 1) * sub + 1
            mlist, states, ctrls = [], [], []
            for s, wi in chunk:
                rm, m, bias, _, servo = _unpack(models[s])
                w = wins[wi]
                lg = logs[w.log]
                q0 = lg.q[w.k0] - bias
                base = None if lg.fixed_base else _base_state(lg, w.k0)
                states.append(rm.initial_state(m, q0, _start_velocity(lg, w.k0),
                                               _cmd_history(lg, w.k0, rm.nsample) - servo, base))
                rows = w.k0 + np.arange(nstep) // sub
                c = np.zeros((nstep, m.nu))
                c[:, rm.act] = lg.cmd[rows] - servo
                ctrls.append(c)
                mlist.append(m)
            rm0 = models[chunk[0][0]][0]
            datas = [mujoco.MjData(mlist[0]) for _ in range(nt)]
            sens = np.empty((len(chunk), nstep, mlist[0].nsensordata))
            with _CountedMujocoWarnings():
                pool.rollout(mlist, datas, np.asarray(states), np.asarray(ctrls), nstep=nstep, skip_checks=True,
                             state=None, sensordata=sens, control_spec=mujoco.mjtState.mjSTATE_CTRL.value,
                             initial_warmstart=None, chunk_size=max(1, len(chunk) // (nt * 2)))
            sens = sens[:, ::sub]  # (n, L, nsens)
            for j, (s, wi) in enumerate(chunk):
                rm, m, bias, meas, _ = _unpack(models[s])
                y = sens[j] @ meas.T + bias
                if with_imu:
                    qa, ga = rm.quat_adr, rm.gyro_adr
                    y = np.concatenate([y, quat_roll_pitch(sens[j][:, qa:qa + 4]), sens[j][:, ga:ga + 3]], axis=1)
                out[wi][s] = y
            del rm0
    for o in out:
        o[~np.isfinite(o)] = np.nan
    return out
