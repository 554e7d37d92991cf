"""Wire payloads, codec, headers, replay filter and key layout (DESIGN §3)."""

from __future__ import annotations

import itertools
import logging
import subprocess
import sys

import msgspec
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aeroweaver_edge.contracts.wire import (
    MAX_PAYLOAD_BYTES,
    SCHEMA_VERSION,
    Approval,
    ApprovalRecord,
    ApprovalStatus,
    Assignment,
    CentralAnswer,
    CentralAsk,
    CentralReview,
    Codec,
    DecodeStats,
    Entity,
    ExperienceRecord,
    Header,
    HeaderFactory,
    InboxMessage,
    Keys,
    MissionContext,
    MsgRef,
    OperatorCommand,
    Payload,
    PendingAction,
    ProgressReport,
    ReplayFilter,
    SimCommand,
    SimEpisode,
    SimPerception,
    SimReward,
    StateBeacon,
    WorldSnapshot,
    last_chunk,
)

H = Header(sender="uav1", epoch=7, seq=3, stamp=1234.5, ttl_s=4.0)
ENC = msgspec.msgpack.Encoder()

SAMPLES: list[msgspec.Struct] = [
    StateBeacon(
        h=H,
        uav="uav1",
        round=4,
        pos=(1.0, -2.0, -5.0),
        vel=(0.5, 0.0, 0.0),
        role="searcher",
        status="nominal",
    ),
    InboxMessage(
        h=H,
        to="uav2",
        round=4,
        kind="intent",
        body={"target_id": "L1", "north": 3.5, "n": 2, "ok": True},
        sender_pos=(1.0, 2.0, -5.0),
        ttl_rounds=3,
    ),
    ProgressReport(
        h=H,
        phase="ready",
        uav="uav1",
        mission_id="m",
        episode=-1,
        round=-1,
        role="searcher",
        skill="",
        invocation="",
        label=None,
        held=True,
    ),
    ProgressReport(
        h=H,
        uav="uav1",
        mission_id="m",
        episode=0,
        round=5,
        role="searcher",
        skill="cover_landmark",
        invocation="cover_landmark(target_id=L1)",
        label="B",
        held=False,
        hold_reason=None,
        reward=-1.25,
        prompt_tokens=100,
        completion_tokens=1,
        latency_s=0.2,
        messages_sent=2,
        messages_dropped=1,
        decode_errors=3,
        corrected=True,
    ),
    MissionContext(
        h=H,
        mission_id="m",
        task="coverage",
        text="cover all",
        constraints=["stay inside"],
        participants=["uav0", "uav1"],
        episode=2,
    ),
    Assignment(
        h=H,
        mission_id="m",
        uav="uav1",
        role="searcher",
        local_goal="reach one",
        skills=["cover_landmark", "hold_position"],
        revision=3,
    ),
    ExperienceRecord(
        h=H,
        task="coverage",
        role="searcher",
        uav="uav1",
        episode=0,
        round=2,
        state_text="round 2",
        skill="hold_position",
        invocation="hold_position()",
        reward=-0.5,
        ret=-2.0,
        final=True,
        reward_source="sim",
    ),
    SimPerception(
        h=H,
        uav="uav1",
        episode=0,
        round=1,
        deadline_s=2.0,
        pos=(0.0, 0.0, -5.0),
        vel=(1.0, 1.0, 0.0),
        entities=[
            Entity(id="L0", kind="landmark", pos=(3.0, 4.0, -5.0)),
            Entity(
                id="uav2", kind="uav", pos=(9.0, 9.0, -5.0), vel=(1.0, 0.0, 0.0), role="searcher"
            ),
        ],
        expected_inbox=[MsgRef(sender="uav2", seq=9, to="uav1")],
    ),
    SimReward(h=H, uav="uav1", episode=0, round=1, reward=-0.75, done=True, reason="horizon"),
    SimCommand(
        h=H,
        uav="uav1",
        episode=0,
        round=1,
        vel=(1.0, 0.0, 0.0),
        held=False,
        sent=[MsgRef(sender="uav1", seq=4, to="uav2")],
    ),
    SimEpisode(h=H, episode=0, task="coverage", phase="end", reason="complete"),
    CentralAsk(
        h=H,
        uav="uav1",
        mission_id="m1",
        episode=0,
        round=2,
        role="searcher",
        local_goal="cover a landmark",
        observation="you: north 0 east 0",
        messages=["uav2 intent r1: skill=cover_landmark"],
        options=["A. cover_landmark(target_id=L0)", "B. hold_position()"],
        deadline_s=10.0,
    ),
    CentralReview(h=H, uav="uav1", episode=0, round=2, agree=False, suggest="B"),
    CentralAnswer(h=H, uav="uav1", episode=0, round=2, phase="final", label="A", reason="plan"),
    WorldSnapshot(
        h=H,
        task="coverage",
        episode=0,
        round=3,
        uavs=["uav1", "uav2"],
        bodies=[Entity(id="uav1", kind="uav", pos=(1.5, -2.0, -5.0), role="searcher")],
        entities=[Entity(id="L0", kind="landmark", pos=(10.0, 20.0, 0.0))],
        rewards={"uav1": -1.25},
        held=["uav2"],
        messages=[MsgRef(sender="uav1", seq=4, to="uav2")],
        reason="",
    ),
    OperatorCommand(h=H, action="stop", mission_id="m1", reason="wind", by="ops"),
    Approval(h=H, id="appr-0001", uav="uav1", action="takeoff", ttl_s=60.0, by="ops"),
    ApprovalStatus(
        h=H,
        uav="uav1",
        level="normal",
        pending=[PendingAction(action="land", since=12.0, skill="land")],
        records=[
            ApprovalRecord(
                id="appr-0001",
                action="takeoff",
                sender="operator",
                by="ops",
                issued=1.0,
                received=1.1,
                expires=61.1,
                state="used",
                uses=1,
            )
        ],
        ack="appr-0001",
    ),
]


