"""The benchmark's statistics, small enough to read: a bootstrap interval for a mean, the
Wilcoxon signed-rank test (exact, ties by mid-ranks) and Holm's step-down correction.

No numpy or scipy: the report must rebuild byte for byte from the archive wherever the
package installs, and each function is a few lines a reviewer can check against a textbook
(tests/aeroweaver_lab/bench/test_stats.py checks them on known values).
"""

from __future__ import annotations

import math
import random
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

BOOTSTRAP_RESAMPLES = 5000
BOOTSTRAP_SEED = 20261203  # fixed: the same episodes give the same interval, byte for byte


def bootstrap_ci(
    xs: Sequence[float],
    level: float = 0.95,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float] | None:
    """Percentile bootstrap interval of the mean (None below two values: no interval)."""
    if len(xs) < 2:
        return None
    rng = random.Random(seed)
    n = len(xs)
    means = sorted(statistics.fmean(rng.choices(xs, k=n)) for _ in range(resamples))
    lo = means[max(0, math.floor((1 - level) / 2 * resamples))]
    hi = means[min(resamples - 1, math.ceil((1 + level) / 2 * resamples) - 1)]
    return lo, hi


@dataclass(frozen=True)
class Wilcoxon:
    n: int  # non-zero differences (zeros are dropped, Wilcoxon's own rule)
    w_plus: float  # sum of the ranks of the positive differences
    p: float  # two-sided, exact under the null given these ranks (ties included)


def midranks(values: Sequence[float]) -> list[float]:
    """Ranks 1..n, ties sharing their average rank."""
    order = sorted(range(len(values)), key=lambda i: values[i])
    ranks = [0.0] * len(values)
    i = 0
    while i < len(order):
        j = i
        while j + 1 < len(order) and values[order[j + 1]] == values[order[i]]:
            j += 1
        for k in range(i, j + 1):
            ranks[order[k]] = (i + j) / 2 + 1
        i = j + 1
    return ranks


def wilcoxon(diffs: Sequence[float]) -> Wilcoxon | None:
    """Signed-rank test of paired differences against a median of 0; None when every
    difference is 0 (nothing to test). The null distribution of W+ is counted exactly: each
    rank's sign is + or - with probability 1/2 (doubled mid-ranks keep it in integers)."""
    d = [x for x in diffs if x != 0]
    if not d:
        return None
    ranks2 = [round(2 * r) for r in midranks([abs(x) for x in d])]
    w2 = sum(r for r, x in zip(ranks2, d, strict=True) if x > 0)
    counts = [0] * (sum(ranks2) + 1)  # counts[s]: sign patterns with doubled W+ = s
    counts[0] = 1
    for r in ranks2:
        for s in range(len(counts) - 1, r - 1, -1):
            counts[s] += counts[s - r]
    total = 2 ** len(d)
    low = sum(counts[: w2 + 1]) / total
    high = sum(counts[w2:]) / total
    return Wilcoxon(len(d), w2 / 2, min(1.0, 2 * min(low, high)))


def holm(pvalues: Sequence[float | None]) -> list[float | None]:
    """Holm's step-down adjusted p-values (family: the non-None entries), in input order."""
    given = sorted((p, i) for i, p in enumerate(pvalues) if p is not None)
    m = len(given)
    out: list[float | None] = [None] * len(pvalues)
    running = 0.0
    for rank, (p, i) in enumerate(given):
        running = max(running, min(1.0, (m - rank) * p))
        out[i] = running
    return out


__all__ = ["Wilcoxon", "bootstrap_ci", "holm", "midranks", "wilcoxon"]
