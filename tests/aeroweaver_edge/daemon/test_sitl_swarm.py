"""The whole daemon on real firmware (``pytest -m sitl``, AEROWEAVER_SITL=/path/to/arducopter):
three ``aeroweaver daemon`` processes over the MAVLink backend fly the rehearsal's coverage
mission through a router and the Commander against three ArduCopter SITL instances, each in
its own network namespace. Preflight sets the companion-loss failsafe, the vehicles arm in
GUIDED, take off, fly the skills' setpoints, land at the end and disarm; every process exits
0 on SIGTERM and nothing is left running. A watcher on each instance's SERIAL1 sees it."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import pytest

from aeroweaver_edge.provision import sitl as provision_sitl
from aeroweaver_edge.provision.daemon_toml import DEMO_POINTS
from tests.helpers import sitl
from tests.helpers.mav_watch import MavWatcher
from tests.helpers.swarm_procs import (
    UAVS,
    Procs,
    daemon_config,
    mission,
    router_config,
    wait_for_uavs,
    wait_until,
)
from tests.helpers.zenoh_net import unique_namespace

pytestmark = [pytest.mark.sitl, pytest.mark.slow, pytest.mark.timeout(600)]


def field_points() -> str:
    return "".join(
        f'[[field.points]]\nid = "{p["id"]}"\nkind = "{p["kind"]}"\n'
        f"north = {float(p['north'])}\neast = {float(p['east'])}\n"
        for p in DEMO_POINTS
    )


def test_three_daemons_fly_the_coverage_mission_on_sitl(tmp_path: Path) -> None:
    binary = sitl.check_binary(sitl.binary_from_env() or Path())
    swarm = unique_namespace("sitl")
    procs = Procs(tmp_path)
    conf, router = router_config(tmp_path)
    started = time.monotonic()
    lat, lon, alt = provision_sitl.ORIGIN
    with (
        MavWatcher(host="0.0.0.0") as watcher,
        sitl.SitlFleet(binary, tmp_path / "sitl", watch_port=watcher.port) as fleet,
    ):
        instances = fleet.start(3)
        try:
            procs.start("router", "router", "--config", str(conf), "--insecure")
            for uav, inst in zip(UAVS, instances, strict=True):
                cfg = daemon_config(
                    tmp_path, uav, swarm, router,
                    extra=f'round_s = 0.5\n[vehicle]\nbackend = "mavlink"\n'
                    f'url = "{inst.daemon_url}"\npersonality = "ardupilot"\n'
                    f"origin = [{lat}, {lon}, {alt}]\nconnect_timeout_s = 120.0\n"
                    f"takeoff_timeout_s = 90.0\n{field_points()}",
                )  # fmt: skip
                procs.start(uav, "daemon", "--config", str(cfg))
            assert wait_for_uavs(router, swarm, set(UAVS), 180), [
                procs.log(u)[-1500:] for u in UAVS
            ]
            assert wait_until(
                lambda: all("waiting for a mission" in procs.log(u) for u in UAVS), 180
            ), [procs.log(u)[-1500:] for u in UAVS]
            record = tmp_path / "m1.json"
            code, out, err, wall = mission(
                "--swarm", swarm, "--connect", router, "--rounds", "24", "--json", str(record),
                timeout_s=300.0,
            )  # fmt: skip
            assert code == 0, (out, err, [procs.log(u)[-3000:] for u in UAVS])
            rec = json.loads(record.read_text())
            assert rec["ended"] == "horizon"
            assert rec["lost_uavs"] == {}
            assert all(row["reports"] >= 12 for row in rec["progress"].values()), rec["progress"]
            # the firmware itself: every vehicle flew GUIDED, landed and disarmed
            watches = [watcher.watch(inst.sysid) for inst in instances]
            assert all(any(s.mode == "GUIDED" and s.armed for s in w.samples) for w in watches)
            assert wait_until(lambda: all(not w.armed for w in watches), 90), [
                (w.mode, w.alt_m) for w in watches
            ]
            codes = {u: procs.term(u)[0] for u in (*UAVS, "router")}
            assert codes == dict.fromkeys((*UAVS, "router"), 0)
        finally:
            procs.stop_all()
    total = time.monotonic() - started
    leftovers = subprocess.run(["pgrep", "-f", str(binary)], capture_output=True, text=True)
    assert leftovers.stdout.strip() == ""  # no SITL instance outlives the test
    for uav in UAVS:
        log = procs.log(uav)
        assert "companion-loss failsafe: the autopilot lands 3 s after" in log
        assert "flight phase arming -> taking_off" in log
        assert "flight phase offboard -> mission (offboard control)" in log
        assert "flight phase mission -> landing (mission ended)" in log
    print(f"\nSITL swarm: mission start {wall:.1f} s wall, whole test {total:.1f} s\n{out}")
    assert total <= 300.0
