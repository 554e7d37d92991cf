"""The bench's own statistics against known values (scipy 1.17's ``wilcoxon`` gave the
reference p-values; scipy is not a dependency)."""

from __future__ import annotations

import math
import random

import pytest

from aeroweaver_lab.bench import paired_stats
from aeroweaver_lab.bench.paired_stats import bootstrap_ci, paired_summary, wilcoxon_p


@pytest.mark.parametrize(
    ("diffs", "p"),
    [
        ([1, 2, 3, 4, 5], 0.0625),  # the smallest two-sided p with n = 5
        ([-1, 2, 3, 4, 5, 6], 0.0625),
        ([0.5, -1.5, 2.5, 3, -0.2, 4, 1.1, 2.2, -3.3, 0.9], 0.232421875),
        ([1, -2, 3, -4, 5, 6, -7, 8, 9, 10, 11, -12], 0.30126953125),
        ([0, 1, 2, 3, 4, 5], 0.0625),  # a zero difference is dropped (Wilcoxon's method)
    ],
)
def test_exact_p_values(diffs: list[float], p: float) -> None:
    assert wilcoxon_p(diffs) == pytest.approx(p, rel=1e-12)


def test_ties_share_ranks_exactly() -> None:
    # |d| = 1, 1, 1, 2: ranks 2, 2, 2, 4; W+ = 8 of 10; P(W+ >= 8) = 4/16
    assert wilcoxon_p([1, 1, -1, 2]) == 0.5


def test_normal_approximation_with_ties_and_continuity() -> None:
    big = [((i * 37) % 23 - 9) / 3 for i in range(1, 61)]  # 60 values, ties, zeros
    # scipy.stats.wilcoxon(big, method="approx", correction=True).pvalue
    assert wilcoxon_p(big) == pytest.approx(0.024875747413353716, rel=1e-9)


def test_exact_and_approximation_agree_near_the_switch(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = random.Random(3)
    d = [rng.gauss(0.3, 1) for _ in range(50)]
    exact = wilcoxon_p(d)
    monkeypatch.setattr(paired_stats, "EXACT_MAX", 10)
    assert wilcoxon_p(d) == pytest.approx(exact, abs=0.01)


def test_degenerate_inputs() -> None:
    assert wilcoxon_p([]) == 1.0
    assert wilcoxon_p([0.0, 1e-12]) == 1.0
    lo, hi = bootstrap_ci([])
    assert math.isnan(lo)
    assert math.isnan(hi)
    assert bootstrap_ci([2.0, 2.0, 2.0]) == (2.0, 2.0)


def test_bootstrap_is_seeded_and_brackets_the_mean() -> None:
    xs = [0.3, -0.1, 0.8, 1.2, 0.4, -0.5, 0.9, 0.2, 0.6, 0.1]
    a = bootstrap_ci(xs)
    assert a == bootstrap_ci(xs)
    assert a != bootstrap_ci(xs, seed=1)
    assert a[0] < sum(xs) / len(xs) < a[1]
    assert bootstrap_ci(xs, level=0.5)[0] > a[0]


def test_paired_summary_record() -> None:
    s = paired_summary([1.0, 2.0, 3.0, 4.0], [0.5, 2.0, 3.5, 1.0])
    assert s["diffs"] == [0.5, 0.0, -0.5, 3.0]
    assert s["mean_diff"] == 0.75
    assert (s["better"], s["worse"], s["equal"]) == (2, 1, 1)
    assert s["p_wilcoxon"] == wilcoxon_p([0.5, 0.0, -0.5, 3.0])
    assert set(s) >= {"mean_diff", "ci95", "better", "worse", "equal", "p_wilcoxon"}
