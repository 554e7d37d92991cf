"""Ed25519 payload signatures: what is accepted, and every way a forgery is refused."""

from __future__ import annotations

import msgspec
import pytest

from aeroweaver_edge.contracts.wire import (
    Assignment,
    Codec,
    ExperienceRecord,
    HeaderFactory,
    InboxMessage,
    Keys,
)
from aeroweaver_edge.security.identity import SwarmPki
from aeroweaver_edge.security.pki import load_signing_key, make_signing_key
from aeroweaver_edge.security.signing import ATTACHMENT_BYTES, Signer, Verifier

K = Keys("s")


def signer(pki: SwarmPki, name: str) -> Signer:
    return Signer(name, load_signing_key(pki.paths(name).sign_key))


def inbox_msg(sender: str = "uav0", to: str = "uav1") -> bytes:
    return Codec().encode(InboxMessage(h=HeaderFactory(sender).next(), to=to, round=1, kind="s"))


def test_genuine_payloads_of_each_author_verify(swarm_pki: SwarmPki) -> None:
    v = Verifier(swarm_pki.identities)
    data = inbox_msg()
    key = K.inbox("uav1", "uav0")
    att = signer(swarm_pki, "uav0").sign(key, data)
    assert len(att) == ATTACHMENT_BYTES
    assert v.check(key, data, att, "uav0") is None
    ctx_key = K.assign("uav0")
    a = Codec().encode(
        Assignment(h=HeaderFactory("cmdr").next(), mission_id="m", uav="uav0", role="r",
                   local_goal="g", skills=[])
    )  # fmt: skip
    assert v.check(ctx_key, a, signer(swarm_pki, "cmdr").sign(ctx_key, a), "cmdr") is None
    exp_key = K.experience("uav2")
    rec = Codec().encode(
        ExperienceRecord(h=HeaderFactory("uav2").next(), task="t", role="r", uav="uav2",
                         episode=0, round=0, state_text="", skill="s", invocation="s()")
    )  # fmt: skip
    assert v.check(exp_key, rec, signer(swarm_pki, "uav2").sign(exp_key, rec), "uav2") is None


def test_every_forgery_is_refused_with_its_reason(swarm_pki: SwarmPki) -> None:
    v = Verifier(swarm_pki.identities)
    data = inbox_msg()
    key = K.inbox("uav1", "uav0")
    good = signer(swarm_pki, "uav0").sign(key, data)
    flipped = bytearray(data)
    flipped[-1] ^= 0x01
    stranger = Signer("uav0", make_signing_key())  # claims uav0 with its own key
    cases = {
        "unsigned": (key, data, None, "uav0"),
        "empty attachment": (key, data, b"", "uav0"),
        "tampered payload": (key, bytes(flipped), good, "uav0"),
        "tampered signature": (key, data, good[:-1] + bytes([good[-1] ^ 1]), "uav0"),
        "wrong key": (key, data, stranger.sign(key, data), "uav0"),
        "wrong key, right key id": (key, data, good[:9] + stranger.sign(key, data)[9:], "uav0"),
        "another identity's key": (key, data, signer(swarm_pki, "uav2").sign(key, data), "uav0"),
        "unknown sender": (key, data, good, "uav9"),
        "wrong topic": (K.inbox("uav2", "uav0"), data, good, "uav0"),
        "truncated attachment": (key, data, good[:40], "uav0"),
        "unknown version": (key, data, b"\x02" + good[1:], "uav0"),
    }
    reasons = {name: v.check(*args) for name, args in cases.items()}
    assert reasons == {
        "unsigned": "unsigned",
        "empty attachment": "unsigned",
        "tampered payload": "bad_signature",
        "tampered signature": "bad_signature",
        "wrong key": "wrong_key",
        "wrong key, right key id": "bad_signature",
        "another identity's key": "wrong_key",
        "unknown sender": "unknown_signer",
        "wrong topic": "bad_signature",
        "truncated attachment": "bad_attachment",
        "unknown version": "bad_attachment",
    }


@pytest.mark.parametrize(
    ("author", "key"),
    [
        ("uav0", K.state("uav1")),  # another UAV's key
        ("uav0", K.inbox("uav1", "uav2")),  # another sender's inbox slot
        ("uav0", K.context),  # a Commander key
        ("uav0", K.sim_reward("uav0")),  # a simulator key
        ("cmdr", K.sim_episode),
        ("world", K.assign("uav0")),
        ("world", K.sim_command("uav0")),  # only uav0 commands its own body
        ("router", K.inbox("uav1", "uav0")),  # a relay authors nothing
        ("observer", K.state("uav0")),
    ],
)
def test_valid_signature_on_a_key_the_author_may_not_write(
    swarm_pki: SwarmPki, author: str, key: str
) -> None:
    """A genuine key cannot sign for keys outside its role: the ACL's table, end to end."""
    v = Verifier(swarm_pki.identities)
    data = msgspec.msgpack.encode({"h": {"sender": author}})
    att = signer(swarm_pki, author).sign(key, data)
    assert v.check(key, data, att, author) == "unauthorised_signer"


def test_wildcard_key_is_authorised_only_inside_the_authors_keys(swarm_pki: SwarmPki) -> None:
    v = Verifier(swarm_pki.identities)
    data = b"x"
    s = signer(swarm_pki, "uav0")
    mine = K.inbox("*", "uav0")  # every inbox, uav0's slot: allowed
    assert v.check(mine, data, s.sign(mine, data), "uav0") is None
    theirs = "aw/s/uav/**"
    assert v.check(theirs, data, s.sign(theirs, data), "uav0") == "unauthorised_signer"
    bad = "aw/s//x"
    assert v.check(bad, data, s.sign(bad, data), "uav0") == "unauthorised_signer"
