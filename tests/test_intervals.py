"""Instance-bootstrap intervals against exact cases and properties."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from wpbench.evaluation.intervals import instance_bootstrap_interval, instance_count
from wpbench.evaluation.summary import wilson_interval


def test_all_successes_and_all_failures_are_exact():
    ids = ["a", "a", "b", "c"]
    assert instance_bootstrap_interval([True] * 4, ids) == (1.0, 1.0)
    assert instance_bootstrap_interval([False] * 4, ids) == (0.0, 0.0)


def test_no_episodes_is_nan():
    low, high = instance_bootstrap_interval([], [])
    assert math.isnan(low) and math.isnan(high)


def test_instances_that_always_fail_together_widen_the_interval():
    """10 instances x 10 episodes, each instance all-or-nothing: 100 episodes but only 10 independent outcomes."""
    ids = [f"i{k}" for k in range(10) for _ in range(10)]
    outcome = [k < 7 for k in range(10) for _ in range(10)]
    low, high = instance_bootstrap_interval(outcome, ids)
    w_low, w_high = wilson_interval(70, 100)
    assert low < 0.7 < high
    assert (high - low) > 1.5 * (w_high - w_low)


def test_one_episode_per_instance_is_close_to_the_binomial_interval():
    rng = np.random.default_rng(1)
    outcome = rng.random(400) < 0.8
    low, high = instance_bootstrap_interval(outcome, [str(i) for i in range(400)])
    w_low, w_high = wilson_interval(int(outcome.sum()), 400)
    assert abs(low - w_low) < 0.02 and abs(high - w_high) < 0.02


@given(st.lists(st.tuples(st.booleans(), st.integers(0, 5)), min_size=1, max_size=40), st.integers(0, 3))
def test_interval_is_ordered_contains_nothing_impossible_and_is_deterministic(episodes, seed):
    outcome = [o for o, _ in episodes]
    ids = [str(i) for _, i in episodes]
    low, high = instance_bootstrap_interval(outcome, ids, resamples=200, seed=seed)
    assert 0.0 <= low <= high <= 1.0
    assert (low, high) == instance_bootstrap_interval(outcome, ids, resamples=200, seed=seed)


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="one length"):
        instance_bootstrap_interval([True, False], ["a"])
    with pytest.raises(ValueError, match="confidence"):
        instance_bootstrap_interval([True], ["a"], confidence=1.5)


def test_instance_count():
    assert instance_count(["a", "b", "a"]) == 2
