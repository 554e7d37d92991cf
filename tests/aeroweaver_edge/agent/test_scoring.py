"""Selector arithmetic on hand-made distributions: base score, correction, every bound-rule case.

Distributions are written as probabilities and converted with ``math.log`` so each case reads
like the design text (DESIGN §4 step 4).
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aeroweaver_edge.agent.scoring import NOT_OBSERVED, LabelScores, choose, omitted_bound

LABELS = ["A", "B", "C", "D"]
ln = math.log


def scores(probs: dict[str, float], bound: float = -math.inf, **kw: object) -> LabelScores:
    return LabelScores(logprobs={k: ln(v) for k, v in probs.items()}, omitted_bound=bound, **kw)  # type: ignore[arg-type]


# ------------------------------------------------------------------ omitted_bound


def test_bound_is_leftover_mass_when_list_is_short() -> None:
    # 3 of 20 requested came back: only the leftover mass bounds a missing token
    assert omitted_bound([ln(0.5), ln(0.2), ln(0.1)], requested=20) == pytest.approx(ln(0.2))


def test_bound_is_list_floor_when_list_is_full_and_floor_is_lower() -> None:
    top = [ln(0.5), ln(0.2), ln(0.1), ln(0.05)]  # leftover 0.15 > floor 0.05
    assert omitted_bound(top, requested=4) == pytest.approx(ln(0.05))


def test_bound_is_leftover_when_full_list_leaves_less_than_its_floor() -> None:
    top = [ln(0.6), ln(0.3), ln(0.08)]  # leftover 0.02 < floor 0.08
    assert omitted_bound(top, requested=3) == pytest.approx(ln(0.02))


def test_bound_ignores_floors_and_is_minus_inf_when_all_mass_seen() -> None:
    assert omitted_bound([ln(0.7), ln(0.3), NOT_OBSERVED], requested=3) == -math.inf
    # -9999 entries do not make the list "full"
    assert omitted_bound([ln(0.5), NOT_OBSERVED, NOT_OBSERVED], requested=3) == pytest.approx(
        ln(0.5)
    )


def test_bound_of_empty_list_is_certainty() -> None:
    assert omitted_bound([], requested=20) == 0.0


# ------------------------------------------------------------------ choose


def test_no_omissions_correction_can_change_the_pick() -> None:
    s = scores({"A": 0.4, "B": 0.3, "C": 0.2, "D": 0.1})
    c = choose(s, LABELS, {"B": 1.0}, beta=0.8)
    assert c.label == "B"
    assert c.corrected
    assert c.corrected_scores["B"] == pytest.approx(ln(0.3) + 0.8)


def test_correction_agreeing_with_base_is_not_flagged() -> None:
    c = choose(scores({"A": 0.6, "B": 0.3, "C": 0.1, "D": 0.0001}), LABELS, {"A": 0.5}, beta=0.8)
    assert c.label == "A"
    assert not c.corrected
    assert "agrees" in c.reason


def test_omitted_label_bounded_by_full_list_floor_keeps_correction() -> None:
    # D omitted; full list floor ln(0.05) + beta*A_D = -3.0 + 0.8 < corrected B = -1.2 + 0.8
    s = scores({"A": 0.5, "B": 0.3, "C": 0.05}, bound=ln(0.05))
    c = choose(s, LABELS, {"B": 1.0, "D": 1.0}, beta=0.8)
    assert c.label == "B"
    assert c.corrected


def test_omitted_label_bounded_by_leftover_mass_keeps_correction() -> None:
    s = scores({"A": 0.55, "B": 0.4}, bound=ln(0.05))  # short list: leftover 0.05
    c = choose(s, LABELS, {"B": 0.5, "C": 0.5, "D": 0.5}, beta=0.8)
    assert c.label == "B"
    assert c.corrected


def test_omitted_label_with_large_advantage_forces_base_argmax() -> None:
    # D is missing; it could be as large as ln(0.1); with advantage 5 it could beat corrected B
    s = scores({"A": 0.5, "B": 0.4}, bound=ln(0.1))
    c = choose(s, LABELS, {"B": 1.0, "D": 5.0}, beta=0.8)
    assert c.label == "A"  # the base argmax, not the corrected winner B
    assert not c.corrected
    assert "bound rule" in c.reason
    assert "D" in c.reason


def test_bound_rule_only_matters_when_correction_changes_the_pick() -> None:
    s = scores({"A": 0.5, "B": 0.4}, bound=ln(0.1))
    c = choose(s, LABELS, {"A": 1.0, "D": 5.0}, beta=0.8)
    assert c.label == "A"
    assert "bound rule" not in c.reason


def test_omitted_bound_equal_to_winner_does_not_trigger_fallback() -> None:
    s = scores({"A": 0.5, "B": 0.4}, bound=ln(0.4))
    c = choose(s, LABELS, {"B": 1.0, "D": 1.0}, beta=1.0)  # D's bound ties corrected B
    assert c.label == "B"
    assert c.corrected


def test_beta_zero_is_the_plain_selector() -> None:
    s = scores({"A": 0.3, "B": 0.7}, bound=ln(0.9))
    c = choose(s, LABELS, {"A": 100.0, "C": 100.0}, beta=0.0)
    assert c.label == "B"
    assert c.reason == "base score"
    assert c.corrected_scores == c.base


def test_base_ties_go_to_the_earlier_label() -> None:
    s = scores({"C": 0.4, "B": 0.4, "A": 0.2})
    assert choose(s, LABELS, {}, beta=0.0).label == "B"


def test_corrected_ties_go_to_the_earlier_label() -> None:
    s = LabelScores(logprobs={"A": -1.0, "B": -2.0, "C": -1.5})
    c = choose(s, LABELS, {"B": 1.0, "C": 0.5}, beta=1.0)  # A, B, C all at -1.0
    assert c.label == "A"


def test_minus_9999_floors_are_not_scores_and_count_as_omitted() -> None:
    s = LabelScores(logprobs={"A": NOT_OBSERVED, "B": ln(0.3), "C": ln(0.2)}, omitted_bound=ln(0.5))
    c = choose(s, LABELS, {}, beta=0.8)
    assert c.label == "B"
    assert "A" not in c.base
    # and A, being omitted, can trigger the bound rule with a large advantage
    c = choose(s, LABELS, {"C": 2.0, "A": 3.0}, beta=1.0)
    assert c.label == "B"
    assert "bound rule: omitted A" in c.reason


def test_only_floors_means_hold() -> None:
    s = LabelScores(logprobs={"A": NOT_OBSERVED, "B": NOT_OBSERVED})
    c = choose(s, LABELS, {}, beta=0.8)
    assert c.label is None


def test_no_candidate_label_returned_means_hold() -> None:
    c = choose(LabelScores(logprobs={"Z": -0.1}), LABELS, {}, beta=0.8)
    assert c.label is None
    assert "no candidate label" in c.reason


def test_error_means_hold() -> None:
    c = choose(LabelScores(logprobs={}, error="LLMTimeout: no answer"), LABELS, {}, beta=0.8)
    assert c.label is None
    assert "LLMTimeout" in c.reason


def test_text_label_fallback_when_logprobs_unusable() -> None:
    s = LabelScores(logprobs={"A": -0.1}, logprobs_usable=False, text_label="C")
    c = choose(s, LABELS, {"A": 9.0}, beta=0.8)
    assert c.label == "C"
    assert "correction off" in c.reason


def test_unusable_logprobs_and_no_valid_text_label_means_hold() -> None:
    for text in (None, "The", "Z"):
        s = LabelScores(logprobs={}, logprobs_usable=False, text_label=text)
        assert choose(s, LABELS, {}, beta=0.8).label is None


def test_labels_outside_the_candidate_set_are_ignored() -> None:
    s = scores({"A": 0.2, "Q": 0.7})
    assert choose(s, ["A", "B"], {}, beta=0.0).label == "A"


# ------------------------------------------------------------------ properties


probs = st.lists(st.floats(0.001, 1.0), min_size=1, max_size=4)


@given(probs, st.lists(st.floats(-3, 3), min_size=4, max_size=4), st.floats(0, 2))
def test_choice_is_a_returned_label_and_no_omissions_means_corrected_argmax(
    ps: list[float], advs: list[float], beta: float
) -> None:
    total = sum(ps)
    base = {lb: ln(p / total) for lb, p in zip(LABELS, ps, strict=False)}
    adv = dict(zip(LABELS, advs, strict=True))
    c = choose(LabelScores(logprobs=base, omitted_bound=-math.inf), LABELS, adv, beta)
    assert c.label in base
    best = max(base[lb] + beta * adv[lb] for lb in base)
    assert base[c.label] + beta * adv[c.label] == pytest.approx(best)


@given(probs, st.floats(-10, 0))
def test_beta_zero_always_picks_the_base_argmax(ps: list[float], bound: float) -> None:
    base = {lb: ln(p) for lb, p in zip(LABELS, ps, strict=False)}
    c = choose(LabelScores(logprobs=base, omitted_bound=bound), LABELS, {"D": 50.0}, 0.0)
    assert c.label is not None
    assert base[c.label] == max(base.values())
