"""Geofence upload over the mission protocol with mission_type FENCE.

MISSION_COUNT -> the vehicle asks for each item (MISSION_REQUEST_INT) -> MISSION_ITEM_INT ->
MISSION_ACK. Items: 5001 polygon inclusion vertices (param1 = vertex count), 5003 circle
inclusion (param1 = radius). The safety gate's rectangle becomes a 4-vertex inclusion
polygon, so the autopilot enforces the same fence as the daemon (two layers).
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass

from aeroweaver_edge.vehicle.mavlink.codec import mavlink
from aeroweaver_edge.vehicle.mavlink.geo import GeoOrigin
from aeroweaver_edge.vehicle.mavlink.link import FlightLink, LinkError

FENCE = mavlink.MAV_MISSION_TYPE_FENCE
POLYGON_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
CIRCLE_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION


@dataclass(frozen=True)
class FenceItem:
    command: int
    lat_e7: int
    lon_e7: int
    param1: float  # vertex count (polygon) or radius in m (circle)


def rectangle(
    origin: GeoOrigin, north: tuple[float, float], east: tuple[float, float]
) -> list[FenceItem]:
    """The inclusion polygon for a north/east box of the local frame (clockwise from SW)."""
    corners = [(north[0], east[0]), (north[1], east[0]), (north[1], east[1]), (north[0], east[1])]
    return [
        FenceItem(POLYGON_INCLUSION, *origin.to_global_e7(n, e), float(len(corners)))
        for n, e in corners
    ]


async def upload_fence(
    link: FlightLink, items: list[FenceItem], timeout_s: float = 0.5, retries: int = 4
) -> None:
    """Upload ``items`` as the vehicle's fence; LinkError if the vehicle does not accept."""
    sysid, compid = link.target
    mav = link.mav
    for _ in range(retries + 1):
        asked = link.expect("MISSION_REQUEST_INT", lambda m: m.mission_type == FENCE)
        asked_old = link.expect("MISSION_REQUEST", lambda m: m.mission_type == FENCE)
        acked = link.expect("MISSION_ACK", lambda m: m.mission_type == FENCE)
        link.send(mav.mission_count_encode(sysid, compid, len(items), FENCE))
        while True:
            done, _ = await asyncio.wait(
                {asked, asked_old, acked}, timeout=timeout_s, return_when=asyncio.FIRST_COMPLETED
            )
            if not done:
                break  # nothing came back: start the upload again
            if acked in done:
                for f in (asked, asked_old):
                    f.cancel()
                ack = acked.result()
                if ack.type != mavlink.MAV_MISSION_ACCEPTED:
                    raise LinkError(
                        f"fence upload refused by system {sysid}: MISSION_ACK {ack.type}"
                    )
                return
            req = (asked if asked in done else asked_old).result()
            for f in (asked, asked_old):
                if not f.done():
                    f.cancel()
            seq = int(req.seq)
            if not 0 <= seq < len(items):
                raise LinkError(f"fence upload: vehicle asked for item {seq} of {len(items)}")
            it = items[seq]
            asked = link.expect("MISSION_REQUEST_INT", lambda m: m.mission_type == FENCE)
            asked_old = link.expect("MISSION_REQUEST", lambda m: m.mission_type == FENCE)
            link.send(
                mav.mission_item_int_encode(
                    sysid,
                    compid,
                    seq,
                    mavlink.MAV_FRAME_GLOBAL,
                    it.command,
                    0,
                    1,
                    it.param1,
                    0.0,
                    0.0,
                    0.0,
                    it.lat_e7,
                    it.lon_e7,
                    0.0,
                    FENCE,
                )
            )
        for f in (asked, asked_old, acked):
            f.cancel()
    raise LinkError(f"fence upload to system {sysid}: no answer after {retries + 1} tries")
