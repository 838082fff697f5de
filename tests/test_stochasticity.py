"""The real world's per-step randomness (``--stochasticity``, envs.effects.Stochasticity)."""

import numpy as np
import pytest

from envs import RealWorld
from envs.effects import Stochasticity
from envs.rollout import rollout
from experiments.cli import main
from walk_engine import GaitParams, WalkEngine

SECONDS = 1.5


def _walks(level: float, streams=(0, 1, 2), seed: int = 11):
    """θ0's walks of ``SECONDS`` on one episode seed (terrain, effects, sensor noise) and several
    streams of per-step randomness; returns (recordings, the world)."""
    env = RealWorld(stochasticity=level)
    recs = []
    for k in streams:
        engine = WalkEngine(env.robot, GaitParams.initial(), None, dt=env.control_dt)
        recs.append(rollout(env, engine, seed=seed, seconds=SECONDS, options={"stochastic_seed": k}))
    return recs, env


def _force_spread(recs) -> float:
    """Mean over time and feet of the spread (std) across episodes of each foot's vertical force [N]."""
    n = min(len(r) for r in recs)
    fz = np.array([r.group("fsr")[:n] for r in recs])
    return float(fz.std(axis=0).mean())


def test_level_0_draws_nothing_and_is_one_world_whatever_the_stream():
    recs, env = _walks(0.0)
    assert env.touchdowns == []  # no contact redrawn
    for r in recs[1:]:
        for col in ("q", "fsr", "gt.com"):
            np.testing.assert_array_equal(r.group(col), recs[0].group(col))


def test_level_0_is_the_real_world_as_it_was():
    """RealWorld() (no stochasticity argument) and level 0 walk the same, bit for bit."""
    env = RealWorld()
    engine = WalkEngine(env.robot, GaitParams.initial(), None, dt=env.control_dt)
    plain = rollout(env, engine, seed=11, seconds=SECONDS)
    (zero,), _ = _walks(0.0, streams=(5,))
    np.testing.assert_array_equal(plain.group("q"), zero.group("q"))
    np.testing.assert_array_equal(plain.group("gt.com"), zero.group("gt.com"))


def test_a_higher_level_spreads_the_touchdown_forces_of_one_terrain_and_gait_more():
    """Same seed (terrain, effects, sensor noise) and gait, other per-step streams: the foot forces
    differ between episodes, the more the higher the level; every touchdown draws its own contact."""
    low, env1 = _walks(0.5, streams=range(4))
    high, env3 = _walks(3.0, streams=range(4))
    s1, s3 = _force_spread(low), _force_spread(high)
    assert 0 < s1 < 0.8 * s3
    assert env3.touchdowns and all(0.3 <= c["lateralFriction"] <= 2.0 and 10 ** (6 - 3 * Stochasticity.SOFTNESS) <= c["contactStiffness"] <= 1e6
                                   for _, _, c in env3.touchdowns)
    again, _ = _walks(3.0)  # a stream is reproducible
    np.testing.assert_array_equal(again[0].group("q"), high[0].group("q"))


def test_draws_scale_with_the_level():
    rng = np.random.default_rng(0)
    tau = np.full(5000, 3.0)
    for level in (1.0, 3.0):
        s = Stochasticity(level)
        assert np.std(s.torque_noise(rng, tau)) == pytest.approx(Stochasticity.TORQUE * level * 3.0, rel=0.05)
        ks = np.log10([s.touchdown(rng, 0.8, 5.3)["contactStiffness"] for _ in range(2000)])
        assert ks.min() >= 6 - Stochasticity.SOFTNESS * level and ks.max() <= 6
    assert not Stochasticity(0.0).active
    with pytest.raises(ValueError, match=">= 0"):
        Stochasticity(-1.0)
    with pytest.raises(ValueError, match=">= 0"):
        RealWorld(stochasticity=float("nan"))


def test_the_option_is_the_real_worlds_and_is_recorded(capsys):
    assert main(["walk", "--world", "real", "--seconds", "0.5", "--stochasticity", "2", "--json"]) == 0
    import json

    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["stochasticity"] == 2.0
    assert main(["walk", "--seconds", "0.5", "--stochasticity", "2"]) == 2  # the sim has none
    assert "real world only" in capsys.readouterr().err
    assert main(["walk", "--world", "real", "--stochasticity", "-1"]) == 2
    assert main(["stress", "--world", "sim", "--stochasticity", "1", "--trials", "1"]) == 2
