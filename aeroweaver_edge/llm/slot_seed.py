"""Compute a shared prompt prefix once and copy it into every cache slot that will use it.

The UAVs of one role share their system message (rules, mission, skill documents: ~430
tokens for coverage), but each llama.cpp slot keeps its own KV cache, so without help the
first decision of every UAV processes that prefix again, all of them at once in round 0.
``seed_slots`` processes a group's prefix once, in the group's first slot, saves that slot
to a file and restores the file into the group's other slots (llama-server's
``POST /slots/<id>?action=save|restore``, which needs ``--slot-save-path``; the embedded
server sets it). Restoring ~10 MB takes milliseconds. Best effort: any failure is logged
and the daemons then compute their prefixes themselves, as they would without seeding.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import httpx

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SlotGroup:
    """Cache slots whose prompts start with the same chat messages."""

    messages: Sequence[Mapping[str, str]]
    slots: Sequence[int]


async def seed_slots(
    server_root: str,
    model: str,
    groups: Sequence[SlotGroup],
    *,
    timeout_s: float = 300.0,
    transport: httpx.AsyncBaseTransport | None = None,
) -> int:
    """Prefill every group's slots with its prefix; returns how many slots were seeded."""
    seeded = 0
    async with httpx.AsyncClient(
        base_url=server_root.rstrip("/"), timeout=timeout_s, transport=transport
    ) as http:
        for index, group in enumerate(groups):
            if not group.slots:
                continue
            first, rest = group.slots[0], group.slots[1:]
            body = {
                "model": model,
                "messages": [dict(m) for m in group.messages],
                "max_tokens": 1,
                "temperature": 0,
                "id_slot": first,
            }
            name = f"seed-{index}.bin"
            try:
                (await http.post("/v1/chat/completions", json=body)).raise_for_status()
                seeded += 1
                if rest:
                    save = await http.post(
                        f"/slots/{first}", params={"action": "save"}, json={"filename": name}
                    )
                    save.raise_for_status()
                for slot in rest:
                    restore = await http.post(
                        f"/slots/{slot}", params={"action": "restore"}, json={"filename": name}
                    )
                    restore.raise_for_status()
                    seeded += 1
            except httpx.HTTPError as exc:
                log.warning(
                    "could not seed cache slots %s at %s (%s); each UAV computes its own "
                    "prompt prefix instead",
                    list(group.slots),
                    server_root,
                    _why(exc),
                )
    return seeded


def _why(exc: httpx.HTTPError) -> str:
    if isinstance(exc, httpx.HTTPStatusError):
        text = " ".join(exc.response.text.split())[:200]
        return f"HTTP {exc.response.status_code} from {exc.request.url.path}: {text}"
    return f"{type(exc).__name__}: {exc}"
