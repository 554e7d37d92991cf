"""The console's web app (Starlette): the page, its data, server-sent events, operator actions.

Routes (all JSON unless said):

* ``GET /`` the page (HTML; carries this server's action token), ``/static/*`` its script
  and style (shipped in the package: no CDN);
* ``GET /api/meta`` mode (live/replay), task, arena, radii, mission, roles, goals, skills,
  who is alive, and whether operator actions are enabled (and if not, why);
* ``GET /api/frames?since=I`` the frames from index I (all by default);
* ``GET /api/events`` server-sent events: ``frame`` (the newest frame, at most one per
  round per client: a slow client skips to the newest and backfills with /api/frames),
  ``patch`` (decisions that came after their frame), ``meta``, ``approvals``;
* ``GET /api/approvals`` each UAV's approval level, pending actions and records;
* ``GET /api/operator/stop`` what a stop would do and the phrase that confirms it;
  ``POST /api/operator/stop`` ``{"confirm": "stop <mission>", "reason": ...}``;
* ``POST /api/operator/approve`` ``{"uav", "action", "ttl_s", "confirm": "approve <uav>
  <action>"}``.

Operator actions go through ``OperatorLink`` (operator keys only: the Commander stops the
mission, the UAV checks the approval); they need the typed confirmation, JSON, this page's
token (a page from another site cannot read it) and an allowed Host header (no DNS
rebinding). A read-only console (observer identity, or a replay) refuses them with 403.
"""

from __future__ import annotations

import json
import secrets
from collections.abc import AsyncIterator
from importlib import resources
from pathlib import Path
from typing import Any

from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import HTMLResponse, JSONResponse, Response, StreamingResponse
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from aeroweaver_edge.console.frames import FrameStore, encode
from aeroweaver_edge.safety.approval import VEHICLE_ACTION_SKILLS, parse_action
from aeroweaver_edge.safety.operator import OperatorError, OperatorLink, record_dict

KEEPALIVE_S = 10.0
PATCH_BATCH_S = 0.1
SKILL_OF = {kind: skill for skill, kind in VEHICLE_ACTION_SKILLS.items()}
MAX_TTL_S = 86_400.0


def static_dir() -> Path:
    return Path(str(resources.files("aeroweaver_edge.console") / "static"))


def stop_phrase(mission_id: str) -> str:
    return f"stop {mission_id}"


def approve_phrase(uav: str, skill: str) -> str:
    return f"approve {uav} {skill}"


