"""Terrain roughness as a fitted *distribution* of ground surfaces (BayesSim/DROPO-style, below).

Uneven ground is not a value the sim lacks but a random surface under the feet that nobody
measured: replaying a log on flat ground leaves a residual that no deterministic term removes
(the surface differs from log to log), concentrated in the torso angles, the ankles and the
stance phases. The sim cannot replay the true surface, only surfaces drawn from a distribution;
so the family is fitted by matching statistics, the way BayesSim/ABC fit stochastic effects,
with DROPO's short windows restarted from the measured state:

1. **Simulated real logs.** For each RMS height ``A`` of a grid and ``S`` random surfaces per
   grid point, each log's commands are run open-loop in MuJoCo on the surface, from the log's
   initial posture with the feet set on the surface (:func:`simulate_on_surfaces`). These logs are
   consistent with their ground (the robot stands on what is simulated), as a real log is.
2. **Same statistic as the real logs.** They are replayed exactly like the real ones (windowed,
   on flat ground, under the current model); the excess cost ε(A) = Σ_channels mean(e²/floor²)
   is the statistic the diagnosis already uses, with its per-channel profile v_c(A); the windows
   start from the same kind of base state as the recordings' (estimated unless they carry ground truth).
3. **Fit.** Â solves ε(Â) = ε_obs (the windows' cost above the channel count, all logs: a robot
   stepping in place samples only the few spots its feet stand on, so one log is one draw of the
   surface and the fit needs every draw there is), by interpolation of the monotone curve in
   log-log coordinates; its 95 % interval comes from a bootstrap over logs (observed) and surfaces
   (simulated).
4. **Held-out check.** A random surface cannot lower the held-out RMS (it is not the surface that
   was there); what the distribution must do is account for the held-out residual. Flat ground
   predicts a held-out excess of 0: the held-out logs must show one above the selection margin,
   with the residual where uneven ground puts it (cosine of the per-channel excess profiles,
   observed vs simulated at Â, >= 0.5). The rank of each held-out log's excess among the simulated
   logs' (every log and surface, rescaled from the nearest grid amplitude by ε(Â)/ε(A)) is reported
   as a plausibility measure, not a gate: a robot stepping in place samples only the few spots its
   feet stand on, and the model's dense random field varies less from spot to spot than sparse
   bumps do (measured: PyBullet logs on sparse bumps fall below the simulated 5th percentile).

Surface model (different code and form from the blind referee's sparse Gaussian bumps of
``terrain.lumpy``): a Gaussian random field, white noise filtered with a Gaussian kernel of
:data:`CORRELATION_RADIUS` (``scipy.ndimage.gaussian_filter``), scaled to RMS height ``Sq`` over the
2 x 2 m patch under the robot (ISO 25178 areal roughness: the standard deviation of the height
about its mean plane); this RMS height [m] is the family's value. It is a property of the ground
the feet feel, where the largest excursion over the patch (also reported, as the model's surfaces'
peak at that Sq) depends on the surface family: at the same peak the dense field is rougher than
sparse bumps (measured: 1.26x the RMS height and slope of ``terrain.lumpy``'s fields, which made a
peak-height fit 33 % low). The correlation radius is an assumption of the model (8 cm: foam, turf,
gravel-sized lumps), stated in the report.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from common.spatial import quat_roll_pitch, quat_to_mat
from sysid.candidates import FAMILIES, apply_terms, readout, series_structure
from sysid.data import Log, has_ground_truth, without_ground_truth
from sysid.model import TERRAIN_CELL, TERRAIN_SIZE, Structure, replay_model, set_terrain
from sysid.replay import (Window, _CountedMujocoWarnings, _base_state, _cmd_history, _pool, _start_velocity, build_models,
                          measured, predict)
from terrain import gaussian

#: Correlation radius of the surface model [m] (standard deviation of the smoothing kernel).
CORRELATION_RADIUS = 0.08
#: RMS-height grid [m] (Sq over the patch); 0 is the flat reference (peaks ~3.5-4x these).
RMS_HEIGHTS = (0.0, 0.0008, 0.0016, 0.0027, 0.004, 0.006, 0.0085)
#: Smallest RMS height the report names [m] (the family's smallest reported effect).
MIN_RMS_HEIGHT = FAMILIES["terrain_roughness"].min_effect
#: Largest RMS height a model surface may have [m] (the family's upper bound).
MAX_RMS_HEIGHT = FAMILIES["terrain_roughness"].hi
#: Smallest held-out excess [floor², summed over channels] and per-channel profile agreement.
MIN_HELDOUT_EXCESS = 0.25
MIN_PROFILE_COSINE = 0.5


def surface(rms_height: float, seed) -> np.ndarray:
    """A random ground surface of the candidate model: heights [m], shape (51, 51) on the 4 cm
    grid of the 2 x 2 m patch of :data:`sysid.model.TERRAIN_SIZE` (row = y, from -1 m), with mean 0
    and standard deviation ``rms_height`` (Sq, ISO 25178).

    Args:
        rms_height: RMS height about the mean plane [m] (>= 0, <= :data:`MAX_RMS_HEIGHT`).
        seed: anything :func:`numpy.random.default_rng` accepts.

    Raises:
        ValueError: rms_height outside [0, MAX_RMS_HEIGHT].
    """
    if not 0.0 <= rms_height <= MAX_RMS_HEIGHT:
        raise ValueError(f"terrain RMS height must be within [0, {MAX_RMS_HEIGHT}] m, got {rms_height}")
    return gaussian(seed, rms_height, CORRELATION_RADIUS, size=(2 * TERRAIN_SIZE[0], 2 * TERRAIN_SIZE[1]),
                    cell_size=TERRAIN_CELL, start_radius=0.0).heights


def _height_at(h: np.ndarray, x: float, y: float) -> float:
    from terrain import Heightfield

    hx, hy = TERRAIN_SIZE
    return float(Heightfield(h, TERRAIN_CELL).height_at(np.clip(x, -hx, hx), np.clip(y, -hy, hy)))


def _foot_forces(m: mujoco.MjModel, rm, states: np.ndarray, cmd: np.ndarray) -> np.ndarray:
    """(L, 2) total normal force under the left and right foot [N] of each full physics state
    (``mjSTATE_FULLPHYSICS`` rows of the replay model ``rm``, ``m`` its edited copy) with the servo
    targets of ``cmd`` (L, n) [rad] (row ``k``: the command that drove the step into state ``k``),
    what a recording's ``fsr`` columns hold (the sim world's sum,
    :func:`envs.mujoco_world.foot_contact_sums`)."""
    from envs.mujoco_world import foot_contact_sums

    feet = {rm.robot.frames["l_sole"].link: 0, rm.robot.frames["r_sole"].link: 1}
    geom_foot = np.array([feet.get(m.body(m.geom_bodyid[g]).name, -1) for g in range(m.ngeom)])
    ground = m.geom("ground").id
    d = mujoco.MjData(m)
    out = np.zeros((len(states), 2))
    for k, x in enumerate(states):
        mujoco.mj_setState(m, d, x, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        d.ctrl[rm.act] = cmd[k]
        mujoco.mj_forward(m, d)
        if d.ncon:
            con = d.contact
            out[k] = foot_contact_sums(con.geom1, con.geom2, d.efc_force[con.efc_address], con.pos, geom_foot,
                                       ground)[0][0]
    return out


def simulate_on_surfaces(logs: list[Log], values: dict, surfaces: list[np.ndarray]) -> list[list[Log]]:
    """Each log's commands run open-loop on each surface, from the log's first row.

    The start state is the log's measured joint angles and base pose at row 0, lifted so the
    lower sole is 0.5 mm above the surface under both soles (like a world reset), with the
    log's start velocities. All (surface, log) pairs go through one threaded
    :func:`mujoco.rollout.rollout` call per log length.

    Args:
        logs: floating-base logs (with base state: ground truth or the estimator's).
        values: the model's terms (term -> value) the simulation runs under.
        surfaces: heights of each surface, shape (51, 51) [m] (see :func:`surface`).

    Returns:
        ``out[s][i]``: log ``i`` simulated on surface ``s``, a noise-free :class:`Log` with the same
        times and commands, measured angles, velocities, IMU roll/pitch/gyro and base ground truth;
        when a log of ``logs`` has no ground truth (its replays estimate the base state), also the
        foot forces (``fsr``, (N, 2) [N]) the estimator takes the stance foot from.

    Raises:
        ValueError: a fixed-base log.
    """
    if any(lg.fixed_base for lg in logs):
        raise ValueError("terrain roughness needs floating-base (standing/stepping) logs")
    lg0 = logs[0]
    st = series_structure(Structure(fixed_base=False, physics_dt=lg0.physics_dt, terrain=True, robot=lg0.robot_name),
                          values)
    rm = replay_model(st)
    nq, nv = rm.model.nq, rm.model.nv
    sole = [rm.model.site(s).id for s in ("l_sole", "r_sole")]
    names = list(rm.robot.joint_names)
    with_fsr = not all(has_ground_truth(lg) for lg in logs)
    out = [[None] * len(logs) for _ in surfaces]
    pool, nt = _pool()
    for L in sorted({len(lg) for lg in logs}):
        idx = [i for i, lg in enumerate(logs) if len(lg) == L]
        sub = logs[idx[0]].substeps
        nstep = (L - 1) * sub + 1
        pairs = [(s, i) for s in range(len(surfaces)) for i in idx]
        for c0 in range(0, len(pairs), 8):  # bounded memory: 8 full-rate state trajectories at a time
            chunk = pairs[c0:c0 + 8]
            mlist, states, ctrls, biases = [], [], [], []
            for s, i in chunk:
                lg = logs[i]
                m = copy.copy(rm.model)
                bias = apply_terms(rm, m, values)
                meas, servo = readout(rm, values)
                set_terrain(m, surfaces[s])
                x0 = rm.initial_state(m, lg.q[0] - bias, _start_velocity(lg, 0), _cmd_history(lg, 0, rm.nsample) - servo,
                                      _base_state(lg, 0))
                d = mujoco.MjData(m)
                mujoco.mj_setState(m, d, x0, mujoco.mjtState.mjSTATE_FULLPHYSICS)
                mujoco.mj_kinematics(m, d)
                feet = [d.site_xpos[k] for k in sole]
                ground = max(_height_at(surfaces[s], p[0], p[1]) for p in feet)
                d.qpos[2] += ground - min(p[2] for p in feet) + 0.0005
                mujoco.mj_getState(m, d, x0, mujoco.mjtState.mjSTATE_FULLPHYSICS)
                rows = np.arange(nstep) // sub
                c = np.zeros((nstep, m.nu))
                c[:, rm.act] = lg.cmd[rows] - servo
                mlist.append(m)
                states.append(x0)
                ctrls.append(c)
                biases.append((bias, meas))
            datas = [mujoco.MjData(mlist[0]) for _ in range(nt)]
            state = np.empty((len(chunk), nstep, rm.nstate))
            sens = np.empty((len(chunk), nstep, mlist[0].nsensordata))
            with _CountedMujocoWarnings():
                pool.rollout(mlist, datas, np.asarray(states), np.asarray(ctrls), nstep=nstep, skip_checks=True,
                             state=state, sensordata=sens, control_spec=mujoco.mjtState.mjSTATE_CTRL.value,
                             initial_warmstart=None, chunk_size=1)
            # rollout reports the state after each step and the sensors at its start: row k of the
            # log is the state after k*sub steps, i.e. the initial state then state[k*sub - 1]
            for j, (s, i) in enumerate(chunk):
                lg = logs[i]
                xs = np.concatenate([np.asarray(states[j])[None], state[j, sub - 1::sub]])[:L]
                ys = sens[j, ::sub][:L]
                qpos, qvel = xs[:, 1:1 + nq], xs[:, 1 + nq:1 + nq + nv]
                q = ys @ biases[j][1].T + biases[j][0]
                dq = qvel[:, rm.dadr].copy()  # measured velocity: motor + play hinge
                for n, a in rm.play_dadr.items():
                    dq[:, names.index(n)] += qvel[:, a]
                quat = qpos[:, 3:7]
                angvel_w = np.einsum("ijn,nj->ni", quat_to_mat(quat.T), qvel[:, 3:6])  # body -> world
                qa, ga = rm.quat_adr, rm.gyro_adr
                imu = {"angle": quat_roll_pitch(ys[:, qa:qa + 4]), "gyro": ys[:, ga:ga + 3].copy()}
                gt = {"gt.base": qpos[:, 0:3].copy(), "gt.quat": quat.copy(), "gt.vel": qvel[:, 0:3].copy(),
                      "gt.angvel": angvel_w}
                fsr = _foot_forces(mlist[j], rm, xs, lg.cmd[np.maximum(np.arange(L) - 1, 0)]) if with_fsr else None
                out[s][i] = Log(name=f"{lg.name}@surface{s}", t=lg.t, cmd=lg.cmd, q=q, dq=dq,
                                control_dt=lg.control_dt, physics_dt=lg.physics_dt, fixed_base=False, imu=imu, gt=gt,
                                fsr=fsr, meta={"robot": lg.robot_name})
    return out


@dataclass
class RoughnessFit:
    """Result of :func:`fit_roughness`.

    Attributes:
        rms_height: fitted RMS height Ŝq [m] (0 when nothing is left to explain).
        ci95: (lo, hi) [m] bootstrap interval.  peak_height: mean largest |height| of the model's
            surfaces at Ŝq [m] (a property of the dense model, not of the real ground).
        grid: RMS heights simulated [m] (the lower part of the grid an adaptive fit needed).
            excess: (n_grid,) simulated excess cost ε(A) per window (mean over surfaces and windows of
            all logs).  excess_obs: observed excess cost per window.
        excess_heldout_obs, excess_heldout_pred: held-out excess cost, observed and predicted at Â.
        heldout_p: smallest two-sided rank p-value of a held-out log's excess among the simulated
            logs' at Â (flat ground: 0 unless the excess is 0).  sim_log_excess: (5, 50, 95)
            percentiles of the simulated per-log excess at Â.  profile_cosine: agreement of the
            per-channel profiles.
        declared: whether the report names the effect; reason: why (not).
        profile_obs, profile_pred: (k,) per-channel held-out excess, observed / predicted at Â.
        n_rollouts: rollouts run (logs simulated on surfaces and windows replayed).  n_fallen:
            simulated windows left out (not replayed) because the open-loop simulation had tipped over.
    """

    rms_height: float
    ci95: tuple[float, float]
    peak_height: float
    grid: list[float]
    excess: list[float]
    excess_obs: float
    excess_heldout_obs: float
    excess_heldout_pred: float
    heldout_p: float
    sim_log_excess: tuple[float, float, float]
    profile_cosine: float
    declared: bool
    reason: str
    profile_obs: list[float] = field(default_factory=list)
    profile_pred: list[float] = field(default_factory=list)
    n_rollouts: int = 0
    n_fallen: int = 0
    excess_heldout_left: float | None = None


def excess_left(rough: RoughnessFit, problem, model: dict) -> tuple[float, float]:
    """What uneven ground still has to explain after the deterministic ``model`` (fitted after the
    roughness, on the same residual): the RMS height [m] whose simulated excess (the curve of
    ``rough``) equals the excess over flat ground ``model`` leaves in all logs, and the held-out
    excess it leaves [floor², summed over channels]. A deterministic effect (low foot friction)
    removes its own excess, which a roughness fit before it had read as uneven ground; a contact
    term fitted on truly uneven ground removes little of it (a random surface is not repeatable).
    Where that excess lies above the heights ``rough`` simulated (its adaptive grid stopped below
    it), the height is the highest one simulated: a lower bound, at or above :data:`MIN_RMS_HEIGHT`,
    so whether the diagnosis withdraws the roughness is decided exactly."""
    ex_tr, ex_ho = _observed_excess(problem, model)
    obs_all = float(np.concatenate([ex_tr, ex_ho]).sum(axis=1).mean())
    left = _invert(np.asarray(rough.grid), np.asarray(rough.excess), obs_all) if obs_all > 0 else 0.0
    return left, float(ex_ho.sum(axis=1).mean())


def _invert(grid: np.ndarray, curve: np.ndarray, target: float) -> float:
    """Amplitude where the (made monotone) excess curve reaches ``target`` (log-log interpolation)."""
    c = np.maximum.accumulate(np.maximum(curve, 1e-9))
    if target <= c[1]:  # below the first non-zero amplitude: ε grows ~A² near 0
        return float(grid[1] * math.sqrt(max(target, 0.0) / c[1]))
    if target >= c[-1]:
        return float(grid[-1])
    j = int(np.searchsorted(c, target))
    a0, a1, e0, e1 = grid[j - 1], grid[j], c[j - 1], c[j]
    if e1 <= e0:
        return float(a1)
    f = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
    return float(math.exp(math.log(a0) + f * (math.log(a1) - math.log(a0))))


def _upright(log: Log, w: Window, max_tilt: float = 0.6) -> bool:
    """Whether a simulated log's torso stays above its robot's fall height (``RobotModel.fall_height``,
    the worlds' rule) and within ``max_tilt`` [rad] of upright over the window."""
    min_height = log.robot.fall_height
    z = log.gt["gt.base"][w.k0:w.k1, 2]
    ang = log.imu["angle"][w.k0:w.k1]
    return bool(np.all(z > min_height) and np.all(np.abs(ang) < max_tilt))


def _excess_per_window(meas: list[np.ndarray], pred: list[np.ndarray], floor: np.ndarray) -> np.ndarray:
    """(n_windows, k) mean squared normalised residual per window and channel (row 0 skipped)."""
    return np.stack([np.mean(((m[1:] - p[1:]) / floor) ** 2, axis=0) for m, p in zip(meas, pred)])


def _observed_excess(problem, model: dict) -> tuple[np.ndarray, np.ndarray]:
    """(train, held-out) per-window, per-channel excess over the floor of the recordings replayed
    under ``model`` on flat ground: ``_excess_per_window - 1`` (0 where only noise is left)."""
    return tuple(_excess_per_window(problem.meas[w], [p[0] for p in problem.predict([model], w)], problem.floor) - 1.0
                 for w in ("train", "heldout"))


def fit_roughness(problem, model: dict, *, n_surfaces: int = 4, seed: int = 0, grid=RMS_HEIGHTS,
                  n_boot: int = 200, adaptive: bool = True) -> RoughnessFit:
    """Fit the terrain-roughness distribution to the residual the deterministic model leaves.

    The grid is simulated bottom-up (``adaptive``): an RMS height is simulated only while the fit
    still needs it, i.e. while the made-monotone excess curve simulated so far stays below the
    observed excess (Â lies higher up) or a bootstrap percentile of the interval lies above it.
    Every figure of the result is then the one the whole grid gives (the curve is made monotone
    from below and inverted between the two points around the target, so the points above the
    bracket never enter; a bootstrap resample above the simulated range is known to lie above every
    resolved one), at the cost of the points it does not need: on the default grid and three
    stepping logs, Â of 3.0-3.7 mm with intervals reaching 4.9-5.2 mm needed 5 of the 6 non-zero
    heights (``benchmarks/bench_roughness_grid.py``). ``adaptive=False`` simulates the whole grid.

    Args:
        problem: the diagnosis' :class:`sysid.identify.Problem` (floating base, IMU channels).
        model: the fitted deterministic terms (the problem's base terms are added).
        n_surfaces: random surfaces per grid point.  seed: seed of the surfaces.
        grid: RMS heights [m], starting with 0, increasing.  n_boot: bootstrap resamples for the interval.
        adaptive: simulate only the grid points the fit needs (bottom-up), else all of them.

    Returns:
        A :class:`RoughnessFit` (see the module docstring for the method and decision rule); its
        ``grid`` and ``excess`` are the heights simulated (always up to the first one at or above
        :data:`MIN_RMS_HEIGHT`, so :func:`excess_left`'s decision is exact as well).

    Raises:
        ValueError: fixed-base problem, or a grid not starting at 0 or not increasing.
    """
    if not problem.with_imu:
        raise ValueError("terrain roughness needs floating-base logs with IMU channels")
    grid = np.asarray(grid, dtype=float)
    if grid[0] != 0.0 or len(grid) < 3 or np.any(np.diff(grid) <= 0):
        raise ValueError("the RMS-height grid must start at 0, increase and have >= 3 points")
    values = {**problem.base, **model}
    floor = problem.floor
    # observed: per-window excess of the current model
    ex_tr, ex_ho = _observed_excess(problem, model)
    obs_ho = float(ex_ho.sum(axis=1).mean())
    ex_all = np.concatenate([ex_tr, ex_ho]).sum(axis=1)
    obs_all = float(ex_all.mean())
    rng_seeds = [[seed, s] for s in range(n_surfaces)]
    used = sorted({w.log for w in problem.train + problem.heldout})
    logs = [problem.logs[i] for i in used]
    remap = {i: j for j, i in enumerate(used)}
    # replayed like the recordings: from the ground-truth base state only if they have it, else from
    # the estimate (its error is part of the recordings' excess too); the simulated logs' own ground
    # truth still tells which of them tipped over
    as_recorded = (lambda sl: sl) if all(has_ground_truth(lg) for lg in logs) else without_ground_truth
    # the simulated logs are replayed on a *flat heightfield*: MuJoCo's box-heightfield contacts differ
    # from box-plane ones (measured: 6-25 mrad torso angle over 6 s open-loop), so the reference must
    # be the same contact model and the statistic measures the surface's unevenness alone
    flat = build_models([values], Structure(fixed_base=False, physics_dt=logs[0].physics_dt, terrain=True,
                                            robot=logs[0].robot_name))
    sim_tr = np.full((len(grid), n_surfaces, len(problem.train), problem.k), np.nan)
    sim_ho = np.full((len(grid), n_surfaces, len(problem.heldout), problem.k), np.nan)
    sim_tr[0] = sim_ho[0] = 0.0
    n_roll = 0
    top = 1  # grid[:top] simulated

    def grow() -> None:
        """The next grid point ``grid[top]``: each log on each of its surfaces, replayed in windows on
        flat ground."""
        nonlocal n_roll, top
        g = top
        top += 1
        sims = simulate_on_surfaces(logs, values, [surface(grid[g], rs) for rs in rng_seeds])
        n_roll += n_surfaces * len(logs)
        for s in range(n_surfaces):
            for which, arr in (("train", sim_tr), ("heldout", sim_ho)):
                wins = [Window(remap[w.log], w.k0, w.k1) for w in problem.wins[which]]
                # an open-loop simulation that tips over is not a sample of walking on that ground: its
                # windows stay NaN and are not replayed (each window is a rollout of its own)
                ok = [i for i, w in enumerate(wins) if _upright(sims[s][w.log], w)]
                if ok:
                    pred = predict(as_recorded(sims[s]), [wins[i] for i in ok], [values], with_imu=True, models=flat)
                    meas = [measured(sims[s][wins[i].log], wins[i], True) for i in ok]
                    arr[g, s, ok] = _excess_per_window(meas, [p[0] for p in pred], floor)
                n_roll += len(ok)

    # Â from every log (each log of a robot stepping in place samples only the few spots its feet
    # stand on: its excess varies from log to log far more than from window to window, so the
    # amplitude takes all the surface samples there are); the held-out logs still decide whether
    # anything is there (below). Interval: bootstrap over logs (observed) and surfaces (simulated).
    win_log = np.array([w.log for w in problem.train + problem.heldout])
    ulog = np.unique(win_log)
    # at least the first non-zero height and up to the smallest reported one (excess_left's decision);
    # everything when not adaptive
    first = min(max(int(np.searchsorted(grid, MIN_RMS_HEIGHT)) + 1, 2), len(grid)) if adaptive else len(grid)
    while top < first:
        grow()

    def beyond(curve: np.ndarray, target: float) -> bool:
        """Whether more grid is left and ``target`` is not below the top of the simulated part of a
        (made monotone) curve; a NaN top (every window simulated there tipped over) resolves nothing,
        so the grid grows on, to the whole grid's inversion at worst."""
        return top < len(grid) and target > 0 and not target < np.maximum.accumulate(np.maximum(curve, 1e-9))[-1]

    while True:
        sim_all = np.concatenate([sim_tr[:top], sim_ho[:top]], axis=2).sum(axis=3)  # (top, S, n_windows)
        curve = np.nanmean(sim_all, axis=(1, 2))
        if beyond(curve, obs_all):
            grow()
            continue
        a_hat = _invert(grid[:top], curve, obs_all) if obs_all > 0 else 0.0
        rng = np.random.default_rng([seed, 99])
        boots = []
        for _ in range(n_boot):
            pick = rng.choice(ulog, len(ulog))
            idx = np.concatenate([np.flatnonzero(win_log == lg) for lg in pick])
            o = float(ex_all[idx].mean())
            ss = rng.integers(0, n_surfaces, n_surfaces)
            c = np.nanmean(sim_all[:, ss][:, :, idx], axis=(1, 2))
            # above the simulated heights: larger than every resolved resample (the inverse is monotone)
            boots.append(math.inf if beyond(c, o) else _invert(grid[:top], c, o) if o > 0 else 0.0)
        with np.errstate(invalid="ignore"):  # inf - inf between two unresolved resamples: NaN, simulated on
            lo, hi = np.percentile(boots, [2.5, 97.5])
        if np.isfinite(hi) or top == len(grid):
            break
        grow()  # a percentile of the interval lies above the simulated heights
    grid, sim_tr, sim_ho = grid[:top], sim_tr[:top], sim_ho[:top]
    n_fallen = int(np.isnan(sim_tr[1:, :, :, 0]).sum() + np.isnan(sim_ho[1:, :, :, 0]).sum())
    # predicted per-channel held-out excess at Â (interpolated between grid profiles, ε ~ A² locally)
    prof_grid = np.nanmean(sim_ho, axis=(1, 2))  # (n_grid, k)
    j = int(np.clip(np.searchsorted(grid, a_hat), 1, len(grid) - 1))
    w = (a_hat ** 2 - grid[j - 1] ** 2) / (grid[j] ** 2 - grid[j - 1] ** 2)
    pred_prof = np.maximum((1 - w) * prof_grid[j - 1] + w * prof_grid[j], 0.0)
    obs_prof = ex_ho.mean(axis=0)
    cos = float(np.dot(np.maximum(obs_prof, 0), pred_prof)
                / max(np.linalg.norm(np.maximum(obs_prof, 0)) * np.linalg.norm(pred_prof), 1e-12))
    # held-out plausibility: per-log excess of each held-out log, ranked among the simulated logs'
    # (all logs, all surfaces) at the nearest grid amplitude, rescaled to Â
    per_log_sim = []
    g = int(np.argmin(np.abs(grid[1:] - a_hat))) + 1
    scale = float(np.interp(a_hat, grid, curve)) / max(curve[g], 1e-12)
    for arr, wins in ((sim_tr, problem.train), (sim_ho, problem.heldout)):
        for lg in sorted({w.log for w in wins}):
            idx = [i for i, w in enumerate(wins) if w.log == lg]
            for s_ in range(n_surfaces):
                v = arr[g, s_, idx].sum(axis=1)
                if np.isfinite(v).any():
                    per_log_sim.append(float(np.nanmean(v)) * scale)
    per_log_sim = np.array(per_log_sim) if per_log_sim else np.zeros(1)
    pcts = tuple(float(v) for v in np.percentile(per_log_sim, [5, 50, 95]))
    ps = []
    for lg in sorted({w.log for w in problem.heldout}):
        idx = [i for i, w in enumerate(problem.heldout) if w.log == lg]
        o = float(ex_ho[idx].sum(axis=1).mean())
        f = (np.sum(per_log_sim < o) + 0.5 * np.sum(per_log_sim == o)) / len(per_log_sim)
        ps.append(float(min(1.0, 2 * min(f, 1 - f) + 1.0 / len(per_log_sim))))
    p_ho = min(ps) if ps else 0.0
    peak = float(np.mean([np.abs(surface(min(a_hat, MAX_RMS_HEIGHT), rs)).max() for rs in rng_seeds])) if a_hat > 0 else 0.0
    if a_hat < MIN_RMS_HEIGHT:
        declared, reason = False, (f"fitted RMS height {1000 * a_hat:.2f} mm is below the smallest reported "
                                   f"({1000 * MIN_RMS_HEIGHT:.1f} mm)")
    elif obs_ho < MIN_HELDOUT_EXCESS:
        declared, reason = False, (f"the held-out logs show no excess over flat ground ({obs_ho:.2f} floor² "
                                   f"< {MIN_HELDOUT_EXCESS:g})")
    elif cos < MIN_PROFILE_COSINE:
        declared, reason = False, (f"the residual does not sit where uneven ground puts it (profile agreement "
                                   f"{cos:.2f} < {MIN_PROFILE_COSINE:g})")
    else:
        declared, reason = True, (f"held-out excess {obs_ho:.1f} floor² over flat ground (which predicts 0); "
                                  f"simulated logs on such ground give {pcts[0]:.1f}-{pcts[2]:.1f} (5-95 %, median {pcts[1]:.1f}), "
                                  f"rank p = {p_ho:.2f}; profile agreement {cos:.2f}")
    return RoughnessFit(rms_height=a_hat, ci95=(float(lo), float(hi)), peak_height=peak, grid=[float(g) for g in grid],
                        excess=[float(c) for c in curve], excess_obs=obs_all, excess_heldout_obs=obs_ho,
                        excess_heldout_pred=float(pred_prof.sum()), heldout_p=p_ho, sim_log_excess=pcts,
                        profile_cosine=cos,
                        declared=declared, reason=reason, profile_obs=[float(v) for v in obs_prof],
                        profile_pred=[float(v) for v in pred_prof], n_rollouts=n_roll, n_fallen=n_fallen)
