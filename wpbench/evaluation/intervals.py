"""Confidence intervals of a success rate.

Episodes of one run repeat furniture instances (a val split has a handful per
category), so they are not independent draws: a policy that fails on one deep chest
fails on most of its episodes. The Wilson interval treats every episode as
independent; :func:`instance_bootstrap_interval` treats the instance as the unit and
resamples whole instances, which is the honest interval when the question is "how
well does the policy do on furniture like this", not "on these very pieces".
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

CONFIDENCE = 0.95
BOOTSTRAP_RESAMPLES = 4000


def instance_bootstrap_interval(
    successes: Sequence[bool],
    instances: Sequence[str],
    confidence: float = CONFIDENCE,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile interval of the success rate when instances, not episodes, are resampled.

    successes: (E,) one outcome per episode; instances: (E,) the furniture instance of
    each episode. Each resample draws as many instances as there are, with replacement,
    and takes every episode of each drawn instance; its rate is successes / episodes of
    the drawn set. Returns (low, high) in [0, 1]; (nan, nan) for no episodes.
    Deterministic for a given ``seed``.
    """
    outcome = np.asarray(successes, dtype=np.float64)
    groups = np.asarray(instances)
    if outcome.ndim != 1 or groups.shape != outcome.shape:
        raise ValueError(f"successes and instances must be (E,) arrays of one length, "
                         f"got {outcome.shape} and {groups.shape}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    if resamples < 1:
        raise ValueError(f"resamples must be >= 1, got {resamples}")
    if len(outcome) == 0:
        return (math.nan, math.nan)
    _, index = np.unique(groups, return_inverse=True)
    wins = np.bincount(index, weights=outcome)             # (I,) successes per instance
    counts = np.bincount(index).astype(np.float64)         # (I,) episodes per instance
    rng = np.random.default_rng(seed)
    drawn = rng.integers(0, len(wins), size=(resamples, len(wins)))
    rates = wins[drawn].sum(axis=1) / counts[drawn].sum(axis=1)
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(rates, [tail, 1.0 - tail])
    return (float(low), float(high))


def instance_count(instances: Sequence[str]) -> int:
    """How many distinct furniture instances the episodes cover."""
    return len(set(instances))