def _beacon_dict(**over: object) -> dict[str, object]:
    """A StateBeacon as a plain mapping, to hand-craft wrong payloads."""
    d = msgspec.to_builtins(SAMPLES[0])
    assert isinstance(d, dict)
    d.update(over)
    return d


# ------------------------------------------------------------------ round trip


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: type(m).__name__)
def test_every_payload_round_trips(msg: msgspec.Struct) -> None:
    codec = Codec()
    data = codec.encode(msg)
    assert codec.decode(data, type(msg)) == msg
    # ... and through the tagged union, which is how a generic sniffer would read it.
    assert msgspec.msgpack.decode(data, type=Payload) == msg
    assert codec.stats.total == 0


def test_every_payload_type_is_sampled() -> None:
    assert {type(m) for m in SAMPLES} == set(Payload.__args__)


def test_header_defaults_to_the_current_schema_version() -> None:
    assert H.v == SCHEMA_VERSION


# ------------------------------------------------------------------ rejection (never raises)


def test_garbage_bytes_are_counted_not_raised() -> None:
    codec = Codec()
    assert codec.decode(b"\xc1\xc1\xc1 not msgpack", StateBeacon, "aw/s/uav/a/state") is None
    assert codec.stats.total == 1
    [reason] = codec.stats.rejected
    assert "StateBeacon" in reason


