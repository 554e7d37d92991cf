"""Typed config: defaults, and every bad file is a ConfigError naming the file and the key."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pydantic import BaseModel

from aeroweaver_edge.config import (
    AgentConfig,
    ConfigError,
    LLMConfig,
    MeshConfig,
    SafetyConfig,
    SimConfig,
    UavConfig,
    VehicleConfig,
    load_config,
    parse_config,
)


def write(tmp_path: Path, text: str, name: str = "uav.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def bad(tmp_path: Path, text: str, name: str = "uav.toml") -> str:
    """Load ``text`` as a UavConfig file, expect a ConfigError, return its message."""
    path = write(tmp_path, text, name)
    with pytest.raises(ConfigError) as info:
        load_config(path, UavConfig)
    message = str(info.value)
    assert str(path) in message
    return message


# ------------------------------------------------------------------ defaults


@pytest.mark.parametrize(
    "section", [MeshConfig, LLMConfig, AgentConfig, SafetyConfig, VehicleConfig, SimConfig]
)
def test_every_section_has_valid_defaults(section: type[BaseModel]) -> None:
    assert section() == section.model_validate({})


def test_minimal_file_gives_paper_defaults(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, 'uav = "uav0"\n'), UavConfig)
    assert (cfg.uav, cfg.swarm, cfg.round_s) == ("uav0", "default", 0.5)
    assert (cfg.agent.beta, cfg.agent.gamma, cfg.agent.neighbourhood) == (0.8, 0.95, 32)
    assert cfg.safety.geofence_north_m == (-70.0, 70.0)
    assert cfg.safety.max_speed_mps == 11.0
    assert cfg.mesh.comm_radius_m == 55.0
    assert cfg.vehicle.backend == "sim"


def test_full_file_is_read(tmp_path: Path) -> None:
    cfg = load_config(
        write(
            tmp_path,
            """
