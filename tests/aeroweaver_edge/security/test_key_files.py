"""Private key files are checked like ssh checks them: the real daemon, given a swarm made
by ``SwarmPki.create`` with one key file damaged (mode 0644/0666/0640, empty, garbage, the
wrong kind of key, another identity's key), exits 2 with one line naming the file (and
``chmod 600`` for a loose mode) before it opens a session. The MAVLink 2 key too."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from aeroweaver_edge.security.identity import SwarmPki, default_members
from aeroweaver_edge.security.key_files import PkiError, check_private, load_private_key

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> SwarmPki:
    return SwarmPki.create(tmp_path_factory.mktemp("pki"), "s", default_members(2))


@pytest.fixture
def swarm(made: SwarmPki, tmp_path: Path) -> SwarmPki:
    """A private copy (permissions kept) each test may damage."""
    root = tmp_path / "swarm"
    shutil.copytree(made.root, root)
    return SwarmPki.load(root)


def uav_toml(pki: SwarmPki, at: Path) -> Path:
    sec = pki.security_for("uav0")
    lines = ['uav = "uav0"', 'swarm = "s"', "[mesh]", 'listen = ["tls/127.0.0.1:0"]',
             "[mesh.security]"]  # fmt: skip
    for key, value in sec.model_dump().items():
        if value is not None:
            lines.append(
                f"{key} = {str(value).lower() if isinstance(value, bool) else repr(value)}"
            )
    path = at / "uav.toml"
    path.write_text("\n".join(lines).replace("'", '"') + "\n", encoding="utf-8")
    return path


def run_daemon(config: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "aeroweaver_edge", "daemon", "--config", str(config)],
        capture_output=True, text=True, timeout=60, env=env, cwd=config.parent,
    )  # fmt: skip


def _chmod(mode: int) -> Callable[[Path], None]:
    return lambda p: p.chmod(mode)


def _write(data: bytes) -> Callable[[Path], None]:
    def write(p: Path) -> None:
        p.write_bytes(data)

    return write


def _truncate(p: Path) -> None:
    p.write_bytes(p.read_bytes()[:60])


def _make_dir(p: Path) -> None:
    p.unlink()
    p.mkdir()


DAMAGE: dict[str, tuple[str, Callable[[Path], None], str]] = {
    "tls key 0644": ("tls.key", _chmod(0o644), "chmod 600"),
    "tls key 0666": ("tls.key", _chmod(0o666), "chmod 600"),
    "tls key 0640": ("tls.key", _chmod(0o640), "chmod 600"),
    "sign key 0644": ("sign.key", _chmod(0o644), "chmod 600"),
    "sign key 0604": ("sign.key", _chmod(0o604), "chmod 600"),
    "empty sign key": ("sign.key", _write(b""), "empty"),
    "blank sign key": ("sign.key", _write(b"\n  \n"), "empty"),
    "garbage sign key": ("sign.key", _write(b"\x00\xffnot a key at all" * 8), "not a PEM"),
    "truncated sign key": ("sign.key", _truncate, "not a PEM"),
    "garbage tls key": ("tls.key", _write(b"-----BEGIN PRIVATE KEY-----\nAAAA\n"), "not a PEM"),
    "huge sign key": ("sign.key", _write(b"A" * 200_000), "bytes is no signing key"),
    "sign key is a directory": ("sign.key", _make_dir, "regular file"),
    "sign key missing": ("sign.key", lambda p: p.unlink(), "cannot read"),
}


@pytest.mark.parametrize("case", sorted(DAMAGE))
def test_a_damaged_private_key_is_one_line_and_exit_2(
    swarm: SwarmPki, tmp_path: Path, case: str
) -> None:
    name, damage, says = DAMAGE[case]
    target = swarm.paths("uav0").dir / name
    damage(target)
    proc = run_daemon(uav_toml(swarm, tmp_path))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert str(target) in lines[0], lines[0]
    assert says in lines[0], lines[0]
    assert "Traceback" not in proc.stderr
    assert "internal error" not in proc.stderr


def test_another_identitys_tls_key_is_named(swarm: SwarmPki, tmp_path: Path) -> None:
    mine, other = swarm.paths("uav0"), swarm.paths("uav1")
    shutil.copy2(other.tls_key, mine.tls_key)
    proc = run_daemon(uav_toml(swarm, tmp_path))
    assert proc.returncode == 2, proc.stderr
    assert f"{mine.tls_key}: not the private key of {mine.tls_cert}" in proc.stderr


def test_an_ecdsa_key_where_the_signing_key_belongs_is_named(
    swarm: SwarmPki, tmp_path: Path
) -> None:
    mine = swarm.paths("uav0")
    shutil.copy2(mine.tls_key, mine.sign_key)
    proc = run_daemon(uav_toml(swarm, tmp_path))
    assert proc.returncode == 2, proc.stderr
    assert f"{mine.sign_key}: not an Ed25519 private key" in proc.stderr


def test_mode_0600_and_0400_are_accepted_and_a_world_bit_never(tmp_path: Path) -> None:
    key = tmp_path / "k"
    key.write_bytes(b"x")
    for mode in (0o600, 0o400):
        key.chmod(mode)
        check_private(key, "test key")
    for mode in (0o644, 0o604, 0o660, 0o620, 0o606, 0o700 | 0o001):
        key.chmod(mode)
        with pytest.raises(PkiError, match=rf"mode {mode:04o}\); chmod 600 {key}"):
            check_private(key, "test key")


def test_a_pem_that_is_no_private_key_is_named(swarm: SwarmPki, tmp_path: Path) -> None:
    key = tmp_path / "cert-as-key"
    key.write_bytes(swarm.ca_cert.read_bytes())
    key.chmod(0o600)
    with pytest.raises(PkiError, match="not a PEM private key"):
        load_private_key(key, "TLS private key")


def test_the_mavlink_key_is_refused_alike(tmp_path: Path) -> None:
    from aeroweaver_edge.vehicle.mavlink.signing import SigningError, load_key, write_key

    key = tmp_path / "mav.key"
    write_key(key)
    assert len(load_key(key)) == 32
    key.chmod(0o644)
    with pytest.raises(SigningError, match="chmod 600"):
        load_key(key)
    key.chmod(0o600)
    key.write_bytes(b"")
    with pytest.raises(SigningError, match="32 raw bytes or 64 hex"):
        load_key(key)