def test_truncated_msgpack_is_rejected() -> None:
    codec = Codec()
    data = codec.encode(SAMPLES[0])
    for cut in (1, len(data) // 2, len(data) - 1):
        assert codec.decode(data[:cut], StateBeacon) is None
    assert codec.stats.total == 3


def test_empty_payload_is_rejected() -> None:
    codec = Codec()
    assert codec.decode(b"", StateBeacon) is None
    assert codec.stats.total == 1


def test_wrong_type_for_a_key_is_rejected() -> None:
    codec = Codec()
    bad = ENC.encode(_beacon_dict(round="four"))
    assert codec.decode(bad, StateBeacon) is None
    bad_pos = ENC.encode(_beacon_dict(pos=[1.0, 2.0]))  # a Vec3 needs three numbers
    assert codec.decode(bad_pos, StateBeacon) is None
    assert codec.stats.total == 2


def test_invalid_utf8_in_a_string_is_rejected_not_raised() -> None:
    """msgspec raises UnicodeDecodeError (not DecodeError) for a str that is not UTF-8;
    this used to escape ``decode`` (found by the mutation property below)."""
    codec = Codec()
    data = bytearray(codec.encode(SAMPLES[0]))
    at = bytes(data).index(b"state") + 1  # inside the tag's str payload
    data[at] = 0x80
    assert codec.decode(bytes(data), StateBeacon) is None
    assert codec.stats.total == 1


def test_missing_header_is_rejected() -> None:
    codec = Codec()
    d = _beacon_dict()
    del d["h"]
    assert codec.decode(ENC.encode(d), StateBeacon) is None
    assert codec.stats.total == 1


def test_another_payload_type_on_the_key_is_rejected() -> None:
    """The tag keeps an InboxMessage from being read as a beacon even if fields overlap."""
    codec = Codec()
    assert codec.decode(codec.encode(SAMPLES[1]), StateBeacon) is None
    assert codec.decode(codec.encode(SAMPLES[9]), SimReward) is None
    assert codec.stats.total == 2


def test_oversize_payload_is_rejected_before_decoding() -> None:
    codec = Codec()
    data = codec.encode(SAMPLES[0]) + b"\x00" * MAX_PAYLOAD_BYTES
    assert codec.decode(data, StateBeacon) is None
    assert codec.stats.rejected == {"oversize": 1}


def test_payload_exactly_at_the_cap_is_accepted() -> None:
    codec = Codec()
    base = len(codec.encode(MissionContext(h=H, mission_id="m", task="t", text="")))
    # str header grows by 2 bytes (str16) once the text passes 255 chars, by 4 past 65535.
    msg = MissionContext(h=H, mission_id="m", task="t", text="x" * (MAX_PAYLOAD_BYTES - base - 2))
    data = codec.encode(msg)
    assert len(data) == MAX_PAYLOAD_BYTES
    assert codec.decode(data, MissionContext) == msg


def test_wrong_schema_version_is_rejected() -> None:
    codec = Codec()
    future = StateBeacon(
        h=msgspec.structs.replace(H, v=SCHEMA_VERSION + 1),
        uav="uav1",
        round=0,
        pos=(0.0, 0.0, 0.0),
        vel=(0.0, 0.0, 0.0),
    )
    assert codec.decode(codec.encode(future), StateBeacon) is None
    assert codec.stats.total == 1
    [reason] = codec.stats.rejected
    assert "schema" in reason


def test_stats_count_by_reason() -> None:
    codec = Codec()
    future = msgspec.structs.replace(SAMPLES[5], h=msgspec.structs.replace(H, v=99))
    codec.decode(b"\xff" * (MAX_PAYLOAD_BYTES + 1), Assignment)
    codec.decode(b"\xff" * (MAX_PAYLOAD_BYTES + 1), Assignment)
    codec.decode(codec.encode(future), Assignment)
    codec.decode(b"\xc1", Assignment)
    assert codec.stats.total == 4
    assert codec.stats.rejected["oversize"] == 2
    assert len(codec.stats.rejected) == 3


def test_reasons_stay_few_under_attacker_chosen_content(caplog: pytest.LogCaptureFixture) -> None:
    """Rejection reasons are categories, not echoes of the payload: a flood of distinct bad
    payloads must neither grow the counter without bound nor defeat the log rate limit."""
    codec = Codec(DecodeStats(log_interval_s=60.0))
    with caplog.at_level(logging.WARNING, logger="aeroweaver_edge.contracts.wire"):
        for i in range(200):
            codec.decode(ENC.encode(_beacon_dict(type=f"forged-{i}")), StateBeacon, "k")
            codec.decode(
                ENC.encode(_beacon_dict(h={**msgspec.to_builtins(H), "v": 100 + i})),
                StateBeacon,
                "k",
            )
            codec.decode(ENC.encode({"h": "x" * i}), StateBeacon, "k")
    assert codec.stats.total == 600
    assert len(codec.stats.rejected) <= 4
    assert len(caplog.records) <= 4


def test_rejections_log_once_per_interval(caplog: pytest.LogCaptureFixture) -> None:
    codec = Codec(DecodeStats(log_interval_s=60.0))
    with caplog.at_level(logging.WARNING, logger="aeroweaver_edge.contracts.wire"):
        for _ in range(50):
            codec.decode(b"\xc1", StateBeacon, "aw/s/uav/a/state")
    assert codec.stats.total == 50
    assert len(caplog.records) == 1
    assert "aw/s/uav/a/state" in caplog.records[0].getMessage()


def test_encode_over_the_cap_raises() -> None:
    codec = Codec()
    huge = MissionContext(h=H, mission_id="m", task="coverage", text="x" * MAX_PAYLOAD_BYTES)
    with pytest.raises(ValueError, match="cap"):
        codec.encode(huge)


PAYLOAD_TYPES = sorted(Payload.__args__, key=lambda t: t.__name__)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.binary(max_size=512), kind=st.sampled_from(PAYLOAD_TYPES))
def test_arbitrary_bytes_never_raise(data: bytes, kind: type[msgspec.Struct]) -> None:
    codec = Codec()
    out = codec.decode(data, kind)
    assert out is None or isinstance(out, kind)
    assert codec.stats.total == (0 if out is not None else 1)


