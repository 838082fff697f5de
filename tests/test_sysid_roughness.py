"""Terrain roughness as a fitted distribution (sysid.roughness): the surface model, the heightfield
plumbing, the simulated logs, and injection-and-recovery on stepping logs over uneven ground."""

import copy

import mujoco
import numpy as np
import pytest

from robots import nao_h25
from sysid.model import TERRAIN_CELL, Structure, replay_model, set_terrain
from sysid.candidates import Term
from sysid.roughness import (CORRELATION_RADIUS, MIN_RMS_HEIGHT, _excess_per_window, excess_left, fit_roughness,
                             simulate_on_surfaces, surface)
from terrain import Heightfield
from _sensors import add_sensor_noise

FLOOR = np.array([1e-3] * 24 + [2e-3] * 2 + [1e-2] * 3)  # encoders, torso roll/pitch, gyro


def _stepping_logs(amplitude: float, seeds, seconds: float = 4.0, friction: float | None = None):
    """Stepping-in-place logs in the MuJoCo sim world on a fresh sparse-bump field per log
    (``terrain.lumpy``, the blind referee's generator, not the tool's dense random field), with
    encoder and IMU noise."""
    from envs import CommandLog, NaoSimEnv, rollout
    from sysid.data import from_recording
    from sysid.excitation import protocol
    from sysid.worlds import rough_ground

    r = nao_h25()
    ground = rough_ground(amplitude, seed=3)
    logs = []
    env = NaoSimEnv(fixed_base=False, **({} if friction is None else {"friction": friction}))
    for i, s in enumerate(seeds):
        rec = rollout(env, CommandLog(protocol(r, seconds, seed=s, fixed_base=False)), seed=0, seconds=seconds,
                      options={"terrain": ground(i)})
        add_sensor_noise(rec, s)
        logs.append(from_recording(rec, f"rough_{s}"))
    return logs


def _problem(logs):
    from sysid.identify import Problem
    from sysid.replay import windows

    return Problem(logs, windows(logs, range(len(logs) - 1), 0.5), windows(logs, [len(logs) - 1], 0.5), FLOOR,
                   with_imu=True)


def test_surface_has_the_requested_rms_height_and_correlation_radius():
    h = surface(0.003, seed=4)
    assert h.shape == (51, 51)
    assert abs(h.std() - 0.003) < 1e-12 and abs(h.mean()) < 1e-12
    # Gaussian-kernel filtered white noise: autocorrelation exp(-d^2 / (4 r^2)), 0.78 at d = r
    lag = int(round(CORRELATION_RADIUS / TERRAIN_CELL))
    acs = []
    for s in range(20):
        x = surface(0.003, seed=s)
        x = x - x.mean()
        acs.append(float((x[:, :-lag] * x[:, lag:]).mean() / x.var()))
    assert 0.65 < np.mean(acs) < 0.88
    assert np.all(surface(0.0, seed=1) == 0)
    with pytest.raises(ValueError):
        surface(0.2, seed=0)


def test_set_terrain_writes_the_heights_mujoco_collides_with():
    rm = replay_model(Structure(fixed_base=False, terrain=True))
    m = copy.copy(rm.model)
    h = surface(0.005, seed=7)
    set_terrain(m, h)
    d = mujoco.MjData(m)
    d.qpos[2] = 5.0  # robot far above
    mujoco.mj_forward(m, d)
    hf = Heightfield(h, TERRAIN_CELL)
    gid = np.zeros(1, np.int32)
    for x, y in np.random.default_rng(0).uniform(-0.9, 0.9, (15, 2)):
        dist = mujoco.mj_ray(m, d, np.array([x, y, 1.0]), np.array([0.0, 0.0, -1.0]), None, 1, -1, gid)
        assert abs((1.0 - dist) - float(hf.height_at(x, y))) < 1e-6
    with pytest.raises(ValueError):
        set_terrain(m, np.zeros((3, 3)))


def test_simulated_log_replays_exactly_on_its_own_ground():
    """A log simulated on a surface, replayed in windows from its own states on the same surface,
    is reproduced (up to the contact solver's warm start, which the state does not carry: exact on a
    plane, a small part of the surface's signature on a heightfield): states, times and IMU
    conventions of the simulated logs are those of real logs."""
    from sysid.replay import build_models, measured, predict, windows

    logs = _stepping_logs(0.0, [5], seconds=3.0)
    h = surface(0.002, seed=2)
    sim = simulate_on_surfaces(logs, {}, [h])[0]
    assert sim[0].q.shape == logs[0].q.shape and np.all(np.isfinite(sim[0].q))
    models = build_models([{}], Structure(fixed_base=False, physics_dt=logs[0].physics_dt, terrain=True))
    set_terrain(models[0][1], h)
    wins = windows(sim, [0], 0.5)
    pred = predict(sim, wins, [{}], with_imu=True, models=models)
    same = _excess_per_window([measured(sim[0], w, True) for w in wins], [p[0] for p in pred], FLOOR)
    assert same[0].sum() < 1e-9  # the first window starts where the simulation started: exact
    # on flat ground the same log is not reproduced: the surface matters
    flat = build_models([{}], Structure(fixed_base=False, physics_dt=logs[0].physics_dt, terrain=True))
    pred = predict(sim, wins, [{}], with_imu=True, models=flat)
    ex = _excess_per_window([measured(sim[0], w, True) for w in wins], [p[0] for p in pred], FLOOR)
    assert ex.sum(axis=1).mean() > 100 * same.sum(axis=1).mean()


