"""Local NED metres <-> WGS84 degrees around an origin (flat earth: fine over a few km)."""

from __future__ import annotations

import math
from dataclasses import dataclass

EARTH_RADIUS_M = 6_378_137.0


@dataclass(frozen=True)
class GeoOrigin:
    lat_deg: float
    lon_deg: float
    alt_m: float = 0.0  # AMSL of the local frame's origin

    def to_global(self, north: float, east: float, down: float = 0.0) -> tuple[float, float, float]:
        lat = self.lat_deg + math.degrees(north / EARTH_RADIUS_M)
        lon = self.lon_deg + math.degrees(
            east / (EARTH_RADIUS_M * math.cos(math.radians(self.lat_deg)))
        )
        return lat, lon, self.alt_m - down

    def to_local(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        north = math.radians(lat - self.lat_deg) * EARTH_RADIUS_M
        east = (
            math.radians(lon - self.lon_deg) * EARTH_RADIUS_M * math.cos(math.radians(self.lat_deg))
        )
        return north, east, self.alt_m - alt

    def to_global_e7(self, north: float, east: float) -> tuple[int, int]:
        lat, lon, _ = self.to_global(north, east)
        return round(lat * 1e7), round(lon * 1e7)


DEFAULT_ORIGIN = GeoOrigin(47.397742, 8.545594, 488.0)
"""PX4 SITL's default home (Zurich), used by the emulator."""