@settings(max_examples=300, deadline=None)
@given(
    index=st.integers(0, len(SAMPLES) - 1),
    flips=st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 255)), min_size=1, max_size=6),
    cut=st.integers(0, 10_000),
)
def test_mutated_valid_payloads_never_raise(
    index: int, flips: list[tuple[int, int]], cut: int
) -> None:
    """Bit rot in a real payload: decodes to a valid struct of the right type, or to None."""
    msg = SAMPLES[index]
    codec = Codec()
    data = bytearray(codec.encode(msg))
    for pos, value in flips:
        data[pos % len(data)] = value
    data = data[: max(1, cut % (len(data) + 1))]
    out = codec.decode(bytes(data), type(msg))
    assert out is None or isinstance(out, type(msg))


# ------------------------------------------------------------------ headers and replay


def test_header_factory_sequence_is_strictly_increasing() -> None:
    hf = HeaderFactory("uav3", epoch=42)
    headers = [hf.next() for _ in range(100)]
    seqs = [h.seq for h in headers]
    assert seqs == sorted(set(seqs))
    assert seqs[0] == 1
    assert hf.last_seq == 100
    assert {(h.sender, h.epoch, h.v) for h in headers} == {("uav3", 42, SCHEMA_VERSION)}
    assert hf.next(ttl_s=2.5).ttl_s == 2.5


def test_header_factory_default_epoch_differs_per_boot() -> None:
    """A later boot has a larger epoch: strictly, in this process and in another one."""
    before = [HeaderFactory("u").epoch for _ in range(1000)]
    assert before[0] > 1_600_000_000 * 10**9  # wall-clock nanoseconds, not a counter from 0
    assert all(b > a for a, b in itertools.pairwise(before))
    code = "from aeroweaver_edge.contracts.wire import HeaderFactory as H; print(H('u').epoch)"
    child = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    after = HeaderFactory("u").epoch
    assert before[-1] < int(child.stdout) < after


def _h(sender: str, epoch: int, seq: int) -> Header:
    return Header(sender=sender, epoch=epoch, seq=seq, stamp=0.0)


def test_replay_filter_drops_duplicates_and_older_seq() -> None:
    rf = ReplayFilter()
    assert rf.accept(_h("a", 1, 5))
    assert not rf.accept(_h("a", 1, 5))  # duplicate
    assert not rf.accept(_h("a", 1, 4))  # older
    assert rf.accept(_h("a", 1, 6))
    assert rf.accept(_h("a", 1, 100))  # gaps are fine


def test_replay_filter_takes_an_authenticated_new_epoch_at_once() -> None:
    rf = ReplayFilter()
    assert rf.accept(_h("a", 1, 50))
    assert rf.accept(_h("a", 2, 1), authenticated=True)  # restart: sequence starts again
    assert rf.check(_h("a", 1, 51), authenticated=True) == "old_epoch"  # pre-restart replay
    assert rf.accept(_h("a", 2, 2))


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_forged_future_epoch_cannot_poison_a_live_sender() -> None:
    """The issue-10 attack: one unsigned message with a future epoch used to make every
    later genuine message a 'replay'. While the sender is live it is now refused."""
    clock = FakeClock()
    rf = ReplayFilter(quiet_s=5.0, clock=clock)
    assert rf.accept(_h("a", 7, 10))
    assert rf.check(_h("a", 2**62, 1)) == "epoch_contested"
    clock.now += 4.99
    assert rf.check(_h("a", 8, 1)) == "epoch_contested"  # still inside the quiet time
    for seq in range(11, 20):
        assert rf.accept(_h("a", 7, seq))  # the genuine sender is unaffected


