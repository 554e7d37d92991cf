"""Boot epochs from a persisted counter: strictly increasing across restarts, never reset."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest

from aeroweaver_edge.security.boot import BootCounterError, next_epoch


def test_counter_counts_starts_per_identity(tmp_path: Path) -> None:
    assert [next_epoch(tmp_path, "uav0") for _ in range(3)] == [1, 2, 3]
    assert next_epoch(tmp_path, "uav1") == 1
    assert (tmp_path / "uav0.boot").read_text() == "3\n"
    assert stat.S_IMODE((tmp_path / "uav0.boot").stat().st_mode) == 0o644
    assert sorted(p.name for p in tmp_path.iterdir()) == ["uav0.boot", "uav1.boot"]


def test_counter_survives_a_new_process(tmp_path: Path) -> None:
    import subprocess
    import sys

    code = (
        "import sys; from aeroweaver_edge.security.boot import next_epoch; "
        "print(next_epoch(sys.argv[1], 'cmdr'))"
    )
    out = [
        subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True,
                       text=True, check=True).stdout.strip()
        for _ in range(2)
    ]  # fmt: skip
    assert out == ["1", "2"]


@pytest.mark.parametrize("content", ["", "x\n", "-3\n", "1e9\n", "\xff"])
def test_corrupt_counter_is_an_error_not_a_reset(tmp_path: Path, content: str) -> None:
    (tmp_path / "uav0.boot").write_bytes(content.encode("latin-1"))
    with pytest.raises(BootCounterError, match=r"uav0\.boot"):
        next_epoch(tmp_path, "uav0")


def test_unwritable_state_dir_is_an_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    with pytest.raises(BootCounterError, match="cannot"):
        next_epoch(blocker, "uav0")
    with pytest.raises(ValueError, match="identity"):
        next_epoch(tmp_path, "../etc/passwd")
