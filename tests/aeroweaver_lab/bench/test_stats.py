"""The benchmark's statistics on values a textbook (or scipy, where installed) gives."""

from __future__ import annotations

import itertools
import random
import statistics

import pytest

from aeroweaver_lab.bench.stats import bootstrap_ci, holm, wilcoxon


def test_wilcoxon_all_positive_is_the_smallest_exact_p() -> None:
    # ten positive differences: W+ = 55, the one most extreme of 2^10 sign patterns per side
    t = wilcoxon([float(x) for x in range(1, 11)])
    assert t is not None
    assert (t.n, t.w_plus) == (10, 55.0)
    assert t.p == pytest.approx(2 / 1024)


def test_wilcoxon_known_table_value() -> None:
    # n = 8, ranks 1..8, negatives on ranks 1, 2 and 3: W- = 6, W+ = 30. P(W- <= 6) =
    # #{subsets of 1..8 with sum <= 6} / 256 = 14 / 256; two-sided 28 / 256.
    t = wilcoxon([-1, -2, -3, 4, 5, 6, 7, 8])
    assert t is not None
    assert t.w_plus == 30.0
    subsets = sum(
        1 for k in range(9) for c in itertools.combinations(range(1, 9), k) if sum(c) <= 6
    )
    assert subsets == 14
    assert t.p == pytest.approx(28 / 256)


def test_wilcoxon_drops_zeros_and_returns_none_when_nothing_differs() -> None:
    assert wilcoxon([0.0, 0.0, 0.0]) is None
    t = wilcoxon([0.0, 1.0, 2.0, -0.5])
    assert t is not None
    assert t.n == 3


def test_wilcoxon_matches_scipy_exact_with_and_without_ties() -> None:
    scipy_stats = pytest.importorskip("scipy.stats")
    rng = random.Random(7)
    for _ in range(30):
        n = rng.randint(3, 14)
        d = [rng.choice([-1, 1]) * rng.uniform(0.1, 5) for _ in range(n)]
        ours = wilcoxon(d)
        assert ours is not None
        ref = scipy_stats.wilcoxon(d, method="exact")
        assert ours.p == pytest.approx(ref.pvalue, rel=1e-9)
    # tied magnitudes: the exact permutation distribution of mid-ranks (scipy's
    # "permutation" method agrees; its "exact" table assumes no ties)
    d = [1.0, -1.0, 2.0, 2.0, 3.0, -4.0, 5.0, 5.0]
    ours = wilcoxon(d)
    assert ours is not None
    signs = list(itertools.product([-1, 1], repeat=len(d)))
    from aeroweaver_lab.bench.stats import midranks

    ranks = midranks([abs(x) for x in d])
    null = [sum(r for r, s in zip(ranks, sg, strict=True) if s > 0) for sg in signs]
    low = sum(w <= ours.w_plus for w in null) / len(null)
    high = sum(w >= ours.w_plus for w in null) / len(null)
    assert ours.p == pytest.approx(min(1.0, 2 * min(low, high)))


def test_holm_step_down() -> None:
    # textbook: p = (0.01, 0.04, 0.03, 0.005), m = 4 -> sorted 0.005*4, 0.01*3, 0.03*2, 0.04*1
    assert holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert holm([0.5, None, 0.9]) == [pytest.approx(1.0), None, pytest.approx(1.0)]
    assert holm([]) == []


def test_bootstrap_interval_holds_the_mean_and_is_reproducible() -> None:
    xs = [float(x) for x in range(10)]
    ci = bootstrap_ci(xs)
    assert ci is not None
    lo, hi = ci
    assert lo < statistics.fmean(xs) < hi
    assert 2.0 < lo < 4.5
    assert 4.5 < hi < 7.0
    assert bootstrap_ci(xs) == ci  # fixed seed: byte-for-byte reports
    assert bootstrap_ci([3.0]) is None
    assert bootstrap_ci([2.0, 2.0, 2.0]) == (2.0, 2.0)
