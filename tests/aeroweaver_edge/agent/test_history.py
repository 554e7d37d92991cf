"""The agent's own interaction history: frozen lines, block window, per episode."""

from __future__ import annotations

import pytest

from aeroweaver_edge.agent.history import InteractionHistory, history_line


def play(h: InteractionHistory, episode: int, rounds: range) -> list[tuple[str, ...]]:
    """What each round shows, deciding and rewarding as lockstep does."""
    shown = []
    for rnd in rounds:
        shown.append(h.lines(episode, rnd))
        h.record_decision(episode, rnd, f"skill_{rnd}()", True)
        h.record_reward(episode, rnd, -float(rnd))
    return shown


def test_a_line_names_round_invocation_and_reward_compactly() -> None:
    assert history_line(4, "explore_local()", True, -1.234) == "r4 explore_local() -1.2"
    assert history_line(5, "hold_position()", False, None) == "r5 hold_position() [no choice]"
    assert history_line(6, "x()", True, -0.001) == "r6 x() 0"  # never "-0"
    assert history_line(7, "y" * 200, True, 1.0) == "r7 " + "y" * 80 + " 1"
    # one plain parameter: its value only, as the option read; anything else unchanged
    assert history_line(8, "cover_landmark(target_id=L1)", True, -2.06) == (
        "r8 cover_landmark(L1) -2.1"
    )
    assert history_line(9, "go_to(north=1, east=2)", True, None) == "r9 go_to(north=1, east=2)"
    assert history_line(9, "say(text=a b)", True, float("nan")) == "r9 say(text=a b) nan"


def test_each_round_shows_the_earlier_rounds_with_their_rewards() -> None:
    shown = play(InteractionHistory(block=8), 0, range(4))
    assert shown[0] == ()
    assert shown[3] == (
        "r0 skill_0() 0",
        "r1 skill_1() -1",
        "r2 skill_2() -2",
    )


def test_the_window_turns_over_in_blocks_so_text_only_grows_in_between() -> None:
    block = 4
    shown = play(InteractionHistory(block=block), 0, range(30))
    turnovers = []
    for t in range(1, 30):
        prev, now = shown[t - 1], shown[t]
        if now[: len(prev)] != prev:
            turnovers.append(t)
            assert now[0] == f"r{t - block} skill_{t - block}() {-(t - block)}"
    # 3 * block lines decided, then every 2 * block rounds: with the default block of 8 a
    # 24-round episode never turns over (the README command's round 16 did, ~60 tokens a UAV)
    assert turnovers == [12, 20, 28]
    assert all(min(t, block) <= len(s) <= 3 * block - 1 for t, s in enumerate(shown))
    assert shown[29][-1].startswith("r28 ")  # the newest line is always there
    default = play(InteractionHistory(block=8), 0, range(24))
    assert all(default[t][: len(default[t - 1])] == default[t - 1] for t in range(1, 24))


def test_a_frozen_line_never_changes_even_if_its_reward_comes_late() -> None:
    h = InteractionHistory(block=8)
    h.lines(0, 0)
    h.record_decision(0, 0, "a()", True)
    first = h.lines(0, 1)  # shown before the reward arrived
    h.record_reward(0, 0, -3.0)
    assert first == ("r0 a()",)
    assert h.lines(0, 2) == ("r0 a()",)


def test_a_new_episode_starts_empty_and_old_rewards_are_ignored() -> None:
    h = InteractionHistory(block=8)
    play(h, 0, range(5))
    assert h.lines(1, 0) == ()
    h.record_reward(0, 3, 9.0)  # a late reward of the last episode
    h.record_decision(1, 0, "b()", False)
    h.record_reward(1, 0, 2.5)
    assert h.lines(1, 1) == ("r0 b() [no choice] 2.5",)


def test_block_must_be_positive() -> None:
    with pytest.raises(ValueError, match="at least 1"):
        InteractionHistory(block=0)
