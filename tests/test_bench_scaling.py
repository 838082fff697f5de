"""``benchmarks/bench_scaling.py``: the serial fraction (Karp-Flatt) and the projection to many cores."""

import math

import pytest

from benchmarks.bench_scaling import karp_flatt, project


def test_karp_flatt_is_0_for_a_perfect_speedup_and_1_for_none():
    assert karp_flatt(2.0, 2) == pytest.approx(0.0)
    assert karp_flatt(1.0, 2) == pytest.approx(1.0)
    # Amdahl's speed-up of a 10 % serial program on 4 cores gives back its 10 %
    s = 1 / (0.1 + 0.9 / 4)
    assert karp_flatt(s, 4) == pytest.approx(0.1)


def test_projection_runs_the_jobs_side_by_side_each_by_amdahl():
    # 2 h on 2 workers at speed-up 1.6: 3.2 h on one core, 20 jobs of 0.16 h, e = 0.25
    pr = project(2.0, 1.6, 2, 20, cores=(10, 40, 80))
    e = karp_flatt(1.6, 2)
    assert pr["serial_fraction"] == pytest.approx(e) and pr["t1_hours"] == pytest.approx(3.2)
    t = 3.2 / 20
    assert pr["10"] == pytest.approx(2 * t)  # fewer cores than jobs: two waves of one core each
    assert pr["40"] == pytest.approx(t * (e + (1 - e) / 2))  # two cores per job
    assert pr["80"] < pr["40"] < pr["10"]
    assert pr["80"] > e * t  # never below a job's serial part


def test_gym_cells_are_serial_so_only_waves_count():
    pr = project(5.5, 2.0, 2, 250, 1.0, cores=(16, 256))
    assert pr["16"] == pytest.approx(math.ceil(250 / 16) * 11 / 250)
    assert pr["256"] == pytest.approx(11 / 250)
