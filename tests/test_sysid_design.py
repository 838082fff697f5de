"""D-optimal excitation design (``sysid.design``): the multiplicative algorithm finds the known
optimum of constructed information matrices, and on the NAO's sim the saturation segment is worth
more than holds for the torque limit."""

import numpy as np
import pytest

from robots import nao_h25
from sysid.design import Z95, d_optimal, design, format_design
from sysid.excitation import protocol


def test_multiplicative_algorithm_finds_the_known_d_optimum():
    # two segments that each inform one of two parameters, and a dominated third one
    info = {"a": np.diag([1.0, 0.0]), "b": np.diag([0.0, 4.0]), "c": 0.25 * np.diag([1.0, 4.0])}
    w, _ = d_optimal(info)
    assert w["a"] == pytest.approx(0.5, abs=1e-3) and w["b"] == pytest.approx(0.5, abs=1e-3)
    assert w["c"] < 1e-3
    w, _ = d_optimal(info, min_share=0.1)  # every segment keeps its floor, the rest as before
    assert w["c"] == pytest.approx(0.1, abs=1e-3)
    assert w["a"] == pytest.approx(0.45, abs=1e-3) and w["b"] == pytest.approx(0.45, abs=1e-3)
    with pytest.raises(ValueError):
        d_optimal(info, min_share=0.5)
    with pytest.raises(ValueError):
        d_optimal({})


def test_saturation_segment_informs_the_torque_limit_more_than_holds():
    d = design(nao_h25(), ("holds", "saturation"), families=("torque_limit", "pd_gain"),
               joints=["LKneePitch", "RElbowRoll"], seconds=8.0, segment_seconds=2.5)
    assert set(d.shares) == {"holds", "saturation"} and sum(d.shares.values()) == pytest.approx(1.0)
    assert d.shares["saturation"] > d.shares["holds"]
    i = d.terms.index("torque_limit")
    assert d.se_optimal[i] < d.se_default[i]  # the design sharpens the torque limit
    assert Z95 * d.se_optimal[i] < 1.0  # and makes it identifiable at its smallest reported effect
    assert d.logdet_optimal >= d.logdet_default
    text = format_design(d.to_json())
    assert "torque_limit" in text and "saturation" in text


def test_protocol_follows_the_shares():
    r = nao_h25()
    a = protocol(r, 6.0, seed=1, segments=("holds", "saturation"))
    b = protocol(r, 6.0, seed=1, segments=("holds", "saturation"), shares={"holds": 0.1, "saturation": 0.9})
    assert a.shape == b.shape
    # the saturation steps (the largest departures from the pose) start earlier with the larger share
    q0 = r.pose("crouch", actuated=True)
    first = [int(np.argmax(np.abs(x - q0).max(axis=1) > 0.4)) for x in (a, b)]
    assert first[1] < first[0]
    with pytest.raises(ValueError, match="shares"):
        protocol(r, 6.0, segments=("holds", "saturation"), shares={"holds": -1.0})


def test_a_parallel_spring_is_identifiable_next_to_a_kp_error_and_an_offset():
    """The design's information covers the parallel-spring family (per-joint probe and smallest
    effect, shares of the joint's kp): with steps and holds, a spring at the knee and at the elbow
    is identifiable at its smallest reported effect alongside a kp error and an encoder offset of
    the same joints."""
    d = design(nao_h25(), ("holds", "steps"), families=("pd_gain", "parallel_spring", "sensor_bias"),
               joints=["LKneePitch", "RElbowRoll"], seconds=8.0, segment_seconds=2.5)
    for j in ("LKneePitch", "RElbowRoll"):
        i = d.terms.index(f"parallel_spring[{j}]")
        assert Z95 * d.se_default[i] < 1.0 and Z95 * d.se_optimal[i] < 1.0
    assert "parallel_spring" in format_design(d.to_json())
