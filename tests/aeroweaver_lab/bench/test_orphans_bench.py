"""``bench.orphans`` in small: one kill -9 of ``aeroweaver sim --processes``, measured."""

from __future__ import annotations

import json

import pytest

from aeroweaver_lab.bench import orphans

pytestmark = pytest.mark.slow


def test_one_kill_leaves_no_daemon_and_no_directory(capsys: pytest.CaptureFixture[str]) -> None:
    assert orphans.main(["--kills", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["kills"], out["daemons_killed_with_it"]) == (1, 3)
    assert (out["orphaned_daemons"], out["dirs_left"]) == (0, 0)
    assert set(out["daemons_gone_s"]) == {"p50", "p95", "max"}
    assert out["daemon_exits"] == {"exit 0": 3}  # a clean stop on the parent-death SIGTERM
