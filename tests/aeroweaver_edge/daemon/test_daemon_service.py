"""``aeroweaver daemon`` is a service, and ``mission start`` tells the truth: real router,
daemon and mission processes on loopback (insecure: the secured flow is in
``test_daemon_service_secured.py``).

- daemons on the sim backend fly two ``mission start --sim-world`` in a row; each start has
  its own mission id and both records have episodes, ``security`` and ``lost_uavs``;
- a mission for them without a world is refused at once (exit 2, one line);
- no daemon up: one line, exit 2, within the roster wait plus start-up;
- the router killed mid-mission: the mission stops, exit 1, the record names the lost UAVs;
- SIGTERM exits 0 at start-up, idle and mid-mission; INFO lines by default, journald's
  format under ``JOURNAL_STREAM``.
"""

from __future__ import annotations

import json
import os
import re
import signal
import time
from pathlib import Path

import pytest

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


def _start_swarm(procs: Procs, root: Path, swarm: str, **env: dict[str, str]) -> str:
    conf, router = router_config(root)
    procs.start("router", "router", "--config", str(conf), "--insecure")
    for uav in UAVS:
        cfg = daemon_config(root, uav, swarm, router)
        procs.start(uav, "daemon", "--config", str(cfg), env=env.get(uav))
    assert wait_for_uavs(router, swarm, set(UAVS)), [procs.log(u)[-800:] for u in UAVS]
    return router


def test_sim_daemons_fly_two_missions_in_a_row_and_stop_with_status_0(tmp_path: Path) -> None:
    swarm = unique_namespace("svc")
    procs = Procs(tmp_path)
    # uav0 writes to a file systemd would have connected to the journal: it says so.
    log0 = tmp_path / "uav0.log"
    log0.touch()
    st = os.stat(log0)
    journal = {"uav0": {"JOURNAL_STREAM": f"{st.st_dev}:{st.st_ino}"}}
    try:
        router = _start_swarm(procs, tmp_path, swarm, **journal)
        # No world: the daemons say they wait for one, and the Commander says so at once.
        code, out, err, wall = mission("--swarm", swarm, "--connect", router, "--rounds", "5")
        assert code == 2, (out, err)
        [line] = err.strip().splitlines()[-1:]
        assert line.startswith("aeroweaver: uav0, uav1, uav2 fly the sim backend and are "
                               "waiting for a simulated world, which nobody runs; pass "
                               "--sim-world")  # fmt: skip
        assert "Traceback" not in err
        assert wall < 20
        records = []
        for n in (1, 2):
            path = tmp_path / f"m{n}.json"
            code, out, err, _ = mission("--swarm", swarm, "--connect", router, "--sim-world",
                                        "--rounds", "5", "--json", str(path))  # fmt: skip
            assert code == 0, (out, err, procs.log("uav0")[-1500:])
            # The mission table comes before the run, the legend before the rounds.
            table, legend = out.index("active skills"), out.index("each round:")
            assert table < legend < out.index("ep 0 round  1")
            records.append(json.loads(path.read_text()))
        for rec in records:
            assert len(rec["episodes"]) == 1
            assert rec["episodes"][0]["rounds"] >= 1
            assert rec["lost_uavs"] == {}
            assert rec["rejoined_uavs"] == {}
            assert rec["security"]["tls"] is False
            assert rec["security"]["rejected_total"] == 0
            assert set(rec["progress"]) == set(UAVS)
        ids = [r["mission"]["mission_id"] for r in records]
        assert ids[0] != ids[1]
        assert all(i.startswith("coverage-") for i in ids)
        time.sleep(1.0)  # idle now
        for uav in UAVS:
            code, took = procs.term(uav)
            assert (code, uav) == (0, uav)
            assert took < 5.0
    finally:
        procs.stop_all()
    text = procs.log("uav1")
    assert "INFO aeroweaver_edge.daemon.app: uav1 up: swarm" in text  # INFO by default
    assert len(re.findall(r"uav1: mission coverage-\S+ ended \(horizon\): \d+ rounds", text)) == 2
    assert "flight phase landing -> ground (landed; ready for the next mission)" in text
    assert "went away and did not come back" not in text
    journal_lines = procs.log("uav0").splitlines()
    assert any(
        ln.startswith("<6>aeroweaver_edge.daemon.app: uav0 up: swarm") for ln in journal_lines
    )
    assert any(
        ln.startswith("<6>aeroweaver_edge.daemon.app: uav0 decides with ") for ln in journal_lines
    )
    assert all(ln.startswith("<") for ln in journal_lines if ln)  # no timestamps, priorities
    assert any(ln.startswith("<6>aeroweaver: uav0 stopping on SIGTERM") for ln in journal_lines)