def test_unauthenticated_new_epoch_after_leave_or_silence() -> None:
    clock = FakeClock()
    rf = ReplayFilter(quiet_s=5.0, clock=clock)
    assert rf.accept(_h("a", 7, 10))
    rf.release("a")  # its liveliness token went away: the session ended
    assert rf.check(_h("a", 6, 99)) == "old_epoch"  # older epochs stay refused
    assert rf.accept(_h("a", 8, 1))
    clock.now += 5.0  # silent for exactly quiet_s: the restart may take over
    assert rf.accept(_h("a", 9, 1))
    rf.release("b")  # unknown sender: nothing to release


def test_max_epoch_step_bounds_unauthenticated_leaps_only() -> None:
    rf = ReplayFilter(max_epoch_step=16)
    assert rf.accept(_h("a", 3, 1))
    rf.release("a")
    assert rf.check(_h("a", 20, 1)) == "epoch_jump"  # 17 ahead
    assert rf.accept(_h("a", 19, 1))  # exactly 16 ahead
    assert rf.accept(_h("a", 2**62, 1), authenticated=True)  # a signature vouches for it


def test_replay_filter_is_per_sender() -> None:
    rf = ReplayFilter()
    assert rf.accept(_h("a", 1, 5))
    assert rf.accept(_h("b", 1, 5))
    assert not rf.accept(_h("b", 1, 5))


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.tuples(st.sampled_from("abc"), st.integers(1, 3), st.integers(1, 20)), max_size=60)
)
def test_replay_filter_delivers_each_message_at_most_once(
    stream: list[tuple[str, int, int]],
) -> None:
    rf = ReplayFilter()
    delivered = [(s, e, q) for s, e, q in stream if rf.accept(_h(s, e, q))]
    assert len(delivered) == len(set(delivered))
    for sender in "abc":
        mine = [(e, q) for s, e, q in delivered if s == sender]
        assert mine == sorted(mine)  # per sender, strictly increasing (epoch, seq)


# ------------------------------------------------------------------ key layout


def test_keys_follow_the_design_layout() -> None:
    k = Keys("alpha")
    assert k.alive_uav("uav1") == "aw/alpha/alive/uav/uav1"
    assert k.alive_uav() == "aw/alpha/alive/uav/*"
    assert k.alive_cmdr == "aw/alpha/alive/cmdr"
    assert k.alive_all == "aw/alpha/alive/**"
    assert k.state("uav1") == "aw/alpha/uav/uav1/state"
    assert k.inbox("uav2", "uav1") == "aw/alpha/uav/uav2/inbox/uav1"
    assert k.inbox("uav2") == "aw/alpha/uav/uav2/inbox/*"
    assert k.report("uav1") == "aw/alpha/uav/uav1/report"
    assert k.experience("uav1") == "aw/alpha/uav/uav1/experience"
    assert k.context == "aw/alpha/cmdr/context"
    assert k.assign("uav1") == "aw/alpha/cmdr/assign/uav1"
    assert k.assign() == "aw/alpha/cmdr/assign/*"
    assert k.sim_perception("uav1") == "aw/alpha/sim/perception/uav1"
    assert k.sim_reward("uav1") == "aw/alpha/sim/reward/uav1"
    assert k.sim_command("uav1") == "aw/alpha/uav/uav1/sim/command"
    assert k.sim_command() == "aw/alpha/uav/*/sim/command"
    assert k.sim_episode == "aw/alpha/sim/episode"


def test_every_uav_key_sits_under_its_own_prefix() -> None:
    k = Keys("s")
    own = "aw/s/uav/uav1/"
    for key in (
        k.state("uav1"),
        k.report("uav1"),
        k.experience("uav1"),
        k.inbox("uav1", "x"),
        k.sim_command("uav1"),
    ):
        assert key.startswith(own)
        assert k.uav_of(key) == "uav1"
    assert last_chunk(k.inbox("uav2", "uav1")) == "uav1"
    assert k.uav_of(k.context) is None
    assert k.uav_of("aw/other/uav/uav1/state") is None
    assert k.uav_of("aw/s/uav/") is None
