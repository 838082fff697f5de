"""``benchmarks/bench_overhead.py`` times the batch's ground lookup and the grounding fit's ensemble,
each apart and together; it exits 1 unless both ways give the same numbers bit for bit."""

import json

from benchmarks.bench_overhead import main


def test_both_ways_agree_bit_for_bit_and_the_report_has_its_ratios(capsys):
    rc = main(["--episodes", "3", "--steps", "40", "--repeats", "1", "--seconds", "1.0", "--json"])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert rc == 0
    assert out["lookup"]["bit_identical"] and out["ensemble_fit"]["bit_identical"]
    assert out["ensemble_fit"]["members"] == 5
    assert out["lookup"]["ratio"] > 0 and out["ensemble_fit"]["ratio"] > 0
