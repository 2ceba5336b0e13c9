"""The repairs' round loop (engine/meshing/improve.py ``_in_rounds``), shared by the peels, collapses and swaps."""

from engine.meshing.improve import PEEL_ROUNDS, _in_rounds


def test_rounds_stop_at_the_first_that_changes_nothing():
    calls = []

    def step(left, done):
        calls.append(left)
        count = min(left, 2)
        return left - count, done + [count], count

    assert _in_rounds(step, (5, [])) == (0, [2, 2, 1, 0], 5)
    assert calls == [5, 3, 1, 0]


def test_rounds_stop_after_the_last():
    assert _in_rounds(lambda n: (n + 1, 1), (0,)) == (PEEL_ROUNDS, PEEL_ROUNDS)
    assert _in_rounds(lambda n: (n + 1, 3), (0,), rounds=2) == (2, 6)
