"""``sgat.algorithm.grounding_loop`` (Algorithm 1 once for every domain): stage order, data handed
between stages, resume after a crash without redoing finished stages, early stop, bad state."""

import copy

import pytest

from sgat.algorithm import grounding_loop, new_progress


def _loop(prog, calls, crash_at=None, saved=None):
    def ground(i, pol):
        calls.append(("ground", i, pol))
        return f"g{i}"

    def improve(i, pol, model, prog):
        calls.append(("improve", i, pol, model))
        if crash_at == ("improve", i):
            raise KeyboardInterrupt  # the process dies here
        return pol + 1

    def evaluate(i, cand, prog):
        calls.append(("evaluate", i, cand))

    return dict(ground=ground, improve=improve, evaluate=evaluate, save=lambda: saved.append(copy.deepcopy(prog)))


def test_stages_run_in_order_and_hand_over_policy_and_model():
    calls, saved = [], []
    prog = new_progress(0)
    out = grounding_loop(prog, 3, **_loop(prog, calls, saved=saved))
    assert out["policy"] == 3 and out["step"] == 4
    assert calls == [("ground", 1, 0), ("improve", 1, 0, "g1"), ("evaluate", 1, 1),
                     ("ground", 2, 1), ("improve", 2, 1, "g2"), ("evaluate", 2, 2),
                     ("ground", 3, 2), ("improve", 3, 2, "g3"), ("evaluate", 3, 3)]
    assert len(saved) == 9  # a checkpoint after every stage


def test_a_crash_resumes_from_the_last_checkpoint_without_redoing_stages():
    calls, saved = [], []
    prog = new_progress(0)
    with pytest.raises(KeyboardInterrupt):
        grounding_loop(prog, 2, **_loop(prog, calls, crash_at=("improve", 2), saved=saved))
    prog = copy.deepcopy(saved[-1])  # what the checkpoint holds: step 2 grounded, not improved
    assert prog["step"] == 2 and prog["stage"] == "improve" and prog["model"] == "g2"
    calls2 = []
    out = grounding_loop(prog, 2, **_loop(prog, calls2, saved=[]))
    assert out["policy"] == 2
    assert calls2 == [("improve", 2, 1, "g2"), ("evaluate", 2, 2)]  # step 2 was not grounded again


def test_stop_ends_early_and_bad_state_is_refused():
    out = grounding_loop(new_progress(0), 10, ground=lambda i, p: None, improve=lambda i, p, m, pr: p + 1,
                         stop=lambda i, pr: i == 2)
    assert out["step"] == 3 and out["policy"] == 2
    with pytest.raises(ValueError, match="unknown stage"):
        grounding_loop({**new_progress(0), "stage": "cma"}, 1, ground=lambda i, p: None,
                       improve=lambda i, p, m, pr: p)
    with pytest.raises(ValueError, match="steps"):
        grounding_loop(new_progress(0), -1, ground=lambda i, p: None, improve=lambda i, p, m, pr: p)
