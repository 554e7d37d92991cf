"""``[agent] estimator`` / ``scripted_base``: validated at load (one line naming the field and
the allowed forms, exit 2), overridden by the environment, overridden in turn by a flag; and
what a daemon built from a loaded file actually runs (its selector, its memory's estimator)."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from aeroweaver_edge.agent import choices
from aeroweaver_edge.agent.estimators import ENV_ESTIMATOR, Estimator
from aeroweaver_edge.agent.memory.async_memory import AsyncExperienceMemory
from aeroweaver_edge.agent.scripted import ENV_BASE, Base, DegradedScorer
from aeroweaver_edge.cli.main import main
from aeroweaver_edge.config import AgentConfig, ConfigError, UavConfig, load_config
from aeroweaver_edge.daemon.app import open_selector


@pytest.fixture(autouse=True)
def _no_overrides(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ENV_ESTIMATOR, raising=False)
    monkeypatch.delenv(ENV_BASE, raising=False)


def toml(tmp_path: Path, agent: str) -> Path:
    path = tmp_path / "uav.toml"
    path.write_text(f'uav = "uav0"\nswarm = "demo"\n\n[agent]\nselector = "scripted"\n{agent}\n')
    return path


def test_defaults_and_canonical_forms(tmp_path: Path) -> None:
    assert AgentConfig().estimator == "paper"
    assert AgentConfig().scripted_base == "reference"
    cfg = load_config(
        toml(tmp_path, 'estimator = " centre , horizon:3 "\nscripted_base = "noisy:1.5@2"'),
        UavConfig,
    )
    assert cfg.agent.estimator == "horizon:3,centre"
    assert cfg.agent.scripted_base == "noisy:1.5@2"
    assert Estimator.parse(cfg.agent.estimator) == Estimator(3, centre=True)


@pytest.mark.parametrize(
    ("line", "field", "needle"),
    [
        ('estimator = "bayes"', "agent.estimator", "horizon:H"),
        ('estimator = "horizon:0"', "agent.estimator", "1..1000"),
        ('estimator = "centre"', "agent.estimator", "centre needs a horizon"),
        ('estimator = ""', "agent.estimator", "expected paper"),
        ("estimator = 3", "agent.estimator", "string"),
        ('scripted_base = "lazy"', "agent.scripted_base", "hold-biased"),
        ('scripted_base = "noisy:-1"', "agent.scripted_base", "SD must be a positive"),
        ('scripted_base = "hold-biased@0"', "agent.scripted_base", "TEMPERATURE"),
    ],
)
def test_bad_values_name_the_field_and_the_forms(
    tmp_path: Path, line: str, field: str, needle: str
) -> None:
    path = toml(tmp_path, line)
    with pytest.raises(ConfigError) as err:
        load_config(path, UavConfig)
    text = str(err.value)
    assert "\n" not in text
    assert f"{path}: {field}:" in text
    assert needle in text


def test_daemon_with_a_bad_value_exits_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = toml(tmp_path, 'estimator = "bayes"')
    assert main(["daemon", "--config", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "agent.estimator" in err
    assert "'bayes'" in err


def test_precedence_flag_environment_config_default(monkeypatch: pytest.MonkeyPatch) -> None:
    assert choices.resolve("estimator") == "paper"
    assert choices.resolve("estimator", configured="horizon:2") == "horizon:2"
    monkeypatch.setenv(ENV_ESTIMATOR, "support:3")
    assert choices.resolve("estimator", configured="horizon:2") == "support:3"
    assert choices.resolve("estimator", "horizon:4", "horizon:2") == "horizon:4"
    monkeypatch.setenv(ENV_ESTIMATOR, "  ")  # empty: no override
    assert choices.resolve("estimator", configured="horizon:2") == "horizon:2"
    assert choices.resolve("scripted_base") == "reference"
    monkeypatch.setenv(ENV_BASE, "hold-biased@5")
    agent = choices.with_env_overrides(AgentConfig(estimator="horizon:2"))
    assert (agent.estimator, agent.scripted_base) == ("horizon:2", "hold-biased@5")
    plain = AgentConfig()
    monkeypatch.delenv(ENV_BASE)
    assert choices.with_env_overrides(plain) is plain


@pytest.mark.parametrize(("env", "value"), [(ENV_ESTIMATOR, "bayes"), (ENV_BASE, "lazy")])
def test_a_bad_override_names_the_variable(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    env: str, value: str,
) -> None:  # fmt: skip
    monkeypatch.setenv(env, value)
    assert main(["daemon", "--config", str(toml(tmp_path, ""))]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert err.count(env) >= 1
    assert repr(value) in err


def test_a_daemon_from_a_file_runs_what_the_file_says(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The pieces ``run_daemon`` builds from a loaded config: its selector and its memory."""
    line = 'estimator = "horizon:3,centre,scale"\nscripted_base = "hold-biased"\nbeta = 0.8'
    cfg = load_config(toml(tmp_path, line), UavConfig)
    cfg = cfg.model_copy(update={"agent": cfg.agent.model_copy(update={"memory_path": None})})

    async def built(cfg: UavConfig) -> tuple[str, Estimator]:
        async with open_selector(cfg, cfg.uav) as (selector, info):
            assert isinstance(selector, DegradedScorer) or info.name == "scripted:reference"
            name = info.name
        memory = await AsyncExperienceMemory.from_config(cfg.agent)
        try:
            return name, memory.sync.estimator
        finally:
            await memory.aclose()

    assert asyncio.run(built(cfg)) == (
        "scripted:hold-biased",
        Estimator(3, centre=True, scale=True),
    )
    monkeypatch.setenv(ENV_BASE, "reference")  # the override, as `aeroweaver daemon` applies it
    over = cfg.model_copy(update={"agent": choices.with_env_overrides(cfg.agent)})
    assert asyncio.run(built(over))[0] == "scripted:reference"
    assert Base.parse(over.agent.scripted_base) == Base()
