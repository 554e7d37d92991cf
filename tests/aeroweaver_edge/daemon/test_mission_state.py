"""MissionState: the Commander's authority comes from its live session, not from a payload."""

from __future__ import annotations

from aeroweaver_edge.contracts.wire import Assignment, Header, MissionContext
from aeroweaver_edge.daemon.mission_state import MissionState


def ctx(
    epoch: int, seq: int, *, sender: str = "cmdr", mission: str = "m", state: str = "active"
) -> MissionContext:
    h = Header(sender=sender, epoch=epoch, seq=seq, stamp=0.0)
    return MissionContext(h=h, mission_id=mission, task="coverage", text="t", state=state)  # type: ignore[arg-type]


def assign(
    epoch: int, seq: int, *, role: str = "searcher", skills: tuple[str, ...] = ("cover_landmark",),
    sender: str = "cmdr", uav: str = "uav0", revision: int = 1, mission: str = "m",
) -> Assignment:  # fmt: skip
    h = Header(sender=sender, epoch=epoch, seq=seq, stamp=0.0)
    return Assignment(h=h, mission_id=mission, uav=uav, role=role, local_goal="g",
                      skills=list(skills), revision=revision)  # fmt: skip


def live(state: MissionState, epoch: int = 5) -> MissionState:
    state.commander_alive(True)
    state.update_context(ctx(epoch, 1))
    state.update_assignment(assign(epoch, 2))
    assert state.view() is not None
    return state


def test_only_the_commander_identity_counts() -> None:
    s = MissionState("uav0")
    s.update_context(ctx(1, 1, sender="uav1"))
    s.update_assignment(assign(1, 2, sender="world"))
    assert (s.context, s.assignment) == (None, None)
    assert s.rejected == {"not_commander": 2}
    s.update_assignment(assign(1, 3, uav="uav1"))  # someone else's: ignored, not an attack
    assert s.rejected.total() == 2


def test_forged_epoch_cannot_lock_a_tracking_uav_out() -> None:
    """Issue 10: a forged assignment with epoch 2^62 took a UAV over, and the real Commander
    could never reclaim it (a vehicle skill, ``land``, became active)."""
    s = live(MissionState("uav0", track_commander=True))
    s.update_assignment(assign(2**62, 1, role="lander", skills=("land",)))
    s.update_context(ctx(2**62, 2, state="ended"))
    view = s.view()
    assert view is not None
    assert (view.role, view.skills) == ("searcher", ("cover_landmark",))
    assert s.rejected == {"epoch_contested": 2}
    s.update_assignment(assign(5, 9, role="relay", revision=2))  # the real one still rules
    view = s.view()
    assert view is not None
    assert view.role == "relay"


def test_authority_ends_with_the_commanders_liveliness() -> None:
    s = live(MissionState("uav0", track_commander=True))
    changes = s.changes
    s.commander_alive(False)
    assert s.view() is None  # the UAV holds
    assert s.changes == changes + 1
    s.update_assignment(assign(5, 10))  # late or replayed: no live Commander, dropped
    assert s.view() is None
    assert s.rejected == {"no_live_commander": 1}
    s.commander_alive(True)  # a new Commander session (restarted: any epoch) takes over
    s.update_context(ctx(3, 1))
    s.update_assignment(assign(3, 2, role="relay"))
    view = s.view()
    assert view is not None
    assert view.role == "relay"


def test_payloads_before_the_token_are_applied_when_it_appears() -> None:
    """Links come up in any order: a context may arrive before the Commander's token."""
    s = MissionState("uav0", track_commander=True)
    s.update_context(ctx(5, 1))
    s.update_assignment(assign(5, 2))
    assert s.view() is None
    s.commander_alive(True)
    assert s.view() is not None
    assert s.rejected == {"no_live_commander": 2}
    s.commander_alive(False)
    s.update_context(ctx(5, 10))  # between sessions nothing is kept
    assert s._early == []
    fresh = MissionState("uav0", track_commander=True)
    for i in range(20):  # the start-up buffer is bounded
        fresh.update_context(ctx(5, 10 + i))
    assert len(fresh._early) == 8


def test_signed_restart_replaces_the_session_and_old_epochs_stay_out() -> None:
    s = live(MissionState("uav0", track_commander=True), epoch=5)
    s.update_context(ctx(6, 1), authenticated=True)  # restarted Commander, new mission text
    assert s.assignment is None  # nothing of the old session carries over
    s.update_assignment(assign(6, 2, role="relay"), authenticated=True)
    view = s.view()
    assert view is not None
    assert view.role == "relay"
    s.commander_alive(False)
    s.commander_alive(True)
    s.update_assignment(assign(5, 99), authenticated=True)  # a captured old signed payload
    assert s.assignment is None
    assert s.rejected == {"old_epoch": 1}


def test_untracked_mode_keeps_newest_epoch_wins() -> None:
    """Without the Commander's token wired in, the old rule stays (safe only when signed)."""
    s = MissionState("uav0")
    s.update_context(ctx(1, 1))
    s.update_assignment(assign(1, 2))
    s.update_context(ctx(2, 1))
    assert s.assignment is None
    s.update_context(ctx(1, 5))
    assert s.context is not None
    assert s.context.h.epoch == 2
    assert s.rejected == {"old_epoch": 1}


def test_within_a_session_older_data_does_not_replace_newer() -> None:
    s = live(MissionState("uav0", track_commander=True))
    s.update_assignment(assign(5, 20, role="relay", revision=2))
    s.update_assignment(assign(5, 21, role="stale", revision=1))  # a catch-up reply, older
    s.update_context(ctx(5, 0, mission="old"))
    view = s.view()
    assert view is not None
    assert (view.role, view.mission_id) == ("relay", "m")
    assert s.rejected.total() == 0


def test_a_commander_lost_mid_mission_is_told_apart_from_a_mission_it_ended() -> None:
    """A flying field UAV holds and waits when the Commander vanishes mid-mission, but
    lands when a Commander ended the mission and then left (issue 8)."""
    s = MissionState("uav0", track_commander=True)
    assert not s.commander_lost  # never had a Commander: nothing lost
    live(s)
    assert not s.commander_lost
    s.commander_alive(False)
    assert s.commander_lost
    s.commander_alive(True)  # back: a new session
    assert not s.commander_lost
    s.update_context(ctx(6, 1))
    s.update_context(ctx(6, 2, state="ended"))  # it ended the mission ...
    s.commander_alive(False)  # ... and then left
    assert not s.commander_lost
    untracked = live(MissionState("uav0"))
    untracked.commander_alive(False)
    assert not untracked.commander_lost  # without tracking the token decides nothing
