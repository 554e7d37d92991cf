"""The LLM selector: one chat completion per decision, first-token logprobs per label.

It never raises into the round loop: any client failure becomes
``LabelScores(logprobs={}, error=...)`` and ``scoring.choose`` turns that into a hold.
How logprobs are used follows the endpoint probe (``llm.probe``):

* ``ok`` — logprobs drive the choice and the experience correction;
* ``rejected`` — requests go out *without* logprob parameters (they would be refused every
  round) and the generated text label is used; correction off;
* ``degenerate`` / ``low_label_mass`` — logprobs are still requested (harmless, useful for
  diagnostics) but the generated text label decides; correction off;
* no verdict (``unreachable``, ``timeout``, ``auth``, ... or no probe) — unknown: the first
  real answer decides the class, so an endpoint that was down at start-up is not stuck
  without correction. A 400/422 while the class is unknown is retried once without logprob
  parameters: only if that answers were logprobs the cause, and only a refusal that names
  them or repeats decides ``rejected`` (``probe.refusal_verdict``; one transient 400 must
  not switch them off for the session, that round uses the text label); a refusal that
  stays (context length, wrong model) is an LLM failure of that round and decides nothing.
"""

from __future__ import annotations

import logging
import string
from dataclasses import replace
from typing import Any

from aeroweaver_edge.agent.prompt import OptionPlacement, PromptLimits, build_messages
from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.contracts.ports import DecisionRequest
from aeroweaver_edge.contracts.scores import LabelScores
from aeroweaver_edge.llm.client import CallTag, ChatClient, LLMError
from aeroweaver_edge.llm.logprobs import parse_label_scores
from aeroweaver_edge.llm.probe import (
    ProbeResult,
    classify_response,
    may_be_logprobs,
    refusal_verdict,
)

log = logging.getLogger(__name__)

LIVE_MIN_LABEL_MASS = 0.05
"""Label-mass floor when the class is decided from a live decision instead of the probe
prompt. Lower than the probe's: one real prompt varies more (SmolLM2 put 0.27 on labels
for one decision prompt and 0.74 on the probe), while a base model stays near 0.01."""


class LLMSelector:
    """``Selector`` backed by an OpenAI-compatible endpoint."""

    def __init__(
        self,
        client: ChatClient,
        cfg: LLMConfig,
        probe_result: ProbeResult | None = None,
        *,
        owns_client: bool = True,
        limits: PromptLimits | None = None,
        agent: str | None = None,
    ) -> None:
        self.client = client
        self.cfg = cfg
        self.probe = probe_result
        self.name = f"llm:{cfg.model}"
        self._owns_client = owns_client
        self._limits = limits
        self.agent = agent  # ledger name; default: the observing UAV's id
        self._refusals = 0  # unexplained logprob refusals so far (see refusal_verdict)
        self._placement = OptionPlacement()  # options before or after the history, per UAV
        if probe_result is not None and not probe_result.ok:
            log.warning("%s", probe_result.line())  # says: correction off, text label

    @property
    def settled(self) -> bool:
        """Whether the endpoint's logprob class is known (a verdict, not a failure)."""
        return self.probe is not None and self.probe.verdict

    @property
    def requests_sent(self) -> int:
        """HTTP requests this selector's client has sent (the daemon's ``llm_calls``)."""
        return self.client.requests_sent

    @property
    def llm_class(self) -> str:
        return self.probe.kind if self.probe is not None else "unprobed"

    @property
    def correction_on(self) -> bool:
        return not self.settled or (self.probe is not None and self.probe.correction_on)

    def _params(self, *, logprobs: bool = True) -> dict[str, Any]:
        params: dict[str, Any] = {"max_tokens": 1, "temperature": self.cfg.temperature}
        if self.cfg.slot is not None:  # llama-server: keep this agent's prefix in its own slot
            params["id_slot"] = self.cfg.slot
        if logprobs and not (self.probe is not None and self.probe.kind == "rejected"):
            params.update(logprobs=True, top_logprobs=self.cfg.top_logprobs)
        return params

    def _failed(self, exc: LLMError) -> LabelScores:
        return LabelScores(
            logprobs={},
            error=str(exc),
            extra={"error_kind": type(exc).__name__, "probe": self.llm_class},
        )

    def _settle(self, probe: ProbeResult) -> None:
        self.probe = probe
        level = logging.INFO if probe.ok else logging.WARNING
        log.log(level, "%s (decided from a live decision)", probe.line())

    @property
    def label_budget(self) -> int | None:
        """Leading letters A, B, ... that the model's tokenizer keeps as one token each (from
        the probe's ``/tokenize`` check); a label of two tokens has no first-token logprob."""
        letters = self.probe.single_token_labels if self.probe is not None else None
        if letters is None:
            return None
        budget = 0
        for expected, letter in zip(string.ascii_uppercase, sorted(letters), strict=False):
            if expected != letter:
                break
            budget += 1
        return budget

    async def score(self, request: DecisionRequest) -> LabelScores:
        labels = [c.label for c in request.candidates]
        if not labels:
            return LabelScores(logprobs={}, error="no candidates to choose from")
        obs = request.observation
        tag = CallTag(self.agent or obs.uav, request.role, obs.episode, obs.round, "decide")
        params = self._params()
        options_last = self._placement.options_last(request)
        messages = build_messages(request, limits=self._limits, options_last=options_last)
        try:
            try:
                result = await self.client.chat(messages, tag=tag, **params)
            except LLMError as exc:
                if self.settled or "logprobs" not in params or not may_be_logprobs(exc):
                    return self._failed(exc)
                plain = self._params(logprobs=False)
                try:  # the same request without logprob parameters tells what was refused
                    result = await self.client.chat(messages, tag=tag, **plain)
                except LLMError:
                    return self._failed(exc)  # refused either way: not about logprobs
                verdict = refusal_verdict(exc, self._refusals)
                self._refusals += 1
                if verdict is not None:
                    self._settle(replace(verdict, model=self.client.model))
                params = plain
        except Exception as exc:  # never into the round loop
            log.exception("LLM selector failed unexpectedly")
            return LabelScores(logprobs={}, error=f"unexpected {type(exc).__name__}: {exc}")
        try:
            if not self.settled and "logprobs" in params:
                self._settle(
                    classify_response(
                        result.raw,
                        labels,
                        LIVE_MIN_LABEL_MASS,
                        endpoint=self.client.endpoint,
                        model=self.client.model,
                    )
                )
            scores = parse_label_scores(
                result.raw,
                labels,
                self.cfg.top_logprobs,
                usage=result.usage,
                latency_s=result.latency_s,
                use_logprobs=self.correction_on and "logprobs" in params,
            )
        except Exception as exc:  # a parser bug must not stop the UAV either
            log.exception("could not parse the LLM answer")
            return LabelScores(logprobs={}, error=f"unparseable answer: {type(exc).__name__}")
        kind = self.probe.kind if self.probe is not None else "unprobed"
        return replace(scores, extra={**scores.extra, "probe": kind})

    async def aclose(self) -> None:
        if self._owns_client:
            await self.client.aclose()
