"""The premise of ``benchmarks/bench_ground.py``: MuJoCo gives a sole on a heightfield a contact per
prism under it (up to ``mjMAXCONPAIR``), where on the plane it gets its corners, so the identified
world's random ground makes the constraint problem several times larger; the sparse Jacobian the
identified sim uses there solves the same problem."""

import pytest

from benchmarks.bench_ground import grounds, main, measure


def test_a_sole_on_a_heightfield_gets_many_more_contacts_than_on_the_plane(capsys):
    g = grounds(0.003, seed=0)
    plane, flat, rough, flat_sparse, _ = (measure(t, [0], 1.0, j) for t, j in g.values())
    assert plane["contacts"] <= 8.0  # at most the corners of two soles
    for hf in (flat, rough):
        assert hf["contacts"] > 3 * plane["contacts"] and hf["constraint_rows"] > 3 * plane["constraint_rows"]
    assert plane["falls"] == flat["falls"] == 0  # standing start on either ground
    # the sparse Jacobian solves the same contacts: the same walk, to the solver's tolerance
    assert flat_sparse["contacts"] == pytest.approx(flat["contacts"], rel=0.05)
    assert main(["--episodes", "1", "--repeats", "1", "--seconds", "0.5", "--json"]) == 0
    assert '"grounds"' in capsys.readouterr().out