uav = "uav-7"
swarm = "blue_team"
[mesh]
connect = ["tcp/10.0.0.1:7447"]
insecure = true  # a plain link off this machine must be asked for
lease_ms = 3000
[agent]
selector = "scripted"
beta = 0.0
[safety]
geofence_north_m = [-10.0, 10.0]
altitude_band_m = [3, 30]
""",
        ),
        UavConfig,
    )
    assert cfg.mesh.connect == ["tcp/10.0.0.1:7447"]
    assert cfg.agent.selector == "scripted"
    assert cfg.safety.altitude_band_m == (3.0, 30.0)


def test_config_is_frozen() -> None:
    cfg = UavConfig(uav="uav0")
    with pytest.raises(ValueError, match="frozen"):
        cfg.uav = "uav1"  # type: ignore[misc]


# ------------------------------------------------------------------ typos and types


def test_typo_at_top_level_names_the_key(tmp_path: Path) -> None:
    msg = bad(tmp_path, 'uav = "uav0"\nroud_s = 0.5\n')
    assert "roud_s" in msg


def test_typo_in_a_section_names_the_key_path(tmp_path: Path) -> None:
    msg = bad(tmp_path, 'uav = "uav0"\n[safety]\nmax_sped_mps = 5.0\n')
    assert "safety.max_sped_mps" in msg


def test_unknown_section_names_it(tmp_path: Path) -> None:
    msg = bad(tmp_path, 'uav = "uav0"\n[saftey]\nmax_speed_mps = 5.0\n')
    assert "saftey" in msg


def test_bad_type_names_the_key(tmp_path: Path) -> None:
    msg = bad(tmp_path, 'uav = "uav0"\n[llm]\ndeadline_s = "soon"\n')
    assert "llm.deadline_s" in msg


def test_list_item_location_is_indexed(tmp_path: Path) -> None:
    msg = bad(tmp_path, 'uav = "uav0"\n[mesh]\nlisten = ["tcp/127.0.0.1:0", 7]\n')
    assert "mesh.listen[1]" in msg


def test_out_of_range_values(tmp_path: Path) -> None:
    assert "mesh.lease_ms" in bad(tmp_path, 'uav = "uav0"\n[mesh]\nlease_ms = 100\n')
    assert "safety.max_speed_mps" in bad(tmp_path, 'uav = "uav0"\n[safety]\nmax_speed_mps = 0\n')
    assert "agent.selector" in bad(tmp_path, 'uav = "uav0"\n[agent]\nselector = "oracle"\n')
    assert "round_s" in bad(tmp_path, 'uav = "uav0"\nround_s = -1\n')


def test_every_problem_is_listed(tmp_path: Path) -> None:
    msg = bad(tmp_path, 'uav = "uav0"\nbogus = 1\n[agent]\nbeta = -1\n')
    assert "bogus" in msg
    assert "agent.beta" in msg


def test_missing_required_uav(tmp_path: Path) -> None:
    assert "uav" in bad(tmp_path, 'swarm = "s"\n')


@pytest.mark.parametrize("uav", ["", "UAV0", "uav 0", "uav/0", "uav*", "ü", "@uav"])
def test_bad_uav_id(tmp_path: Path, uav: str) -> None:
    msg = bad(tmp_path, f"uav = {json.dumps(uav)}\n")
    assert "uav" in msg


def test_bad_swarm_id(tmp_path: Path) -> None:
    assert "swarm" in bad(tmp_path, 'uav = "uav0"\nswarm = "a/**"\n')


@pytest.mark.parametrize("field", ["geofence_north_m", "geofence_east_m", "altitude_band_m"])
def test_reversed_or_empty_envelope_bounds(tmp_path: Path, field: str) -> None:
    assert f"safety.{field}" in bad(tmp_path, f'uav = "uav0"\n[safety]\n{field} = [60.0, 2.0]\n')
    assert f"safety.{field}" in bad(tmp_path, f'uav = "uav0"\n[safety]\n{field} = [5.0, 5.0]\n')


@pytest.mark.parametrize(
    "line",
    [
        "geofence_north_m = [nan, 70.0]",
        "geofence_east_m = [-70.0, inf]",
        "altitude_band_m = [2.0, inf]",
        "max_speed_mps = inf",
        "min_separation_m = nan",
    ],
)
def test_non_finite_envelope_is_refused(tmp_path: Path, line: str) -> None:
    """TOML has nan and inf; a NaN bound silently disables that side of the geofence
    (``max(x, nan)`` is ``x``) and ``inf`` disables the cap, so both must be refused."""
    key = line.split(" ", 1)[0]
    assert f"safety.{key}" in bad(tmp_path, f'uav = "uav0"\n[safety]\n{line}\n')


# ------------------------------------------------------------------ file problems


def test_toml_syntax_error(tmp_path: Path) -> None:
    msg = bad(tmp_path, 'uav = "uav0"\n[safety\n')
    assert "TOML" in msg


def test_json_config_by_suffix(tmp_path: Path) -> None:
    path = write(
        tmp_path, json.dumps({"uav": "uav3", "safety": {"max_speed_mps": 4.0}}), "uav.json"
    )
    cfg = load_config(path, UavConfig)
    assert (cfg.uav, cfg.safety.max_speed_mps) == ("uav3", 4.0)


def test_json_typo_names_key(tmp_path: Path) -> None:
    msg = bad(tmp_path, json.dumps({"uav": "uav3", "agent": {"betta": 1}}), "uav.json")
    assert "agent.betta" in msg


def test_json_syntax_error(tmp_path: Path) -> None:
    assert "JSON" in bad(tmp_path, '{"uav": "uav3",', "uav.json")


def test_toml_content_in_a_json_file_is_a_json_error(tmp_path: Path) -> None:
    assert "JSON" in bad(tmp_path, 'uav = "uav0"\n', "uav.json")


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match="cannot read") as info:
        load_config(path, UavConfig)
    assert str(path) in str(info.value)


def test_directory_instead_of_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path, UavConfig)


@pytest.mark.parametrize("payload", ["[1, 2]", '"uav0"', "3", "null"])
def test_top_level_must_be_a_table(tmp_path: Path, payload: str) -> None:
    assert "top level" in bad(tmp_path, payload, "uav.json")


def test_config_error_is_a_value_error() -> None:
    assert issubclass(ConfigError, ValueError)


def test_parse_config_names_the_source() -> None:
    with pytest.raises(ConfigError, match=r"^inline: uav"):
        parse_config({"uav": "BAD"}, UavConfig, "inline")
    with pytest.raises(ConfigError, match=r"^<config>: "):
        parse_config({}, UavConfig)


# ------------------------------------------------------------------ derived values


@pytest.mark.parametrize(
    ("uav", "index"), [("uav0", 0), ("uav12", 12), ("drone-3", 3), ("alpha", 0), ("u007", 7)]
)
def test_uav_index_from_id_digits(uav: str, index: int) -> None:
    assert UavConfig(uav=uav).uav_index == index


def test_explicit_index_wins() -> None:
    assert UavConfig(uav="uav12", index=4).uav_index == 4
    with pytest.raises(ValueError, match="index"):
        UavConfig(uav="uav1", index=-1)


def test_sim_config_bounds() -> None:
    assert SimConfig().deadline_s == 30.0
    with pytest.raises(ValueError, match="uavs"):
        SimConfig(uavs=51)
    assert SimConfig(uavs=50).uavs == 50
    with pytest.raises(ValueError, match="max_rounds"):
        SimConfig(max_rounds=0)
