"""The whole simulated swarm end to end: world + daemons + Commander over loopback zenoh,
with the deterministic scripted selector (no LLM)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from aeroweaver_edge.orchestration.daemons import DaemonSet
from aeroweaver_edge.orchestration.swarm import RunSummary, SwarmOptions, run_swarm
from aeroweaver_edge.sim.runner import RoundLog
from commander.progress import ProgressBoard

SUMMARY_KEYS = {
    "task",
    "seed",
    "rounds",
    "team_return",
    "agent_returns",
    "messages_sent",
    "wall_s",
    "decode_errors",
    "messages_dropped",
    "lost_uavs",
    "episodes",
    "holds",
    "deadline_misses",
    "security",
}
UAVS = ["uav0", "uav1", "uav2"]


def scripted(**kw: Any) -> SwarmOptions:
    return SwarmOptions(selector="scripted", deadline_s=5.0, **kw)


def check_summary(data: dict[str, Any], seed: int = 1, uavs: list[str] = UAVS) -> None:
    assert set(data) >= SUMMARY_KEYS, SUMMARY_KEYS - set(data)
    assert (data["task"], data["seed"]) == ("coverage", seed)
    assert 1 <= data["rounds"] <= 24
    assert set(data["agent_returns"]) == set(uavs)
    assert data["team_return"] == pytest.approx(sum(data["agent_returns"].values()) / len(uavs))
    assert data["decode_errors"] == 0
    assert data["lost_uavs"] == {}
    assert data["envelope_violations"]["total"] == 0
    assert data["envelope_violations"]["checked"] == len(uavs) * data["rounds"]
    [episode] = data["episodes"]
    assert episode["reason"] == ("complete" if episode["rounds"] < 24 else "horizon")
    assert episode["rounds"] == data["rounds"]
    assert data["messages_sent"] > 0
    assert data["wall_s"] > 0
    assert "not an LLM" in data["note"]
    json.dumps(data)  # JSON-ready as is


async def test_in_process_coverage_episode_completes() -> None:
    """Two searchers, two landmarks: covered for 3 rounds in a row before the horizon (the
    default three-UAV layout does not complete with the reference policy: tasks e2e)."""
    logs: list[RoundLog] = []

    async def on_round(log: RoundLog, board: ProgressBoard) -> None:
        logs.append(log)

    summary = await run_swarm(scripted(uavs=2, seed=2), on_round=on_round)
    data = summary.as_dict()
    check_summary(data, seed=2, uavs=UAVS[:2])
    [episode] = data["episodes"]
    assert episode["reason"] == "complete"
    assert data["rounds"] < 24
    assert episode["metrics"]["covered_landmarks"] == 2.0
    assert [log.result.stable_rounds for log in logs[-3:]] == [1, 2, 3]
    assert data["mode"] == "in-process"
    assert data["selector"] == "scripted:reference"
    assert len(logs) == data["rounds"]
    # Every UAV answered every round in time: nobody was missing or absent.
    assert all(
        set(log.commands) == set(UAVS[:2]) and not log.missed and not log.absent for log in logs
    )
    assert data["deadline_misses"] == 0
    assert data["tokens"] == {"prompt": 0, "prompt_cached": 0, "completion": 0, "total": 0}
    assert data["tokens_per_decision"] == {}  # no LLM decisions


async def test_same_seed_gives_the_same_returns_in_processes_mode() -> None:
    a = (await run_swarm(scripted(seed=2))).as_dict()
    b = (await run_swarm(scripted(seed=2, processes=True))).as_dict()
    check_summary(b, seed=2)
    assert b["mode"] == "processes"
    assert b["agent_returns"] == a["agent_returns"]
    assert b["rounds"] == a["rounds"]
    assert b["episodes"][0]["metrics"] == a["episodes"][0]["metrics"]


@pytest.mark.parametrize("processes", [False, True], ids=["task-cancelled", "sigkill"])
async def test_a_killed_daemon_is_marked_lost_and_the_rest_keep_deciding(processes: bool) -> None:
    """In-process the daemon task is cancelled (its session closes cleanly); with
    ``processes=True`` the daemon process gets SIGKILL (the session just vanishes)."""
    victim, kill_after = "uav2", 2
    logs: list[RoundLog] = []

    async def fault(log: RoundLog, daemons: DaemonSet) -> None:
        logs.append(log)
        if log.round == kill_after:
            await daemons.kill(victim)

    summary: RunSummary = await run_swarm(scripted(processes=processes), fault=fault)
    data = summary.as_dict()

    assert 1 <= data["rounds"] <= 24
    assert len(logs) == data["rounds"]
    assert list(data["lost_uavs"]) == [victim]
    episode, lost_round = data["lost_uavs"][victim]
    assert episode == 0
    assert kill_after <= lost_round <= kill_after + 1
    after = logs[kill_after + 1 :]
    assert after, "the episode must go on after the kill"
    for log in after:
        assert {"uav0", "uav1"} <= set(log.commands), log.round  # the others keep deciding
        assert victim not in log.commands
    assert all(victim in log.absent for log in after[1:])
    # The world noticed the loss via liveliness instead of waiting out every deadline.
    assert data["deadline_misses"] <= 1
    assert set(data["agent_returns"]) == set(UAVS)


def _aeroweaver() -> list[str]:
    script = Path(sys.executable).with_name("aeroweaver")
    if script.exists():
        return [str(script)]
    found = shutil.which("aeroweaver")
    return [found] if found else [sys.executable, "-m", "aeroweaver_edge"]


def _cli_sim(tmp_path: Path, out: Path, *extra: str) -> dict[str, Any]:
    proc = subprocess.run(
        [*_aeroweaver(), "sim", "coverage", "--selector", "scripted", "--json", str(out), *extra],
        capture_output=True,
        text=True,
        timeout=90,
        cwd=tmp_path,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert f"summary written to {out}" in proc.stdout
    data: dict[str, Any] = json.loads(out.read_text(encoding="utf-8"))
    check_summary(data)
    return data


def test_cli_sim_writes_the_json_summary(tmp_path: Path) -> None:
    """Secured by default; ``--insecure`` flies the very same returns without security."""
    secured = _cli_sim(tmp_path, tmp_path / "runs" / "coverage.json", "--quiet")
    sec = secured["security"]
    assert (sec["tls"], sec["mtls"], sec["acl"], sec["signed"]) == (True, True, True, True)
    assert (sec["rejected_total"], sec["missing_messages"], sec["refused_commands"]) == (0, 0, {})
    plain = _cli_sim(tmp_path, tmp_path / "plain.json", "--quiet", "--insecure")
    assert not any(plain["security"][k] for k in ("tls", "mtls", "acl", "signed"))
    assert plain["agent_returns"] == secured["agent_returns"]
    assert plain["rounds"] == secured["rounds"]
