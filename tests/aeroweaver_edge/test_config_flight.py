"""The vehicle and field sections: every bad value is an error naming the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from aeroweaver_edge.config import ConfigError, UavConfig, load_config


def load(tmp_path: Path, vehicle: str, extra: str = "") -> UavConfig:
    path = tmp_path / "uav.toml"
    path.write_text(f'uav = "uav0"\n[vehicle]\n{vehicle}\n{extra}', encoding="utf-8")
    return load_config(path, UavConfig)


def test_a_complete_mavlink_section_is_read(tmp_path: Path) -> None:
    cfg = load(
        tmp_path,
        'backend = "mavlink"\nurl = "udpin://0.0.0.0:14541"\npersonality = "ardupilot"\n'
        'sysid = 2\nsetpoint_hz = 25\nlease_s = 1.5\nfailsafe_policy = "warn"\n'
        'end_action = "return"\non_link_loss = "land"',
        '[field]\npoints = [{ id = "W0", north = 1.0, east = 2.0 }]\n',
    )
    v = cfg.vehicle
    assert (v.backend, v.url, v.personality, v.sysid) == ("mavlink", "udpin://0.0.0.0:14541",
                                                          "ardupilot", 2)  # fmt: skip
    assert (v.setpoint_hz, v.lease_s, v.failsafe_policy) == (25, 1.5, "warn")
    assert (v.end_action, v.on_link_loss) == ("return", "land")
    assert cfg.field.points[0].kind == "waypoint"


@pytest.mark.parametrize(
    ("vehicle", "needle"),
    [
        ('backend = "mavlink"', "vehicle: url is required for backend 'mavlink'"),
        ('backend = "mavlink"\nurl = "tcp://x:1"', "scheme must be udpin:// or udpout://"),
        ('backend = "mavlink"\nurl = "udpin://0.0.0.0"', "expected HOST:PORT"),
        ('backend = "mavlink"\nurl = "udpout://h:0"', "udpout needs a real destination port"),
        ('backend = "mavsdk"\nurl = "14540"', "is not a MAVSDK connection URL"),
        ("setpoint_hz = 5", "vehicle.setpoint_hz"),
        ("sysid = 0", "vehicle.sysid"),
        ("sysid = 256", "vehicle.sysid"),
        ("lease_s = nan", "vehicle.lease_s"),
        ('personality = "betaflight"', "vehicle.personality"),
        ('failsafe_policy = "ignore"', "vehicle.failsafe_policy"),
        ('end_action = "crash"', "vehicle.end_action"),
        ("link_timeout_s = 0.1", "vehicle.link_timeout_s"),
        ("command_retries = 11", "vehicle.command_retries"),
        ('backend = "mavlink"\nurl = "udpin://h:1"\nlease_s = 0.05', "shorter than two setpoint"),
        ("altitude_m = 500", "vehicle.altitude_m"),
    ],
)
def test_bad_vehicle_settings_name_the_key(tmp_path: Path, vehicle: str, needle: str) -> None:
    with pytest.raises(ConfigError, match=r"uav\.toml") as info:
        load(tmp_path, vehicle)
    assert needle in str(info.value)


def test_bad_field_points_name_the_key(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"field.points\[0\].north"):
        load(tmp_path, "", '[field]\npoints = [{ id = "W0", north = "far", east = 2.0 }]\n')
    with pytest.raises(ConfigError, match=r"field.points\[0\].kind"):
        load(tmp_path, "", '[field]\npoints = [{ id = "W0", kind = "tree", north = 1, east = 2 }]')
