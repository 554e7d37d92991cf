"""Paired statistics over seed sequences: bootstrap interval and Wilcoxon signed-rank test.

Written out so the adaptation bench needs no scipy; the exact test and the mid-ranks are
``bench.stats``' (the benchmark's), this module adds the normal approximation above
``EXACT_MAX`` and the adaptation bench's record. The signed-rank test
is two-sided, drops zero differences (Wilcoxon's method) and gives tied magnitudes their
average rank; up to ``EXACT_MAX`` non-zero differences the p-value is exact (the
permutation distribution of the positive-rank sum, ties included, by dynamic programming
over doubled ranks), above that the normal approximation with tie and continuity
corrections (as ``scipy.stats.wilcoxon(..., method="approx", correction=True)``).
"""

from __future__ import annotations

import math
import random
import statistics
from collections.abc import Sequence
from typing import Final

from aeroweaver_lab.bench.stats import midranks, wilcoxon

EXACT_MAX: Final = 50
EQUAL_TOL: Final = 1e-9  # differences within this are "equal" (float noise, not an effect)


def bootstrap_ci(
    xs: Sequence[float], *, level: float = 0.95, resamples: int = 10_000, seed: int = 0
) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of ``xs`` (seeded: reproducible)."""
    if not xs:
        return (math.nan, math.nan)
    rng = random.Random(seed)
    n = len(xs)
    means = sorted(math.fsum(rng.choices(xs, k=n)) / n for _ in range(resamples))
    lo = means[math.floor((1 - level) / 2 * resamples)]
    hi = means[min(resamples - 1, math.ceil((1 + level) / 2 * resamples) - 1)]
    return (lo, hi)


def wilcoxon_p(diffs: Sequence[float]) -> float:
    """Two-sided p-value of the signed-rank test that the differences centre on 0;
    1.0 when every difference is zero."""
    d = [x for x in diffs if abs(x) > EQUAL_TOL]
    n = len(d)
    if n == 0:
        return 1.0
    if n <= EXACT_MAX:  # the benchmark's exact test (bench.stats), on the same differences
        exact = wilcoxon(d)
        assert exact is not None  # d has no zero
        return exact.p
    ranks = midranks([abs(x) for x in d])
    w_plus = math.fsum(r for r, x in zip(ranks, d, strict=True) if x > 0)
    mean = n * (n + 1) / 4
    ties: dict[float, int] = {}
    for rank in ranks:
        ties[rank] = ties.get(rank, 0) + 1
    var = n * (n + 1) * (2 * n + 1) / 24 - sum(t**3 - t for t in ties.values()) / 48
    if var <= 0:
        return 1.0
    z = (abs(w_plus - mean) - 0.5) / math.sqrt(var)
    return min(1.0, math.erfc(max(z, 0.0) / math.sqrt(2)))


def paired_summary(beta_means: Sequence[float], base_means: Sequence[float]) -> dict[str, object]:
    """The bench's per-task record from per-sequence mean returns (same order)."""
    diffs = [b - a for b, a in zip(beta_means, base_means, strict=True)]
    lo, hi = bootstrap_ci(diffs)
    return {
        "mean_diff": statistics.fmean(diffs) if diffs else math.nan,
        "ci95": [lo, hi],
        "better": sum(x > EQUAL_TOL for x in diffs),
        "worse": sum(x < -EQUAL_TOL for x in diffs),
        "equal": sum(abs(x) <= EQUAL_TOL for x in diffs),
        "p_wilcoxon": wilcoxon_p(diffs),
        "diffs": diffs,
    }


__all__ = ["bootstrap_ci", "paired_summary", "wilcoxon_p"]
