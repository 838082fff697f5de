"""``benchmarks/bench_diagnose_rounds.py`` reads how much of a diagnosis is physics from a profile:
the time inside MuJoCo's threaded ``rollout``. If MuJoCo renamed that built-in, the share would read
0 % without an error; this fails instead."""

import cProfile
import time

import mujoco
import numpy as np
from mujoco import rollout

from benchmarks.bench_diagnose_rounds import rollout_seconds

XML = """<mujoco><worldbody><body><freejoint/><geom size="0.1"/></body></worldbody></mujoco>"""


def test_rollout_seconds_counts_the_time_inside_mujocos_rollout():
    m = mujoco.MjModel.from_xml_string(XML)
    d = mujoco.MjData(m)
    x0 = np.zeros(mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    mujoco.mj_getState(m, d, x0, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    rollout.rollout(m, d, x0[None], nstep=20000)
    sum(i * i for i in range(200000))  # Python time outside the rollout
    prof.disable()
    wall = time.perf_counter() - t0
    inside = rollout_seconds(prof)
    assert 0.0 < inside < wall
    empty = cProfile.Profile()
    empty.enable()
    sum(range(1000))
    empty.disable()
    assert rollout_seconds(empty) == 0.0
