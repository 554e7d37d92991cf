"""``aeroweaver daemon`` as a service on the other backends, with real processes:

- a secured swarm (``keys init``, TLS + ACL + signatures through the router): two
  ``mission start --keys --sim-world`` in a row fly on the same daemons; the world's boot
  counter is a new epoch each time, which the daemons take as a new world;
- the field path: ``aeroweaver emulator`` (MAVLink over UDP), daemons on the mavlink
  backend, two field missions in a row (launch, fly, land, launch again), a line per round
  on the operator's terminal; SIGTERM afterwards exits 0.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from aeroweaver_edge.cli.main import main
from tests.helpers.mav import free_udp_ports
from tests.helpers.swarm_procs import (
    UAVS,
    Procs,
    daemon_config,
    mission,
    router_config,
    wait_for_uavs,
    wait_until,
)
from tests.helpers.zenoh_net import free_port, unique_namespace

pytestmark = pytest.mark.slow


def test_secured_daemons_fly_two_missions_in_a_row(tmp_path: Path) -> None:
    swarm, keys = "sec", tmp_path / "keys"
    port = free_port()  # the router's; uavN listens on port + 1 + N (keys init --loopback)
    router = f"tls/127.0.0.1:{port}"
    assert main(["keys", "init", "--swarm", swarm, "--uavs", "3", "--out", str(keys),
                 "--loopback", "--port", str(port), "--vehicle", "sim",
                 "--selector", "scripted", "--mode", "client"]) == 0  # fmt: skip
    for uav in UAVS:  # scripted and uncorrected, so no LLM is needed and picks are fixed
        toml = keys / uav / "uav.toml"
        toml.write_text(re.sub(r"(?m)^beta = .*$", "beta = 0.0", toml.read_text()))
    procs = Procs(tmp_path)
    try:
        procs.start("router", "router", "--config", str(keys / "router" / "zenoh.json5"))
        for uav in UAVS:
            procs.start(uav, "daemon", "--config", str(keys / uav / "uav.toml"))
        # (the observer's check would need the swarm's keys: wait for the daemons' own word)
        assert wait_until(lambda: all("waiting for a mission" in procs.log(u)
                                      for u in UAVS), 60)  # fmt: skip
        records = []
        for n in (1, 2):
            path = tmp_path / f"m{n}.json"
            code, out, err, _ = mission("--swarm", swarm, "--keys", str(keys), "--connect",
                                        router, "--sim-world", "--roster-wait", "2",
                                        "--rounds", "4", "--json", str(path))  # fmt: skip
            assert code == 0, (out, err, procs.log("uav0")[-1500:])
            records.append(json.loads(path.read_text()))
        for rec in records:
            assert len(rec["episodes"]) == 1
            assert rec["security"]["tls"] is True
            assert rec["security"]["signed"] is True
            assert rec["security"]["rejected_total"] == 0  # the second world is no replay
            assert rec["lost_uavs"] == {}
        assert records[0]["mission"]["mission_id"] != records[1]["mission"]["mission_id"]
        for uav in UAVS:
            assert procs.term(uav)[0] == 0
    finally:
        procs.stop_all()
    assert (keys / "state" / "world.boot").read_text() == "2\n"  # two worlds, two epochs
    assert len(re.findall(r"uav0: mission \S+ ended", procs.log("uav0"))) == 2


@pytest.mark.parametrize(
    ("backend", "host"),
    [("mavlink", "127.0.0.1"), pytest.param("mavsdk", "0.0.0.0", marks=pytest.mark.mavsdk)],
)
def test_emulated_field_swarm_flies_two_missions_in_a_row(
    tmp_path: Path, backend: str, host: str
) -> None:
    swarm = unique_namespace("fld")
    procs = Procs(tmp_path)
    conf, router = router_config(tmp_path)
    base = free_udp_ports(1)[0]
    while base > 65000:
        base = free_udp_ports(1)[0]
    try:
        procs.start("router", "router", "--config", str(conf), "--insecure")
        procs.start("emulator", "emulator", "--uavs", "3", "--port-base", str(base),
                    "--time-scale", "4", "--status-every", "0")  # fmt: skip
        for i, uav in enumerate(UAVS):
            cfg = daemon_config(
                tmp_path, uav, swarm, router,
                extra=f'round_s = 0.5\n[vehicle]\nbackend = "{backend}"\n'
                f'url = "udpin://{host}:{base + i}"\n'
                f'[[field.points]]\nid = "L{i}"\nkind = "landmark"\nnorth = {4 + 3 * i}.0\n'
                "east = 3.0\n",
            )  # fmt: skip
            # (the extra goes before [mesh]: top-level keys, then sections)
            procs.start(uav, "daemon", "--config", str(cfg))
        assert wait_for_uavs(router, swarm, set(UAVS)), [procs.log(u)[-800:] for u in UAVS]
        outs = []
        for n in (1, 2):
            path = tmp_path / f"m{n}.json"
            code, out, err, _ = mission("--swarm", swarm, "--connect", router,
                                           "--rounds", "6", "--json", str(path))  # fmt: skip
            assert code == 0, (out, err, procs.log("uav0")[-2000:])
            rec = json.loads(path.read_text())
            assert rec["ended"] == "horizon"
            assert all(row["reports"] >= 6 for row in rec["progress"].values())
            assert rec["lost_uavs"] == {}
            assert "security" in rec
            outs.append(out)
            # landed before the next one: the daemons wait for the touch-down themselves
            assert wait_until(
                lambda n=n: all(  # type: ignore[misc]
                    procs.log(u).count("flight phase mission -> landing") >= n for u in UAVS
                ),
                30,
            )
        for out in outs:
            assert re.search(r"^uav0 ready as searcher$", out, re.M)
            rounds = re.findall(r"^round +\d+ \| uav0 r\d+ .*\| uav2 ", out, re.M)
            assert len(rounds) >= 3, out  # a line per round of the swarm
        for uav in UAVS:
            assert procs.term(uav)[0] == 0
    finally:
        procs.stop_all()
    log = procs.log("uav1")
    assert "uav1 up: swarm" in log
    assert f"vehicle {backend} udpin://" in log
    assert log.count("flight phase ground -> preflight (mission assigned)") == 2
    assert "flight phase landing -> ground (landed; ready for the next mission)" in log
