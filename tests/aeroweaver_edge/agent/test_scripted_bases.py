"""Degraded scripted bases (issue 24): hold-biased, position-biased and noisy, each a
seeded, reproducible function of the decision, selectable by name and from the daemon's
environment."""

from __future__ import annotations

import dataclasses
import math

import pytest

from aeroweaver_edge.agent.candidates import build_candidates
from aeroweaver_edge.agent.scripted import (
    ENV_BASE,
    HOLD_BIAS,
    POSITION_BIAS,
    Base,
    DegradedScorer,
    ReferenceScorer,
    scorer_for,
    scorer_from_env,
)
from aeroweaver_edge.contracts.observation import Observation, VehicleState
from aeroweaver_edge.contracts.ports import DecisionRequest
from aeroweaver_edge.contracts.selector_specs import NOISE_SD
from aeroweaver_edge.contracts.skill_api import SkillContext
from aeroweaver_edge.contracts.wire import Entity
from aeroweaver_edge.skills import load_skills

CTX = SkillContext(uav="uav0", uav_index=0, role="searcher", task="coverage")
ACTIVE = ["cover_landmark", "explore_local", "return_in_bounds", "hold_position"]
LANDMARKS = (
    Entity(id="L0", kind="landmark", pos=(10.0, 0.0, -5.0)),
    Entity(id="L1", kind="landmark", pos=(0.0, 30.0, -5.0)),
)


REG = load_skills()


def request(rnd: int = 3, episode: int = 0, uav: str = "uav0") -> DecisionRequest:
    o = Observation(
        uav=uav,
        episode=episode,
        round=rnd,
        own=VehicleState((0.0, 0.0, -5.0), (0.0, 0.0, 0.0)),
        entities=LANDMARKS,
    )
    cs = build_candidates(REG, ACTIVE, o, CTX)
    return DecisionRequest(
        observation=o, mission_text="cover", role="searcher", local_goal="cover one",
        constraints=(), skill_docs=(), observation_text="", candidates=cs.candidates,
        task="coverage",
    )  # fmt: skip


def hold_label(req: DecisionRequest) -> str:
    return next(c.label for c in req.candidates if c.skill == "hold_position")


async def logits(base: str, req: DecisionRequest) -> dict[str, float]:
    return dict((await scorer_for(base).score(req)).logprobs)


def differences(a: dict[str, float], b: dict[str, float]) -> dict[str, float]:
    """Per label, how much ``a`` raised it relative to ``b`` (log-softmax shifts cancel)."""
    first = next(iter(a))
    return {k: (a[k] - a[first]) - (b[k] - b[first]) for k in a}


def test_parse_and_names() -> None:
    assert Base.parse("hold-biased") == Base("hold-biased")
    assert Base.parse("noisy").name == "noisy"
    assert Base.parse("noisy:0.5") == Base("noisy", 0.5)
    assert Base.parse("noisy:0.5").name == "noisy:0.5"
    assert isinstance(scorer_for("reference"), ReferenceScorer)
    assert scorer_for("position-biased").name == "scripted:position-biased"
    for bad in ("", "biased", "noisy:0", "noisy:x", "noisy:nan", "hold-biased:2"):
        with pytest.raises(ValueError, match="scripted base"):
            Base.parse(bad)


async def test_hold_biased_raises_hold_by_exactly_the_bias() -> None:
    req = request()
    d = differences(await logits("hold-biased", req), await logits("reference", req))
    hold = hold_label(req)
    assert hold != req.candidates[0].label  # differences are against the first label
    for label, x in d.items():
        assert x == pytest.approx(HOLD_BIAS if label == hold else 0.0), label


async def test_position_biased_raises_one_seeded_option_per_decision() -> None:
    ref = await logits("reference", request())
    raised = []
    for rnd in range(24):
        req = request(rnd)
        lp = await logits("position-biased", req)
        assert lp == await logits("position-biased", req)  # reproducible
        # exactly one label gained POSITION_BIAS against every other
        gains = {k: lp[k] - ref[k] for k in lp}
        top = max(gains, key=lambda k: gains[k])
        others = [v for k, v in gains.items() if k != top]
        assert all(gains[top] - v == pytest.approx(POSITION_BIAS) for v in others)
        raised.append(top)
    assert len(set(raised)) == len(request().candidates)  # the order changes every round


async def test_noise_is_seeded_by_the_decision() -> None:
    req = request()
    a = await logits("noisy", req)
    assert a == await logits("noisy", req)
    assert a != await logits("noisy", request(rnd=4))
    assert a != await logits("noisy", request(uav="uav1"))
    moved = request()
    moved = dataclasses.replace(
        moved,
        observation=dataclasses.replace(
            moved.observation, own=VehicleState((1.0, 0.0, -5.0), (0.0, 0.0, 0.0))
        ),
    )
    assert a != await logits("noisy", moved)  # another layout, other noise


async def test_noise_has_the_configured_spread() -> None:
    ref = await logits("reference", request())
    devs: list[float] = []
    for rnd in range(300):
        lp = await logits("noisy", request(rnd=rnd))
        d = differences(lp, ref)
        devs += [v for k, v in d.items() if k != next(iter(d))]
    sd = math.sqrt(sum(x * x for x in devs) / len(devs))
    assert sd == pytest.approx(NOISE_SD * math.sqrt(2), rel=0.1)  # difference of two draws


def test_scorer_from_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ENV_BASE, raising=False)
    assert type(scorer_from_env()) is ReferenceScorer
    monkeypatch.setenv(ENV_BASE, "hold-biased")
    s = scorer_from_env()
    assert isinstance(s, DegradedScorer)
    assert s.name == "scripted:hold-biased"
    monkeypatch.setenv(ENV_BASE, "bogus")
    with pytest.raises(ValueError, match="bogus"):
        scorer_from_env()


async def test_temperature_keeps_the_argmax_and_shrinks_the_gaps() -> None:
    assert Base.parse("hold-biased@5") == Base("hold-biased", temperature=5.0)
    assert Base.parse("noisy:1@2").name == "noisy:1@2"
    for bad in ("hold-biased@0", "hold-biased@", "noisy:@2", "x@2"):
        with pytest.raises(ValueError, match="scripted base"):
            Base.parse(bad)
    req = request()
    sure = await logits("hold-biased", req)
    soft = await logits("hold-biased@5", req)
    assert max(sure, key=lambda k: sure[k]) == max(soft, key=lambda k: soft[k])
    first = next(iter(sure))
    for k in sure:
        assert soft[k] - soft[first] == pytest.approx((sure[k] - sure[first]) / 5)
