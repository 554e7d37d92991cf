"""The parameter protocol, read and set by name (PARAM_REQUEST_READ / PARAM_SET ->
PARAM_VALUE), with each autopilot's encoding of integer parameters."""

from __future__ import annotations

from aeroweaver_edge.vehicle.mavlink.codec import Message
from aeroweaver_edge.vehicle.mavlink.link import FlightLink, LinkError
from aeroweaver_edge.vehicle.mavlink.personality import Personality


def _name(msg: Message) -> str:
    pid = msg.param_id
    if isinstance(pid, bytes):
        pid = pid.decode("ascii", errors="replace")
    return str(pid).rstrip("\x00")


class ParamClient:
    def __init__(
        self, link: FlightLink, personality: Personality, timeout_s: float = 0.5, retries: int = 3
    ) -> None:
        self.link = link
        self.personality = personality
        self.timeout_s = timeout_s
        self.retries = retries
        self.types: dict[str, int] = {}

    async def get(self, name: str) -> float | None:
        """The parameter's value, or None if the vehicle never answered."""
        if len(name) > 16:
            raise ValueError(f"parameter names are at most 16 characters: {name!r}")
        sysid, compid = self.link.target
        for _ in range(self.retries + 1):
            fut = self.link.expect("PARAM_VALUE", lambda m: _name(m) == name)
            self.link.send(
                self.link.mav.param_request_read_encode(sysid, compid, name.encode(), -1)
            )
            msg = await self.link.wait_future(fut, self.timeout_s)
            if msg is not None:
                self.types[name] = int(msg.param_type)
                return self.personality.decode_param(float(msg.param_value), int(msg.param_type))
        return None

    async def set(self, name: str, value: float, ptype: int | None = None) -> float:
        """Set and return the value the vehicle echoes; LinkError if it never does."""
        if ptype is None:
            ptype = self.types.get(name)
            if ptype is None:
                if await self.get(name) is None:
                    raise LinkError(f"parameter {name} not found on system {self.link.sysid}")
                ptype = self.types[name]
        sysid, compid = self.link.target
        raw = self.personality.encode_param(value, ptype)
        for _ in range(self.retries + 1):
            fut = self.link.expect("PARAM_VALUE", lambda m: _name(m) == name)
            self.link.send(self.link.mav.param_set_encode(sysid, compid, name.encode(), raw, ptype))
            msg = await self.link.wait_future(fut, self.timeout_s)
            if msg is not None:
                return self.personality.decode_param(float(msg.param_value), int(msg.param_type))
        raise LinkError(f"PARAM_SET {name}: no PARAM_VALUE from system {self.link.sysid}")
