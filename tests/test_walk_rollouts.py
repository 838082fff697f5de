"""The robot walks with θ0 in both worlds; commands, parameter effects, falls, determinism."""

import functools
import math

import numpy as np
import pytest

from common.spatial import quat_yaw
from experiments.runtime.fitness import FALL_PENALTY, run_walk, walk_fitness
from walk_engine import GaitParams, WalkCommand


def _yaw(quat_wxyz):
    return np.unwrap(quat_yaw(quat_wxyz))


def test_theta0_walks_20s_in_sim():
    rec, res = run_walk(seconds=20.0)
    assert not res.fell, res
    assert res.speed_cm_s >= 8.0, res
    assert res.drift_m < 0.1 * res.distance_m, res
    assert rec.meta["params"] == GaitParams().to_dict()


def test_sim_rollouts_are_bit_identical():
    a, ra = run_walk(seconds=3.0)
    b, rb = run_walk(seconds=3.0)
    assert ra == rb
    assert a.columns.keys() == b.columns.keys()
    for k in a.columns:
        assert np.array_equal(a.columns[k], b.columns[k], equal_nan=True), k


@pytest.mark.parametrize("wz", [0.35, -0.35])
def test_turning_in_place_in_sim(wz):
    rec, res = run_walk(seconds=10.0, command=WalkCommand(0.0, 0.0, wz))
    assert not res.fell
    rate = math.degrees(_yaw(rec.group("gt.quat"))[-1] - _yaw(rec.group("gt.quat"))[0]) / 10.0
    assert np.sign(rate) == np.sign(wz) and abs(rate) >= 15.0, rate


@pytest.mark.parametrize("vy", [0.08, -0.08])
def test_sideways_walking_in_sim(vy):
    rec, res = run_walk(seconds=10.0, command=WalkCommand(0.0, vy, 0.0))
    assert not res.fell
    dy = rec.group("gt.base")[-1, 1] - rec.group("gt.base")[0, 1]
    assert np.sign(dy) == np.sign(vy) and abs(dy) / 10.0 >= 0.03, dy
    assert abs(res.distance_m) < 0.5 * abs(dy)


def test_walking_while_turning_in_sim():
    rec, res = run_walk(seconds=10.0, command=WalkCommand(None, 0.0, 0.3))
    assert not res.fell
    assert math.degrees(_yaw(rec.group("gt.quat"))[-1] - _yaw(rec.group("gt.quat"))[0]) / 10.0 >= 15.0


@functools.lru_cache(maxsize=None)
def _speed_of(params: GaitParams) -> float:
    res = run_walk(params, seconds=5.0)[1]
    assert not res.fell, (params, res)
    return res.speed_cm_s


def _speed(**kw):
    return _speed_of(GaitParams(**kw))


def test_parameters_move_speed_in_the_expected_direction():
    """Longer steps -> faster; longer step period -> slower (speed ≈ step_length / period);
    deeper crouch (lower CoM) -> slower (the knee at 1.7 rad needs more torque than the servo
    gives, so the support leg sags and the steps shorten). 6 cm steps tip over in the sim's hard-floor
    contacts as in the flat real world without effects, so the longest step here is 5.5 cm."""
    assert _speed(step_length=0.02) < _speed(step_length=0.04) < _speed(step_length=0.055)
    assert _speed(step_period=0.30) > _speed(step_period=0.36) > _speed(step_period=0.45)
    assert _speed(com_height=0.23) < _speed(com_height=0.27)


def test_falling_parameters_give_finite_penalised_fitness():
    rec, res = run_walk(GaitParams(com_x_offset=-0.02, zmp_offset_x=-0.02))
    assert res.fell and res.fall_reason in ("tilt", "torso_low") and 0 < res.fall_time_s < 7.5
    assert math.isfinite(res.fitness) and res.fitness == pytest.approx(res.speed_cm_s - FALL_PENALTY)
    # the fitness is computed from the recording alone
    assert walk_fitness(rec, 7.5) == res


def test_fitness_uses_nominal_duration():
    rec, res = run_walk(seconds=2.0)
    base = rec.group("gt.base")
    assert res.speed_cm_s == pytest.approx(100 * (base[-1, 0] - base[0, 0]) / 2.0)
    assert walk_fitness(rec, 4.0).speed_cm_s == pytest.approx(res.speed_cm_s / 2)


def test_theta0_walks_on_flat_real_world_without_effects_as_fast_as_in_the_sim():
    """Without the real world's effects and bumps the two engines agree on the walk: θ0's speed in
    PyBullet is within 1 cm/s of MuJoCo's (measured 14.30 vs 14.45 cm/s)."""
    rec, res = run_walk(world="real", profile="none", terrain="flat", seconds=7.5)
    assert not res.fell and res.speed_cm_s >= 8.0 and res.drift_m < 0.1 * res.distance_m, res
    _, sim = run_walk(world="sim", seconds=7.5)
    assert abs(res.speed_cm_s - sim.speed_cm_s) < 1.0, (res.speed_cm_s, sim.speed_cm_s)


@pytest.mark.slow
def test_theta0_walks_20s_on_flat_real_world_without_effects():
    rec, res = run_walk(world="real", profile="none", terrain="flat", seconds=20.0)
    assert not res.fell and res.speed_cm_s >= 8.0 and res.drift_m < 0.1 * res.distance_m, res


@pytest.mark.slow
def test_real_profile_is_hard_but_not_hopeless_for_theta0():
    """θ0 falls in 30-90 % of 7.5 s trials on fresh terrain seeds of the "real" profile,
    while a higher swing (step_height 0.03 m) mostly survives. Thirty seeds (100-129, never used
    for tuning; measured 14/30 falls, and 16/30 on a machine without AVX-512, whose PyBullet rounds
    differently in the last bits) rather than ten: at a fall rate near 0.5 a single block of ten
    lands outside [3, 9] falls about 8 % of the time (measured blocks: 2, 4, 8 falls). The 40
    trials run on a pool of 2 (``run_episode``: the same walks as ``run_walk(world="real", seed=s)``)."""
    from experiments.runtime.executors import make_executor
    from experiments.runtime.tasks import EpisodeTask, run_episode

    theta0, higher = tuple(GaitParams().to_array().tolist()), tuple(GaitParams(step_height=0.03).to_array().tolist())
    tasks = ([EpisodeTask(world="real", theta=theta0, seed=s) for s in range(100, 130)]
             + [EpisodeTask(world="real", theta=higher, seed=s) for s in range(120, 130)])
    with make_executor(2) as ex:
        fell = [r.fell for r in ex.map(run_episode, tasks)]
    falls = sum(fell[:30])
    assert 9 <= falls <= 27, falls
    assert sum(fell[30:]) <= 3, sum(fell[30:])
