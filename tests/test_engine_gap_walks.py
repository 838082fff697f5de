"""benchmarks/engine_gap_walks.py: the MuJoCo worlds it builds and its agreement figures."""

import functools
import json

import numpy as np
import pytest

from benchmarks.engine_gap_walks import VARIANTS, agreement, mujoco_report


def test_agreement_of_a_world_with_itself_and_with_a_shuffled_one():
    rng = np.random.default_rng(0)
    pb = rng.normal(0, 5, (16, 8)) + np.linspace(-10, 10, 16)[:, None]
    fell = pb < -5
    same = agreement(pb, pb, fell, fell)
    assert same["rho"] == pytest.approx(1.0) and same["mae"] == 0 and same["bias"] == 0 and same["falls_differ"] == 0
    assert same["ci"] == pytest.approx([1.0, 1.0])
    shifted = agreement(pb - 3.0, pb, fell, fell)
    assert shifted["rho"] == pytest.approx(1.0) and shifted["bias"] == pytest.approx(-3.0) and shifted["mae"] == pytest.approx(3.0)
    shuffled = agreement(pb[rng.permutation(16)], pb, fell[::-1], fell)
    assert abs(shuffled["rho"]) < 0.6 and shuffled["ci"][0] < shuffled["rho"] < shuffled["ci"][1]
    assert shuffled["falls_differ"] > 0


def test_the_mujoco_variants_carry_the_contact_and_the_play_hinges_they_name(tmp_path):
    """``stiff ground`` sets every contact's time constant to 4 ms, ``no play hinges`` builds no
    backlash hinge, and every variant walks the very lumpy field PyBullet walks for the seed."""
    from envs.bullet_world import NaoRealEnv, real_ground
    from experiments.runtime.tasks import _world

    seen = {}
    for name, (tc, backlash) in VARIANTS.items():
        rep = mujoco_report("real", tc, backlash)
        assert any(k.startswith("backlash[") for k in rep["model"]) == backlash and rep["effects"] == []
        path = tmp_path / name.replace(" ", "_").replace(",", "") / "report.json"
        path.parent.mkdir()
        path.write_text(json.dumps(rep))
        env = _world({"world": "identified", "identified": [str(path)], "ground": ["real", 0.01], "seed": 4}).unwrapped
        env.reset(seed=4)
        m = env.model
        hinges = [m.joint(j).name for j in range(m.njnt) if m.joint(j).name.endswith("__play")]
        assert bool(hinges) == backlash
        assert np.allclose(m.geom_solref[:, 0], 0.004 if tc else 0.01)
        seen[name] = env.terrain.heights
    real = NaoRealEnv(profile="real", ground=functools.partial(real_ground, amplitude=0.01))
    real.reset(seed=4)
    assert all(np.array_equal(h, real.terrain.heights) for h in seen.values())
