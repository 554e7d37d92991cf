"""Fuzz every key type through the receive path: Codec, signature check, handlers.

``python -m aeroweaver_lab.bench.fuzz_wire --cases 100000 --seed 1`` generates hostile
payloads for every key a node receives on (beacons, inbox, reports, experience, context,
assignments, simulator perception/reward/command/episode, liveliness keys) from a seeded
generator (random bytes, mutated valid encodings, well-formed msgpack of the wrong shape,
type confusion, valid structs with adversarial values: NaN/inf, 2^63 epochs, huge rounds,
spoofed senders, long text), with random, stale or genuine signature attachments. Each one
goes through what a secured node does with it:

    Codec.decode -> Verifier.check -> PeerLink._on_beacon / _on_inbox / _on_alive
    (a peer message's body also through the retrieval summary and the prompt line),
    MissionState.update_context / update_assignment, ExperienceMemory.ingest,
    SimLink.on_perception / on_reward / on_episode (a daemon's link to the world),
    CommandCheck.admit + bound (the world's check of simulator commands)

Every case must end in exactly one bucket (rejected with a counted reason, accepted, or
ignored as older/duplicate data) and nothing may raise. Prints one JSON document; exits 1
if anything raised or a case went uncounted.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import math
import random
import tempfile
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import msgspec

from aeroweaver_edge.agent.memory.experience import ExperienceMemory
from aeroweaver_edge.agent.prompt import PromptLimits, format_message
from aeroweaver_edge.agent.state_text import message_summary
from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.contracts.wire import (
    Assignment,
    Codec,
    Entity,
    ExperienceRecord,
    Header,
    HeaderFactory,
    InboxMessage,
    Keys,
    MissionContext,
    MsgRef,
    ProgressReport,
    SimCommand,
    SimEpisode,
    SimPerception,
    SimReward,
    StateBeacon,
)
from aeroweaver_edge.daemon.mission_state import MissionState
from aeroweaver_edge.mesh.peers import PeerLimits, PeerLink
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.security.identity import SwarmPki, default_members
from aeroweaver_edge.security.pki import load_signing_key
from aeroweaver_edge.security.signing import Signer, Verifier
from aeroweaver_edge.sim.command_check import CommandCheck
from aeroweaver_edge.vehicle.sim import SimLink
from aeroweaver_edge.world.kinematics import KinematicWorld

SWARM = "fz"
K = Keys(SWARM)
ME = "uav0"
WHERE = (0, 1)  # the round the world is collecting commands for
NAMES = ["uav0", "uav1", "uav2", "cmdr", "world", "uav9", "", "x" * 300, "uav1\x00", "é"]
KINDS: dict[str, type[msgspec.Struct]] = {
    "state": StateBeacon,
    "inbox": InboxMessage,
    "report": ProgressReport,
    "experience": ExperienceRecord,
    "context": MissionContext,
    "assign": Assignment,
    "perception": SimPerception,
    "reward": SimReward,
    "command": SimCommand,
    "episode": SimEpisode,
}
EVIL_FLOATS = [math.nan, math.inf, -math.inf, 1e308, -1e308, 0.0, -0.0, 5e-324, 1e6]
EVIL_INTS = [0, -1, 1, 2**31, 2**62, 2**63 - 1, -(2**63), 10**6]


@dataclass
class Case:
    topic: str
    key: str
    data: bytes
    attachment: bytes | None
    how: str


class Fuzzer:
    """A seeded stream of hostile cases; the same seed gives the same cases."""

    def __init__(self, seed: int, signers: dict[str, Signer] | None = None) -> None:
        self.rng = random.Random(seed)
        self.codec = Codec()
        self.signers = signers or {}
        self._seq = 0

    def key_for(self, topic: str) -> str:
        r = self.rng
        who = r.choice(NAMES[:6])
        return {
            "state": K.state(who),
            "inbox": K.inbox(ME, who),
            "report": K.report(who),
            "experience": K.experience(who),
            "context": K.context,
            "assign": K.assign(r.choice([ME, "uav1"])),
            "perception": K.sim_perception(ME),
            "reward": K.sim_reward(ME),
            "command": K.sim_command(who),
            "episode": K.sim_episode,
            "alive": r.choice([K.alive_uav(who), K.alive_cmdr, f"{K.root}/alive/uav/{who}/x"]),
        }[topic]

    def header(self) -> Header:
        r = self.rng
        self._seq += 1
        sender = r.choice(NAMES)
        if r.random() < 0.5:
            return Header(sender=sender, epoch=r.choice([1, 2]), seq=self._seq, stamp=0.0)
        return Header(
            v=r.choice([1, 1, 2, -1]),
            sender=sender,
            epoch=r.choice(EVIL_INTS),
            seq=r.choice([*EVIL_INTS, self._seq]),
            stamp=r.choice(EVIL_FLOATS),
            ttl_s=r.choice(EVIL_FLOATS),
        )

    def vec(self) -> tuple[float, float, float]:
        r = self.rng
        if r.random() < 0.7:
            return (r.uniform(-80, 80), r.uniform(-80, 80), -5.0)
        return (r.choice(EVIL_FLOATS), r.choice(EVIL_FLOATS), r.choice(EVIL_FLOATS))

    def text(self) -> str:
        r = self.rng
        return r.choice(
            ["", "coverage", "searcher", "A" * r.choice([10, 5000]), "\u202e\x00é", "m"]
        )

    def struct(self, topic: str) -> msgspec.Struct:
        """A well-typed payload for ``topic`` with adversarial values."""
        r, h = self.rng, self.header()
        rnd, ep = r.choice([*EVIL_INTS, 1, 2, 3]), r.choice([0, 1, *EVIL_INTS])
        if topic == "state":
            return StateBeacon(
                h=h,
                uav=h.sender if r.random() < 0.7 else r.choice(NAMES),
                round=rnd,
                pos=self.vec(),
                vel=self.vec(),
                role=self.text(),
            )
        if topic == "inbox":
            values: list[str | int | float | bool] = [
                1, 2.5, True, "x" * r.choice([1, 3000]), *EVIL_FLOATS, *EVIL_INTS, 1.7e308
            ]  # fmt: skip  # (1.7e308: a distance from it overflows)
            keys = ["north", "east", "skill", "target_id"]  # the fields readers interpret
            body = {
                r.choice([*keys, self.text()[:50]]): r.choice(values)
                for _ in range(r.choice([0, 1, 3, 200]))
            }
            return InboxMessage(
                h=h,
                to=r.choice([ME, "uav1", ""]),
                round=rnd,
                kind=self.text(),
                body=body,
                sender_pos=self.vec(),
                ttl_rounds=r.choice(EVIL_INTS),
            )
        if topic == "report":
            return ProgressReport(
                h=h,
                uav=h.sender,
                mission_id="m",
                episode=ep,
                round=rnd,
                role="r",
                skill="s",
                invocation="s()",
                label="A",
                held=False,
                latency_s=r.choice(EVIL_FLOATS),
            )
        if topic == "experience":
            return ExperienceRecord(
                h=h,
                task=self.text(),
                role=self.text(),
                uav=h.sender,
                episode=ep,
                round=rnd,
                state_text=self.text(),
                skill="s",
                invocation="s()",
                reward=r.choice([None, *EVIL_FLOATS]),
                ret=r.choice([None, *EVIL_FLOATS]),
                final=r.random() < 0.5,
            )
        if topic == "context":
            return MissionContext(
                h=h,
                mission_id=r.choice(["m", "x"]),
                task="coverage",
                text=self.text(),
                constraints=[self.text()],
                participants=[ME],
                episode=ep,
                state=r.choice(["active", "ended"]),
            )
        if topic == "assign":
            return Assignment(
                h=h,
                mission_id=r.choice(["m", "x"]),
                uav=r.choice([ME, "uav1"]),
                role=self.text(),
                local_goal=self.text(),
                skills=[self.text() for _ in range(r.choice([0, 2, 500]))],
                revision=r.choice(EVIL_INTS),
            )
        if topic == "perception":
            ents = [
                Entity(id=self.text()[:8], kind="landmark", pos=self.vec())
                for _ in range(r.choice([0, 3, 300]))
            ]
            return SimPerception(
                h=h,
                uav=ME,
                episode=ep,
                round=rnd,
                deadline_s=r.choice(EVIL_FLOATS),
                pos=self.vec(),
                vel=self.vec(),
                entities=ents,
                expected_inbox=[MsgRef(sender="uav1", seq=rnd)],
            )
        if topic == "reward":
            return SimReward(h=h, uav=ME, episode=ep, round=rnd, reward=r.choice(EVIL_FLOATS))
        if topic == "command":
            return SimCommand(h=h, uav=h.sender, episode=ep, round=rnd, vel=self.vec())
        phases: list[Literal["start", "end", "shutdown"]] = ["start", "end", "shutdown"]
        return SimEpisode(h=h, episode=ep, task=self.text(), phase=r.choice(phases))

    def junk(self, depth: int = 0) -> Any:
        """Random msgpack-able data: the right container, the wrong contents."""
        r = self.rng
        pick = r.randrange(9 if depth < 3 else 6)
        if pick == 0:
            return r.choice([*EVIL_INTS, 2**64 - 1])
        if pick == 1:
            return r.choice(EVIL_FLOATS)
        if pick == 2:
            return self.text()
        if pick == 3:
            return r.randbytes(r.choice([0, 8, 64]))
        if pick == 4:
            return None
        if pick == 5:
            return r.random() < 0.5
        if pick == 6:
            return [self.junk(depth + 1) for _ in range(r.choice([0, 1, 3, 50]))]
        return self.junk_map(depth)

    def junk_map(self, depth: int = 0) -> dict[str, Any]:
        r = self.rng
        names = ["h", "type", "uav", "to", "round", "pos", "vel", "body", "sender", "epoch", "seq"]
        return {r.choice(names): self.junk(depth + 1) for _ in range(r.choice([1, 3, 8]))}

    def case(self) -> Case:
        r = self.rng
        topic = r.choice([*KINDS, "alive"])
        key = self.key_for(topic)
        if topic == "alive":
            return Case(topic, key, b"", None, "liveliness")
        how = r.choice(["bytes", "mutated", "junk", "confused", "evil", "evil", "genuine"])
        sender = ""
        if how == "bytes":
            data = r.randbytes(r.choice([0, 1, 7, 64, 512, 70_000]))
        elif how == "junk":
            tag = r.choice([*(k.__struct_config__.tag for k in KINDS.values()), "nope"])
            data = msgspec.msgpack.encode(
                {"type": tag, **self.junk_map()} if r.random() < 0.7 else self.junk()
            )
        elif how == "confused":
            data = self._encode(self.struct(r.choice(list(KINDS))))
        else:
            msg = self.struct(topic)
            sender = msg.h.sender  # type: ignore[attr-defined]
            data = self._encode(msg)
            if how == "mutated" and data:
                buf = bytearray(data)
                for _ in range(r.choice([1, 2, 8])):
                    op = r.randrange(3)
                    i = r.randrange(len(buf))
                    if op == 0:
                        buf[i] = r.randrange(256)
                    elif op == 1:
                        del buf[i:]
                    else:
                        buf[i:i] = r.randbytes(r.choice([1, 4]))
                    if not buf:
                        break
                data = bytes(buf)
        return Case(topic, key, data, self.attachment(key, data, sender), how)

    def _encode(self, msg: msgspec.Struct) -> bytes:
        try:
            return self.codec.encode(msg)
        except ValueError:  # over the cap: send it anyway, as an attacker would
            return msgspec.msgpack.encode(msg)

    def attachment(self, key: str, data: bytes, sender: str) -> bytes | None:
        """None, garbage, a signature for another topic, one by some other identity, or
        (half the time, when we hold the claimed sender's key) a genuine one, so that the
        handlers behind the signature check get their share of hostile payloads."""
        r = self.rng
        if not self.signers:
            return None
        if sender in self.signers and r.random() < 0.5:
            return self.signers[sender].sign(key, data)
        pick = r.randrange(4)
        if pick == 0:
            return None
        if pick == 1:
            return r.randbytes(r.choice([1, 73, 200]))
        name = r.choice(list(self.signers))
        if pick == 2:
            return self.signers[name].sign(key + "/x", data)  # another topic
        return self.signers[name].sign(key, data)


@dataclass
class Harness:
    """One receiving node's handlers, fed directly (the mesh delivered these bytes)."""

    link: PeerLink
    mission: MissionState
    memory: ExperienceMemory
    verifier: Verifier | None
    sim: SimLink
    check: CommandCheck
    world: KinematicWorld
    codec: Codec = field(default_factory=Codec)
    outcomes: Counter[str] = field(default_factory=Counter)
    errors: list[str] = field(default_factory=list)

    def run(self, case: Case) -> None:
        try:
            self.outcomes[self._run(case)] += 1
        except Exception as exc:  # the property under test: this never happens
            self.errors.append(f"{case.topic}/{case.how}: {type(exc).__name__}: {exc}"[:300])

    def _run(self, case: Case) -> str:
        if case.topic == "alive":
            before, roster = self.link.stats.rejected.total(), self.link.roster
            self.link._on_alive((case.key, len(case.key) % 2 == 0))  # a PUT/DELETE mix
            if self.link.stats.rejected.total() > before:
                return "rejected"
            return "accepted" if self.link.roster != roster else "ignored"
        kind = KINDS[case.topic]
        msg = self.codec.decode(case.data, kind, case.key)
        if msg is None:
            return "rejected"
        sender = getattr(getattr(msg, "h", None), "sender", "")
        if self.verifier is not None:
            reason = self.verifier.check(case.key, case.data, case.attachment, sender)
            if reason is not None:
                self.codec.stats.reject(reason, case.key)
                return "rejected"
        return self._handle(case, msg)

    def _handle(self, case: Case, msg: msgspec.Struct) -> str:
        link, mission = self.link, self.mission
        authenticated = self.verifier is not None
        if isinstance(msg, InboxMessage):
            # What a round later does with an accepted body: the retrieval text and the
            # prompt line. A peer can meet the routing rules, so both must take any body.
            message_summary(msg, (12.0, -7.0))
            format_message(msg, PromptLimits(), (12.0, -7.0))
            before = link.stats.rejected.total()
            link._on_inbox((case.key, msg))
            if link.inbox.pending >= link.limits.max_pending // 2:
                link.inbox.drop_pending()  # a round collected them
            return "rejected" if link.stats.rejected.total() > before else "accepted"
        if isinstance(msg, StateBeacon):
            before = link.stats.rejected.total()
            taken = link._on_beacon((case.key, msg))
            return (
                "accepted"
                if taken
                else ("rejected" if link.stats.rejected.total() > before else "ignored")
            )
        if isinstance(msg, (MissionContext, Assignment)):
            before, changes = mission.rejected.total(), mission.changes
            if isinstance(msg, MissionContext):
                mission.update_context(msg, authenticated=authenticated)
            else:
                mission.update_assignment(msg, authenticated=authenticated)
            if mission.rejected.total() > before:
                return "rejected"
            return "accepted" if mission.changes != changes else "ignored"
        if isinstance(msg, ExperienceRecord):
            # The daemon's own check (daemon._pump_experience), then the memory's.
            if not msg.uav == msg.h.sender == case.key.split("/")[-2]:
                return "rejected"
            return "accepted" if self.memory.ingest(msg) else "ignored"
        if isinstance(msg, SimCommand):  # the world's side
            cmd = self.check.admit(case.key, msg, WHERE, ())
            if cmd is None:
                return "rejected"
            self.check.bound(self.world, cmd.uav, cmd.vel)
            return "accepted"
        why: str | None = None
        if isinstance(msg, SimPerception):
            why = self.sim.on_perception(msg)
            self.sim._next = None  # the daemon took it
        elif isinstance(msg, SimReward):
            why = self.sim.on_reward(msg)
            self.sim.drain()
        elif isinstance(msg, SimEpisode):
            why = self.sim.on_episode(msg)
        else:
            return "accepted"  # a progress report: the Commander's board counts foreign ones
        if why is not None:
            self.sim.rejected[why] += 1
            return "rejected"
        return "accepted"


async def _make_link(pki: SwarmPki | None) -> tuple[Mesh, PeerLink]:
    security = pki.security_for(ME) if pki is not None else None
    cfg = MeshConfig(listen=["tls/127.0.0.1:0" if pki else "tcp/127.0.0.1:0"], security=security)
    mesh = await Mesh.open(cfg, node_id=ME)
    limits = PeerLimits(known_peers={"uav0", "uav1", "uav2"}, max_speed_mps=11.0, max_abs_m=500.0)
    link = PeerLink(mesh, K, ME, HeaderFactory(ME), 55.0, limits=limits)
    for peer in ("uav1", "uav2"):
        link._on_alive((K.alive_uav(peer), True))
    link.publish_beacon(1, (0.0, 0.0, -5.0), (0.0, 0.0, 0.0))
    return mesh, link


def run(cases: int, seed: int, secured: bool = True) -> dict[str, Any]:
    return asyncio.run(_run(cases, seed, secured))


async def _run(cases: int, seed: int, secured: bool) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as d:
        pki = SwarmPki.create(Path(d), SWARM, default_members(3)) if secured else None
        signers = {}
        if pki is not None:
            for name in ("uav0", "uav1", "uav2", "cmdr", "world"):
                signers[name] = Signer(name, load_signing_key(pki.paths(name).sign_key))
        mesh, link = await _make_link(pki)
        try:
            verifier = Verifier(pki.identities) if pki is not None else None
            mission = MissionState(ME, track_commander=True)
            mission.commander_alive(True)
            memory = ExperienceMemory(None)
            world = KinematicWorld()
            for i, uav in enumerate(("uav0", "uav1", "uav2")):
                world.add_uav(uav, (10.0 * i, 0.0))
            sim = SimLink(mesh, K, ME, HeaderFactory(ME))
            check = CommandCheck(K, ("uav0", "uav1", "uav2"))
            harness = Harness(link, mission, memory, verifier, sim, check, world)
            fuzzer = Fuzzer(seed, signers)
            by_topic: Counter[str] = Counter()
            t0 = time.perf_counter()
            for _ in range(cases):
                case = fuzzer.case()
                by_topic[case.topic] += 1
                harness.run(case)
            elapsed = time.perf_counter() - t0
            memory.close()
        finally:
            await mesh.aclose()
    reasons = Counter(harness.codec.stats.rejected)
    reasons.update(link.stats.rejected)
    reasons.update({f"mission:{k}": v for k, v in mission.rejected.items()})
    reasons.update({f"sim:{k}": v for k, v in harness.sim.rejected.items()})
    reasons.update({f"world:{k}": v for k, v in harness.check.refused.items()})
    return {
        "cases": cases,
        "seed": seed,
        "secured": secured,
        "counted": sum(harness.outcomes.values()),
        "outcomes": dict(harness.outcomes),
        "by_topic": dict(sorted(by_topic.items())),
        "errors": len(harness.errors),
        "first_errors": harness.errors[:5],
        "rejected_by_reason": dict(reasons.most_common()),
        "pending_after": link.inbox.pending,
        "cases_per_s": round(cases / elapsed),
    }


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m aeroweaver_lab.bench.fuzz_wire",
                                description=__doc__.split("\n\n")[0])  # fmt: skip
    p.add_argument("--cases", type=int, default=100_000)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--insecure", action="store_true", help="no signature layer (plain swarm)")
    args = p.parse_args(argv)
    logging.getLogger("aeroweaver_edge").setLevel(logging.ERROR)  # rejections are counted
    out = run(args.cases, args.seed, secured=not args.insecure)
    print(json.dumps(out, indent=1))
    return 0 if out["errors"] == 0 and out["counted"] == out["cases"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
