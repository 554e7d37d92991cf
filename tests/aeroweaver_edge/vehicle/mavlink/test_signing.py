"""MAVLink 2 signing: key files, the persisted timestamp, and a vehicle that requires
signing refusing unsigned, wrongly signed and replayed frames (real UDP bytes)."""

from __future__ import annotations

import asyncio
import os
import socket
from pathlib import Path

import pytest

from aeroweaver_edge.sim.emulator.host import EmulatorHost, EmulatorOptions
from aeroweaver_edge.vehicle.errors import VehicleError
from aeroweaver_edge.vehicle.mavlink.codec import Codec, mavlink
from aeroweaver_edge.vehicle.mavlink.signing import (
    SigningError,
    TimestampStore,
    load_key,
    now_timestamp,
    timestamp_path,
    write_key,
)
from tests.helpers.mav import emulated, until

KEY = bytes(range(32))
ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM


def test_key_file_must_be_private(tmp_path: Path) -> None:
    path = tmp_path / "uav0.key"
    assert write_key(path, KEY) == KEY
    assert oct(path.stat().st_mode & 0o777) == "0o600"
    assert load_key(path) == KEY
    path.chmod(0o640)
    with pytest.raises(SigningError, match=r"accessible by group/others \(mode 640\); chmod 600"):
        load_key(path)
    path.chmod(0o600)
    path.write_text("abcd\n")
    with pytest.raises(SigningError, match="32 raw bytes or 64 hex characters"):
        load_key(path)
    with pytest.raises(SigningError, match="cannot read signing key"):
        load_key(tmp_path / "missing.key")


def test_timestamp_never_goes_backwards_even_with_a_clock_behind(tmp_path: Path) -> None:
    store = TimestampStore(tmp_path / "k.timestamp")
    now = now_timestamp()
    assert store.load() >= now
    ahead = now + 86_400 * 100_000  # the last run's clock was a day ahead of ours
    store.save(ahead)
    assert TimestampStore(store.path).load() == ahead + 1
    store.save(ahead - 5)  # never written backwards
    assert int(store.path.read_text()) == ahead
    assert not list(tmp_path.glob("*.tmp"))  # atomic: temp file renamed away
    assert oct(store.path.stat().st_mode & 0o777) == "0o600"


def test_a_keyed_codec_refuses_unsigned_wrong_key_and_replayed_frames() -> None:
    sender, receiver = Codec(255, 190), Codec(1, 1)
    sender.enable_signing(KEY, now_timestamp())
    receiver.enable_signing(KEY, now_timestamp())
    frame = sender.encode(sender.mav.heartbeat_encode(6, 8, 0, 0, 0))
    assert [m.get_type() for m in receiver.decode(frame)] == ["HEARTBEAT"]
    assert receiver.decode(frame) == []  # replay
    unsigned = Codec(255, 190).encode(sender.mav.heartbeat_encode(6, 8, 0, 0, 0))
    assert receiver.decode(unsigned) == []
    wrong = Codec(255, 190)
    wrong.enable_signing(bytes(32), now_timestamp())
    assert receiver.decode(wrong.encode(wrong.mav.heartbeat_encode(6, 8, 0, 0, 0))) == []
    assert receiver.stats.bad["signature"] == 3
    # A forged frame cannot push the replay window forward (signature checked first).
    forger = Codec(255, 190)
    forger.enable_signing(bytes(32), now_timestamp() + 10**9)
    assert receiver.decode(forger.encode(forger.mav.heartbeat_encode(6, 8, 0, 0, 0))) == []
    fresh = sender.encode(sender.mav.heartbeat_encode(6, 8, 0, 0, 0))
    assert [m.get_type() for m in receiver.decode(fresh)] == ["HEARTBEAT"]


async def test_a_signed_link_flies_and_persists_its_timestamp(tmp_path: Path) -> None:
    key_path = tmp_path / "uav0.key"
    write_key(key_path, KEY)
    async with emulated(1, signing_keys=[KEY], vehicle={"signing_key": str(key_path)}) as (
        host,
        [v],
    ):
        await v.arm()
        assert host.vehicles[0].armed
        assert host.vehicles[0].codec.stats.bad["signature"] == 0
        last = v.link.codec.signing_timestamp
    assert int(timestamp_path(key_path).read_text()) >= last


async def test_an_unsigned_daemon_gets_nothing_done_on_a_signing_vehicle() -> None:
    async with emulated(1, signing_keys=[KEY], vehicle={"command_retries": 1}) as (host, [v]):
        ap = host.vehicles[0]
        assert v.refused is not None
        assert "could not be read" in v.refused
        with pytest.raises(VehicleError, match="refusing to arm"):
            await v.arm()
        assert ap.codec.stats.bad["signature"] > 0
        assert ap.log == []
        assert ap.rx["PARAM_REQUEST_READ"] == 0
        assert not ap.armed


async def test_a_wrong_key_is_named_in_the_connect_error(tmp_path: Path) -> None:
    key_path = tmp_path / "wrong.key"
    write_key(key_path, bytes(32))
    with pytest.raises(VehicleError, match=r"failed the signature check: wrong key\?"):
        async with emulated(
            1, signing_keys=[KEY], vehicle={"signing_key": str(key_path), "connect_timeout_s": 1.5}
        ):
            pass


async def test_a_replayed_signed_command_is_refused_by_the_vehicle() -> None:
    opts = EmulatorOptions(uavs=1, local_base=0, remote_ports=[9], signing_keys=[KEY])
    async with EmulatorHost(opts) as host:
        ap = host.vehicles[0]
        gcs = Codec(255, 190)
        gcs.enable_signing(KEY, now_timestamp())
        arm = gcs.encode(gcs.mav.command_long_encode(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0))
        disarm = gcs.encode(gcs.mav.command_long_encode(1, 1, ARM, 0, 0, 0, 0, 0, 0, 0, 0))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            to = ("127.0.0.1", host.local_port(0))
            sock.sendto(arm, to)
            await until(lambda: ap.armed, 2, "signed arm")
            sock.sendto(disarm, to)
            await until(lambda: not ap.armed, 2, "signed disarm")
            bad = ap.codec.stats.bad["signature"]
            sock.sendto(arm, to)  # the captured arm frame, replayed
            await until(lambda: ap.codec.stats.bad["signature"] == bad + 1, 2, "replay refused")
            assert not ap.armed
            assert [r.params[0] for r in ap.log] == [1.0, 0.0]
        await asyncio.sleep(0)


def test_write_key_generates_random_keys(tmp_path: Path) -> None:
    a, b = write_key(tmp_path / "a.key"), write_key(tmp_path / "b.key")
    assert a != b
    assert len(a) == 32
    assert os.stat(tmp_path / "a.key").st_mode & 0o077 == 0
