"""The robot's mass from the weight on its feet (sysid.weighing): found when the logs weigh more or
less than the model beyond their spread and the smallest share reported, the torso's scale from it,
a calibration's weighing as the reference, and nothing to weigh without foot forces."""

import numpy as np
import pytest

from robots import nao_h25
from sysid.candidates import Term
from sysid.data import Log
from sysid.weighing import MIN_SHARE, weigh

G = 9.81
MODEL_KG = 5.30535  # the NAO model's mass (the sum of its bodies' masses)
TORSO_KG = 1.04956


def _logs(mass_kg: float, n: int = 3, rows: int = 600, *, fixed: bool = False, fsr: bool = True, seed: int = 0,
          sigma_n: float = 0.5) -> list[Log]:
    """Floating-base logs whose total foot force is ``mass_kg`` g plus the force of a vertical
    oscillation of the centre of mass that starts and ends at rest (zero mean), its split between the
    feet shifting, and white noise of ``sigma_n`` N per foot; row 0 has no force (a simulator's first row)."""
    rng = np.random.default_rng(seed)
    nj = 24
    out = []
    for i in range(n):
        t = np.arange(rows) * 0.01
        T = t[-1] + 0.01
        a_z = 0.3 * (2 * np.pi / T) ** 2 * np.cos(2 * np.pi * t / T) * (1 + i)  # d²/dt² of a full-period bob
        total = mass_kg * (G + a_z)
        share = 0.5 + 0.4 * np.sin(2 * np.pi * 3 * t / T)
        f = np.stack([share * total, (1 - share) * total], axis=1) + rng.normal(0, sigma_n, (rows, 2))
        f[0] = 0.0
        out.append(Log(name=f"w{i}", t=t, cmd=np.zeros((rows, nj - 1)), q=np.zeros((rows, nj)), dq=None,
                       control_dt=0.01, physics_dt=0.001, fixed_base=fixed, fsr=f if fsr else None,
                       meta={"robot": "nao"}))
    return out


def test_a_heavier_torso_is_weighed_on_the_feet():
    robot = nao_h25()
    w = weigh(_logs(MODEL_KG + 0.16), robot)
    assert w.found and w.root == robot.root
    assert w.model_kg == pytest.approx(MODEL_KG, abs=1e-4) and w.root_nominal_kg == pytest.approx(TORSO_KG, abs=1e-4)
    assert abs(w.delta_kg - 0.16) < 0.01 and w.delta_ci95[0] < w.delta_kg < w.delta_ci95[1]
    assert w.delta_ci95[1] - w.delta_ci95[0] < 0.05
    assert w.root_scale == pytest.approx((TORSO_KG + 0.16) / TORSO_KG, abs=0.02)
    lo, hi = w.root_scale_ci95
    assert lo < w.root_scale < hi
    assert f"{w.mass_kg:.3f} kg" in w.sentence() and f"{1000 * w.delta_kg:+.0f} g" in w.sentence()
    d = w.to_dict()
    assert d["found"] and d["root_scale"] == w.root_scale and d["text"] == w.sentence()


def test_the_models_own_mass_is_not_a_finding_nor_a_difference_below_the_smallest_share():
    robot = nao_h25()
    same = [weigh(_logs(MODEL_KG, seed=s), robot) for s in range(60)]
    assert not any(w.found for w in same)
    covered = np.mean([w.delta_ci95[0] < 0 < w.delta_ci95[1] for w in same])
    assert covered >= 0.85, covered  # the 95 % interval of three logs covers the truth (binomial spread of 60 draws)
    # half the smallest share reported, measured sharply (little noise): outside its interval, still no finding
    small = weigh(_logs(MODEL_KG * (1 + MIN_SHARE / 2), sigma_n=0.05), robot)
    assert small.delta_ci95[0] > 0 and not small.found
    lighter = weigh(_logs(MODEL_KG - 0.2), robot)
    assert lighter.found and lighter.root_scale < 1


def test_a_calibrations_weighing_is_the_reference_and_the_base_models_torso_counts():
    robot = nao_h25()
    # force sensors reading 3 % high on both sets of logs: against the model a mass error, against the calibration none
    cal = weigh(_logs(MODEL_KG * 1.03, seed=1), robot)
    assert cal.found
    w = weigh(_logs(MODEL_KG * 1.03, seed=2), robot, reference_per_log_kg=cal.per_log_kg)
    assert not w.found and "calibration" in w.reference and w.reference_kg == pytest.approx(cal.mass_kg)
    # a base model that already makes the torso 20 % heavier: the model weighs that much more
    base = {Term("link_mass", robot.root): 1.2}
    wb = weigh(_logs(MODEL_KG + 0.2 * TORSO_KG), robot, base_model=base)
    assert wb.model_kg == pytest.approx(MODEL_KG + 0.2 * TORSO_KG, abs=1e-4) and not wb.found
    assert wb.root_scale == pytest.approx(1.2, abs=0.01)


def test_nothing_to_weigh_without_foot_forces_on_a_fixed_base_or_on_one_log():
    robot = nao_h25()
    assert weigh(_logs(MODEL_KG, fsr=False), robot) is None
    assert weigh(_logs(MODEL_KG, fixed=True), robot) is None
    assert weigh(_logs(MODEL_KG, n=1), robot) is None