class ConsoleApp:
    """State shared by the routes: the frame store and, when the console may act, the
    operator link (``read_only`` says why it may not)."""

    def __init__(
        self,
        store: FrameStore,
        *,
        operator: OperatorLink | None = None,
        read_only: str = "",
        allowed_hosts: list[str] | None = None,
    ) -> None:
        self.store = store
        self.operator = operator
        self.read_only = read_only if operator is None else ""
        if operator is None and not self.read_only:
            self.read_only = "no operator identity"
        self.token = secrets.token_urlsafe(24)
        self.allowed_hosts = allowed_hosts or ["127.0.0.1", "localhost", "::1"]
        self._page = (static_dir() / "index.html").read_text(encoding="utf-8")

    def starlette(self) -> Starlette:
        routes = [
            Route("/", self.index),
            Route("/favicon.ico", lambda _r: Response(status_code=204)),
            Route("/api/meta", self.meta),
            Route("/api/frames", self.frames),
            Route("/api/events", self.events),
            Route("/api/approvals", self.approvals),
            Route("/api/operator/stop", self.stop, methods=["GET", "POST"]),
            Route("/api/operator/approve", self.approve, methods=["POST"]),
            Mount("/static", app=StaticFiles(directory=static_dir()), name="static"),
        ]
        middleware = [Middleware(TrustedHostMiddleware, allowed_hosts=self.allowed_hosts)]
        return Starlette(routes=routes, middleware=middleware)

    # -- reading --------------------------------------------------------------------------

    async def index(self, request: Request) -> Response:
        page = self._page.replace("{{TOKEN}}", self.token)
        return HTMLResponse(page, headers={"Cache-Control": "no-store"})

    def meta_dict(self) -> dict[str, Any]:
        return {
            **self.store.meta,
            "operator": {"enabled": self.operator is not None, "read_only": self.read_only},
            "frames": self.store.last_index + 1,
        }

    async def meta(self, request: Request) -> Response:
        return _json(self.meta_dict())

    async def frames(self, request: Request) -> Response:
        try:
            since = int(request.query_params.get("since", "0"))
        except ValueError:
            return _error(400, "since must be a frame index")
        return Response(
            encode({"first": self.store.first, "frames": self.store.since(since)}),
            media_type="application/json",
        )

    async def approvals(self, request: Request) -> Response:
        return _json(self.store.approvals)

    async def events(self, request: Request) -> Response:
        try:
            last = int(request.query_params.get("after", "-1"))
        except ValueError:
            return _error(400, "after must be a frame index")
        return StreamingResponse(
            self._stream(last),
            media_type="text/event-stream",
            headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"},
        )

    async def _stream(self, last: int) -> AsyncIterator[str]:
        """One client's events: per wake-up at most the newest frame (coalesced), the
        decision patches since its cursor, and meta/approvals when they changed."""
        store = self.store
        patch_seq = store.patch_seq
        meta_v = approvals_v = -1
        yield "retry: 1000\n\n"
        while True:
            closed = store.closed  # one last pass after the close: the page learns it ended
            out: list[str] = []
            if store.meta_version != meta_v:
                meta_v = store.meta_version
                out.append(_event("meta", self.meta_dict()))
            if store.approvals_version != approvals_v:
                approvals_v = store.approvals_version
                out.append(_event("approvals", store.approvals))
            newest = store.last_index
            if newest > last and (frame := store.frame(newest)) is not None:
                last = newest
                out.append(_event("frame", frame))
            if store.patch_seq != patch_seq:
                for i, decisions in sorted(store.patches_since(patch_seq).items()):
                    out.append(_event("patch", {"i": i, "decisions": decisions}))
                patch_seq = store.patch_seq
            yield "".join(out) if out else ": keep-alive\n\n"
            if closed:
                return
            await store.wait_change(KEEPALIVE_S)
            if store.last_index == last and not store.closed:
                # Only decisions or status changed: let a burst of reports gather into one
                # event (a new frame is never held back).
                await store.wait_frame(PATCH_BATCH_S, last)

    # -- acting ---------------------------------------------------------------------------

    def _guard(self, request: Request) -> Response | OperatorLink:
        if self.operator is None:
            return _error(403, f"this console is read-only ({self.read_only})")
        if request.headers.get("x-aw-token") != self.token:
            return _error(403, "missing or wrong page token: reload the console page")
        return self.operator

    async def _body(self, request: Request) -> dict[str, Any] | Response:
        if request.headers.get("content-type", "").split(";")[0].strip() != "application/json":
            return _error(415, "send JSON (Content-Type: application/json)")
        try:
            body = json.loads(await request.body())
        except (json.JSONDecodeError, UnicodeDecodeError):
            return _error(400, "the body is not JSON")
        if not isinstance(body, dict):
            return _error(400, "the body must be a JSON object")
        return body

    async def stop(self, request: Request) -> Response:
        op = self._guard(request)
        if isinstance(op, Response):
            return op
        try:
            plan = await op.plan_stop()
        except OperatorError as exc:
            return _error(409, str(exc))
        phrase = stop_phrase(plan.mission_id)
        if request.method == "GET":
            return _json({"will": plan.describe(), "confirm": phrase})
        body = await self._body(request)
        if isinstance(body, Response):
            return body
        if body.get("confirm") != phrase:
            return _error(400, f"type {phrase!r} to confirm: {plan.describe()}")
        try:
            note = await op.stop(plan, str(body.get("reason") or "")[:200])
        except OperatorError as exc:
            return _error(504, str(exc))
        return _json({"stopped": plan.mission_id, "commander": note})

    async def approve(self, request: Request) -> Response:
        op = self._guard(request)
        if isinstance(op, Response):
            return op
        body = await self._body(request)
        if isinstance(body, Response):
            return body
        uav, action_text = str(body.get("uav", "")), str(body.get("action", ""))
        try:
            action = parse_action(action_text)
            ttl = float(body.get("ttl_s", 300))
        except (TypeError, ValueError) as exc:
            return _error(400, str(exc))
        if not 0 < ttl <= MAX_TTL_S:
            return _error(400, f"ttl_s must be within (0, {MAX_TTL_S:g}] seconds")
        phrase = approve_phrase(uav, action)
        if body.get("confirm") != phrase:
            return _error(
                400, f"type {phrase!r} to confirm: {uav} may then {action} within {ttl:g} s"
            )
        try:
            rec = await op.approve(uav, action, ttl)
        except OperatorError as exc:
            return _error(409, str(exc))
        return _json({"approved": record_dict(rec)})


def _event(kind: str, data: Any) -> str:
    return f"event: {kind}\ndata: {encode(data)}\n\n"


def _json(value: Any, status: int = 200) -> Response:
    return Response(encode(value), status_code=status, media_type="application/json")


def _error(status: int, message: str) -> Response:
    return JSONResponse({"error": message}, status_code=status)


__all__ = ["ConsoleApp", "approve_phrase", "static_dir", "stop_phrase"]
