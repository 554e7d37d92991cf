"""What ``aeroweaver keys init`` writes: complete, commented daemon configs that load back to
what was meant, distinct loopback ports for a one-machine rehearsal, the vehicle link asked
for, the ground tools' files, and nothing at all when it fails half-way."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from types import UnionType
from typing import Any, Union, get_args, get_origin

import pytest
from pydantic import BaseModel

from aeroweaver_edge.cli.main import main
from aeroweaver_edge.config import MeshConfig, UavConfig, load_config, parse_config
from aeroweaver_edge.provision import daemon_toml
from aeroweaver_edge.provision.keys_dir import SWARM_FILE, SwarmDir
from aeroweaver_edge.security import identity
from aeroweaver_edge.security.pki import load_cert


def init(out: Path, *extra: str, uavs: int = 3) -> int:
    argv = ["keys", "init", "--swarm", "s", "--uavs", str(uavs), "--out", str(out), *extra]
    return main(argv)


def keys_in(model: type[BaseModel], prefix: str = "") -> set[str]:
    """Every settable key of a config model, dotted (``vehicle.url``), sub-models expanded."""
    out: set[str] = set()
    for name, field in model.model_fields.items():
        key = f"{prefix}{name}"
        options = (field.annotation,)
        if get_origin(field.annotation) in (Union, UnionType):  # X | None
            options = get_args(field.annotation)
        sub = [a for a in options if isinstance(a, type) and issubclass(a, BaseModel)]
        if sub:
            out |= keys_in(sub[0], key + ".")
        else:
            out.add(key)
    return out


def keys_written(text: str) -> set[str]:
    """Keys set or shown commented out (``# key = ...``) in a rendered file, dotted."""
    out: set[str] = set()
    section = ""
    for line in text.splitlines():
        if m := re.fullmatch(r"\[([a-z_.]+)\]", line):
            section = m.group(1) + "."
        elif m := re.match(r"(?:# )?([a-z_]+) = ", line):
            out.add(section + m.group(1))
    return out


def test_loopback_emulator_configs_are_complete_and_distinct(tmp_path: Path) -> None:
    out = tmp_path / "D"
    assert init(out, "--loopback", "--vehicle", "emulator", "--port", "17447",
                "--vehicle-port", "24540") == 0  # fmt: skip
    listens: dict[str, list[str]] = {}
    for i in range(3):
        path = out / f"uav{i}" / "uav.toml"
        text = path.read_text()
        cfg = load_config(path, UavConfig)
        # every key config.py defines is in the file, set or shown commented out
        assert keys_in(UavConfig) - keys_written(text) == set()
        # every key has its own comment (none falls back to the "see config.py" pointer)
        assert "see aeroweaver_edge/config.py" not in text
        assert set(daemon_toml.COMMENTS) >= keys_in(UavConfig)
        # the header's "Edit [...]" names sections that are there
        edit = re.search(r"Edit (.*?) for your vehicle", text.replace("\n# ", " "))
        assert edit is not None
        named = re.findall(r"\[([a-z.]+)\]", edit.group(1))
        assert set(named) == set(daemon_toml.HEADER_SECTIONS)
        assert all(f"\n[{s}]\n" in text for s in named)
        # what it says
        assert cfg.vehicle.backend == "mavlink"
        assert cfg.vehicle.url == f"udpin://127.0.0.1:{24540 + i}"  # emulator vehicle i
        assert cfg.agent.selector == "scripted"
        assert 'selector "scripted": the task\'s reference policy' in text
        assert [p.id for p in cfg.field.points] == ["L0", "L1", "L2"]
        assert cfg.mesh.connect == ["tls/127.0.0.1:17447"]
        assert cfg.agent.memory_path == str(out.resolve() / "state" / f"uav{i}.sqlite3")
        listens[f"uav{i}"] = cfg.mesh.listen
        # the file loads back to exactly the settings it was rendered from
        again = parse_config(tomllib.loads(text), UavConfig, str(path))
        assert again == cfg
    assert listens == {f"uav{i}": [f"tls/127.0.0.1:{17448 + i}"] for i in range(3)}
    text = (out / "router" / "zenoh.json5").read_text()
    assert '"tls/127.0.0.1:17447"' in text
    for ground in ("cmdr", "world", "operator", "observer", "central"):
        data = tomllib.loads((out / ground / "mesh.toml").read_text())
        mesh = parse_config(data["mesh"], MeshConfig, ground)
        assert data["swarm"] == "s"
        assert mesh.listen == ["tls/127.0.0.1:0"]  # its own port, picked by the OS
        assert mesh.connect == ["tls/127.0.0.1:17447"]
        assert mesh.security is not None
        assert mesh.security.identity == ground
    keys = SwarmDir.open(out)
    assert (keys.swarm, keys.connect) == ("s", ("tls/127.0.0.1:17447",))
    assert not list(tmp_path.glob(".D.*"))  # the temporary build directory is gone


def test_vehicle_sim_says_it_waits_for_a_simulated_world(tmp_path: Path) -> None:
    out = tmp_path / "D"
    assert init(out, "--loopback", "--port", "17447", uavs=1) == 0
    text = (out / "uav0" / "uav.toml").read_text()
    cfg = load_config(out / "uav0" / "uav.toml", UavConfig)
    assert cfg.vehicle.backend == "sim"
    assert cfg.agent.selector == "llm"
    prose = text.replace("\n# ", " ")
    assert "WAITS for one" in prose
    assert f"--keys {out} --sim-world" in prose


@pytest.mark.parametrize("vehicle", ["mavlink", "mavsdk"])
def test_field_configs_one_listen_per_machine(tmp_path: Path, vehicle: str) -> None:
    out = tmp_path / "D"
    assert init(out, "--vehicle", vehicle, "--listen", "tls/0.0.0.0:7447",
                "--connect", "tls/10.0.0.1:7447", "--install-dir", "/etc/aeroweaver/keys",
                "--state-dir", "/var/lib/aeroweaver", "--host", "router=10.0.0.1",
                "--host", "uav1=uav1.lan") == 0  # fmt: skip
    for i in range(3):
        data = tomllib.loads((out / f"uav{i}" / "uav.toml").read_text())
        # paths are as installed on the vehicle, so load as data, not from this machine
        assert data["vehicle"] == {**data["vehicle"], "backend": vehicle,
                                   "url": "udpin://0.0.0.0:14540"}  # fmt: skip
        assert data["mesh"]["listen"] == ["tls/0.0.0.0:7447"]  # each UAV has its own machine
        assert data["mesh"]["connect"] == ["tls/10.0.0.1:7447"]
        assert data["mesh"]["security"]["ca"] == "/etc/aeroweaver/keys/ca.crt"
        assert data["agent"]["memory_path"] == f"/var/lib/aeroweaver/uav{i}.sqlite3"
    for ground in ("cmdr", "world", "operator", "observer", "central"):
        data = tomllib.loads((out / ground / "mesh.toml").read_text())
        # ground tools share the ground station: never the UAVs' port
        assert data["mesh"]["listen"] == ["tls/127.0.0.1:0"]
    assert '"tls/0.0.0.0:7447"' in (out / "router" / "zenoh.json5").read_text()
    desc = tomllib.loads((out / SWARM_FILE).read_text())
    assert desc == {"swarm": "s", "connect": ["tls/10.0.0.1:7447"]}
    pki = identity.SwarmPki.load(out)
    san = str(load_cert(pki.paths("uav1").tls_cert).extensions)
    assert "uav1.lan" in san


def test_a_failure_half_way_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    real = identity._issue_member
    calls: list[str] = []

    def failing(*args: Any) -> Any:
        calls.append(args[2])
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        return real(*args)

    monkeypatch.setattr(identity, "_issue_member", failing)
    out = tmp_path / "new" / "deeper" / "D"
    assert init(out, "--loopback") == 2
    err = capsys.readouterr().err
    assert err.startswith("aeroweaver: keys init: cannot write ")
    assert err.endswith(": No space left on device\n")
    assert len(calls) == 3  # the CA and two identities were already written, then removed
    assert list(tmp_path.iterdir()) == []  # not even the parents it made


def test_out_may_be_an_existing_empty_directory(tmp_path: Path) -> None:
    out = tmp_path / "D"
    out.mkdir()
    assert init(out, "--loopback", uavs=1) == 0
    assert (out / "uav0" / "uav.toml").is_file()
    assert (out / "ca" / "ca.key").stat().st_mode & 0o077 == 0


def test_loopback_sitl_configs_share_one_frame_and_say_how_to_start_each_instance(
    tmp_path: Path,
) -> None:
    from aeroweaver_edge.provision import sitl
    from aeroweaver_edge.vehicle.mavlink.geo import DEFAULT_ORIGIN

    out = tmp_path / "D"
    assert init(out, "--loopback", "--vehicle", "sitl", "--vehicle-port", "24540") == 0
    parm = out / sitl.PARAMS_FILE
    assert parm.read_text() == sitl.params_text()
    assert "FS_THR_ENABLE 0\n" in parm.read_text()
    assert (DEFAULT_ORIGIN.lat_deg, DEFAULT_ORIGIN.lon_deg, DEFAULT_ORIGIN.alt_m) == sitl.ORIGIN
    for i in range(3):
        path = out / f"uav{i}" / "uav.toml"
        cfg = load_config(path, UavConfig)
        assert cfg.vehicle.backend == "mavlink"
        assert cfg.vehicle.personality == "ardupilot"
        assert cfg.vehicle.url == f"udpin://127.0.0.1:{24540 + i}"
        assert cfg.vehicle.origin == sitl.ORIGIN  # one frame for every instance
        assert cfg.agent.selector == "scripted"
        assert [p.id for p in cfg.field.points] == ["L0", "L1", "L2"]
        flat = path.read_text().replace("\n# ", " ")
        assert f"--sysid {i + 1} -I {i} --serial0 udpclient:127.0.0.1:{24540 + i}" in flat
        assert f"--defaults {parm.resolve()}" in flat
    lat, lon, _ = sitl.home(1)
    n, e, _ = DEFAULT_ORIGIN.to_local(lat, lon, DEFAULT_ORIGIN.alt_m)
    assert (round(n, 3), round(e, 3)) == (0.0, sitl.SPACING_M)


def test_sitl_without_loopback_is_refused_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert init(tmp_path / "D", "--vehicle", "sitl") == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "--vehicle sitl: the rehearsal runs every vehicle on this machine" in err
    assert not (tmp_path / "D").exists()
