"""``benchmarks/decision_sides.py``: eval's timing loop as eval runs it (order, warm-up, a score
after every decision), figures per round and ratios paired within a round, and a side process
that answers every loop on real clips."""

from __future__ import annotations

import numpy as np
from benchmark_modules import load_benchmark

sides = load_benchmark("decision_sides")


def test_eval_loop_times_one_call_per_case_method_and_w_each_followed_by_its_score():
    calls = []

    def select(case, m, W):
        calls.append(("select", case, m, W))
        return f"keys {case} {m} {W}"

    def score(case, keys, m):
        calls.append(("score", keys))

    got = sides.eval_loop(["a", "b"], ["optimal", "dqn"], [5, 15], select, score)
    # eval's warm-up: one call of each method on the first case at the first W, untimed
    assert calls[:2] == [("select", "a", "optimal", 5), ("select", "a", "dqn", 5)]
    want = []
    for case in ("a", "b"):  # _evaluate_chunk's order: case, method, W
        for m in ("optimal", "dqn"):
            for W in (5, 15):
                want += [("select", case, m, W), ("score", f"keys {case} {m} {W}")]
    assert calls[2:] == want
    assert sorted(got) == ["dqn 15", "dqn 5", "optimal 15", "optimal 5"]
    assert all(len(v) == 2 and all(cpu >= 0 and wall >= 0 for cpu, wall in v) for v in got.values())


def test_hot_loop_calls_each_case_repeats_times_back_to_back_after_one_warm_up():
    calls = []
    got = sides.hot_loop(["a", "b"], ["dqn"], [5], lambda c, m, W: calls.append(c), 3)
    assert calls == ["a", "a", "a", "a", "b", "b", "b"]
    assert len(got["dqn 5"]) == 6


def test_ratios_are_paired_within_rounds_so_a_drift_of_the_machine_cancels():
    # the machine 1x, 1.5x and 0.8x as fast in three rounds; side A always 0.9 of side B
    speed = [1.0, 1.5, 0.8]
    rounds = [{"A": (0.9 * s, 0.9 * s), "B": (s, s)} for s in speed]
    med, lo, hi = sides.paired_ratio(rounds, "A", "B")
    np.testing.assert_allclose([med, lo, hi], 0.9)
    med, lo, hi = sides.summary(rounds, "B")
    np.testing.assert_allclose(med, 1.0)
    np.testing.assert_allclose(lo, 0.8)
    np.testing.assert_allclose(hi, 1.5)


def test_the_table_gives_each_loop_s_ratio_against_another_side_paired_within_rounds():
    # side A: eval's loop 0.8 of B's, the hot loop 0.6 of B's, in every round whatever its speed
    rounds = []
    for s in (1.0, 1.6, 0.7):
        r = {}
        for loop, a in (("eval", 0.8), ("hot", 0.6), ("evaluate", 1.0)):
            r[("A", loop, "dqn", 15)] = (a * s, a * s)
            r[("B", loop, "dqn", 15)] = (s, s)
        rounds.append(r)
    table = sides.sides_table(rounds, ["A", "B"], ["dqn"], [15])
    assert "/ B: 0.80x (hot loop 0.60x)" in table


def test_a_side_process_answers_every_loop_on_real_clips(cmu_dir):
    with sides.Side(None, cmu_dir, 2) as side:
        sides.warm([side])
        rounds = sides.run_rounds([side], ["optimal", "dqn"], [5], 1, repeats=1)
    assert len(rounds) == 1
    for loop in sides.LOOPS:
        for m in ("optimal", "dqn"):
            cpu, wall = rounds[0][("this tree", loop, m, 5)]
            assert wall > 0 and (loop == "evaluate" or cpu > 0)
    table = sides.sides_table(rounds, ["this tree"], ["optimal", "dqn"], [5])
    assert table.count("| 5 |") == 2 and "aim: at most 0.7 ms" in table