def test_no_daemon_up_is_one_line_and_exit_2_within_the_bound(tmp_path: Path) -> None:
    procs = Procs(tmp_path)
    conf, router = router_config(tmp_path)
    procs.start("router", "router", "--config", str(conf), "--insecure")
    try:
        assert wait_until(lambda: "up" in procs.log("router"), 20)
        code, out, err, wall = mission("--swarm", unique_namespace("none"), "--connect", router,
                                       "--roster-wait", "1.5", "--sim-world")  # fmt: skip
    finally:
        procs.stop_all()
    assert code == 2
    assert len(err.strip().splitlines()) == 1, err
    assert re.match(r"aeroweaver: no UAV daemon of swarm '\S+' answered within 1.5 s; start "
                    r"them \(aeroweaver daemon --config uav.toml\)", err)  # fmt: skip
    assert out == ""
    assert wall < 15  # the roster wait plus interpreter start-up


def test_router_killed_mid_mission_stops_it_and_names_the_lost_uavs(tmp_path: Path) -> None:
    swarm = unique_namespace("lost")
    procs = Procs(tmp_path)
    try:
        router = _start_swarm(procs, tmp_path, swarm)
        record = tmp_path / "m.json"
        log = procs.start("mission", "mission", "start", "Cover the three landmarks with three "
                          "drones", "--no-llm", "--swarm", swarm, "--connect", router,
                          "--sim-world", "--rounds", "60", "--episodes", "3", "--pace", "0.3",
                          "--lost-grace", "2", "--json", str(record))  # fmt: skip
        assert wait_until(lambda: "ep 0 round  3" in log.read_text(), 60), log.read_text()
        # SIGTERM mid-mission: uav2 holds, lands and exits 0 at once.
        code, took = procs.term("uav2")
        assert (code, took < 5.0) == (0, True), procs.log("uav2")[-1000:]
        assert wait_until(lambda: "lost contact with uav2" in log.read_text(), 10)
        t_kill = time.monotonic()
        procs.procs["router"].send_signal(signal.SIGKILL)  # the router dies: no goodbye
        procs.procs["router"].wait()
        status = procs.procs["mission"].wait(timeout=60)
        stopped_after = time.monotonic() - t_kill
        assert status == 1, log.read_text()[-2000:]
        assert stopped_after < 20  # the grace (2 s) plus the link timeout
        text = log.read_text()
        assert "ended: lost contact with every UAV (uav0, uav1, uav2) for 2 s" in text
        assert "aeroweaver: mission ended without contact to uav0, uav1, uav2" in text
        rec = json.loads(record.read_text())
        assert set(rec["lost_uavs"]) == set(UAVS)
        assert all(len(where) == 2 for where in rec["lost_uavs"].values())
        assert rec["out_of_contact"] == list(UAVS)
        assert rec["rejoined_uavs"] == {}
        assert {"tls", "acl", "signed", "rejected_total"} <= set(rec["security"])
        # The daemons left behind hold and go on as services; SIGTERM still ends them with 0.
        for uav in ("uav0", "uav1"):
            assert procs.procs[uav].poll() is None
            code, took = procs.term(uav)
            assert (code, uav) == (0, uav)
    finally:
        procs.stop_all()


def _daemon_with_a_silent_vehicle(root: Path) -> Path:
    """uav0 on a MAVLink link nobody answers (30 s connect timeout): it stays starting."""
    return daemon_config(
        root, "uav0", "up", None,
        extra=f'[vehicle]\nbackend = "mavlink"\nurl = "udpin://127.0.0.1:{free_port()}"\n'
        "connect_timeout_s = 30\n",
    )  # fmt: skip


@pytest.mark.parametrize("after_s", [0.6, 1.5, 3.0])
def test_sigterm_during_start_up_exits_0_promptly(tmp_path: Path, after_s: float) -> None:
    """Imports, config, the mesh, then a vehicle link that never answers (mavlink, 30 s
    connect timeout): a stop at any of these points ends the daemon at once with 0."""
    cfg = _daemon_with_a_silent_vehicle(tmp_path)
    procs = Procs(tmp_path)
    try:
        procs.start("uav0", "daemon", "--config", str(cfg))
        time.sleep(after_s)
        assert procs.procs["uav0"].poll() is None, procs.log("uav0")
        code, took = procs.term("uav0")
    finally:
        procs.stop_all()
    assert code == 0, procs.log("uav0")
    assert took < 3.0, procs.log("uav0")


def test_sigterm_repeated_while_stopping_still_exits_0(tmp_path: Path) -> None:
    """The parent-death signal can come more than once: the kernel sends it again each
    time a multithreaded parent's dying thread hands the daemon to the next one (stop 28's
    suite: one daemon of a killed run died of its second SIGTERM, after its loop had put
    the default handler back). Every SIGTERM after the first is part of the same stop."""
    cfg = _daemon_with_a_silent_vehicle(tmp_path)
    procs = Procs(tmp_path)
    try:
        procs.start("uav0", "daemon", "--config", str(cfg))
        time.sleep(2.0)  # up to the vehicle link: the loop owns SIGTERM
        proc = procs.procs["uav0"]
        assert proc.poll() is None, procs.log("uav0")
        started = time.monotonic()
        while proc.poll() is None and time.monotonic() - started < 10.0:
            proc.send_signal(signal.SIGTERM)  # a burst until it is gone
            time.sleep(0.0005)
        code = proc.wait(timeout=10)
    finally:
        procs.stop_all()
    assert code == 0, procs.log("uav0")