@pytest.mark.slow  # about a minute on a loaded 2-core machine
def test_terrain_roughness_injection_and_recovery():
    """Stepping on sparse bumps of 12 mm peak (the referee's generator; RMS height ~3 mm) is named as
    uneven ground with an RMS height of the right size; the same protocol on flat ground is not."""
    from sysid.worlds import rough_ground

    truth = np.mean([rough_ground(0.012, seed=3)(i).heights.std() for i in range(3)])
    grid = (0.0, 0.001, 0.002, 0.0032, 0.0055)
    problem = _problem(_stepping_logs(0.012, [30, 31, 32]))
    rough = fit_roughness(problem, {}, n_surfaces=2, grid=grid, n_boot=50)
    assert rough.declared, rough.reason
    # measured: 4.4 mm for 3.2 mm (+36 %; two surfaces per grid point, for speed; the blind benchmark's
    # median error is 15-19 %): within 50 %, and the bootstrap interval holds the truth
    assert abs(rough.rms_height / truth - 1.0) < 0.5, (rough.rms_height, truth)
    assert rough.ci95[0] <= truth <= rough.ci95[1], (rough.ci95, truth)
    # a wrong contact term fitted next to it leaves most of the surface's excess (not repeatable)
    left, _ = excess_left(rough, problem, {Term("ground_compliance"): 0.03})
    assert left > 0.5 * rough.rms_height
    assert rough.ci95[0] <= rough.rms_height <= rough.ci95[1]
    assert rough.peak_height > 2.5 * rough.rms_height  # a Gaussian field's extreme over the patch
    flat = fit_roughness(_problem(_stepping_logs(0.0, [30, 31, 32])), {}, n_surfaces=2, grid=grid, n_boot=50)
    assert not flat.declared
    assert flat.rms_height < MIN_RMS_HEIGHT


@pytest.mark.slow  # about a minute on a loaded 2-core machine
def test_the_adaptive_grid_gives_the_whole_grids_fit_from_fewer_heights():
    """Simulating the RMS-height grid bottom-up only as far as the fit needs it gives the very fit
    the whole grid gives (the height, its bootstrap interval, the decision and its evidence), and
    leaves out the heights above the bracket; a grid point above the truth is never simulated."""
    problem = _problem(_stepping_logs(0.008, [30, 31, 32], seconds=3.0))
    grid = (0.0, 0.001, 0.002, 0.004, 0.006, 0.012)  # measured: 3.0 mm [1.3, 4.5]
    full = fit_roughness(problem, {}, n_surfaces=2, grid=grid, n_boot=50, adaptive=False)
    lazy = fit_roughness(problem, {}, n_surfaces=2, grid=grid, n_boot=50)
    assert full.grid == list(grid) and lazy.grid == full.grid[:len(lazy.grid)]
    assert len(lazy.grid) < len(grid), (lazy.grid, full.rms_height, full.ci95)
    assert lazy.excess == full.excess[:len(lazy.grid)]
    for f in ("rms_height", "ci95", "declared", "reason", "peak_height", "excess_obs", "excess_heldout_pred",
              "heldout_p", "sim_log_excess", "profile_cosine", "profile_pred"):
        assert getattr(lazy, f) == getattr(full, f), f
    assert lazy.ci95[1] < lazy.grid[-1] and lazy.rms_height > 0
    assert lazy.n_rollouts < full.n_rollouts
    # what a deterministic term leaves is read off the simulated part of the curve alike
    left_lazy, ho_lazy = excess_left(lazy, problem, {Term("ground_compliance"): 0.03})
    left_full, ho_full = excess_left(full, problem, {Term("ground_compliance"): 0.03})
    assert ho_lazy == ho_full and (left_lazy == left_full or left_full >= left_lazy >= lazy.grid[-1] >= MIN_RMS_HEIGHT)
    with pytest.raises(ValueError, match="increase"):
        fit_roughness(problem, {}, grid=(0.0, 0.002, 0.001))


@pytest.mark.slow  # about a minute on a loaded 2-core machine
def test_a_deterministic_contact_effect_is_not_left_to_uneven_ground():
    """Low foot friction (0.2) on flat ground leaves an excess over the nominal replay that a
    roughness fit alone would name as uneven ground; with the friction term in the model, what is
    left corresponds to less than the smallest reported RMS height (the diagnosis then rejects it)."""
    problem = _problem(_stepping_logs(0.0, [30, 31, 32], friction=0.2))
    grid = (0.0, 0.0005, 0.001, 0.002, 0.0035)
    rough = fit_roughness(problem, {}, n_surfaces=2, grid=grid, n_boot=20)
    assert rough.declared, rough.reason  # the friction's excess, read as ground
    left, _ = excess_left(rough, problem, {Term("foot_friction"): 0.2})
    assert left < MIN_RMS_HEIGHT and left < 0.5 * rough.rms_height


def test_a_diagnosis_out_of_time_before_the_ground_says_so():
    """A time budget spent before the uneven-ground stage leaves the ground untested: the report
    says so in its verdict and warnings (it read "none passes the tests" before)."""
    from sysid.diagnose import diagnose

    rep = diagnose(_stepping_logs(0.012, [30, 31], seconds=3.0), time_budget_s=0.0, max_rounds=1)
    assert rep["time_budget_reached"] and rep["terrain_roughness"] is None
    assert any("uneven-ground stage" in w for w in rep["warnings"]) and "terrain roughness was not tested" in rep["verdict"]
