"""The optional ``mavsdk`` Vehicle backend (``pip install aeroweaver-edge[mavsdk]``).

MAVSDK 4.x is a ctypes binding over a bundled C library: ``Mavsdk(Configuration...)``,
``add_any_connection``, ``first_autopilot``; ``System()`` is gone (docs/notes/mavlink.md).
Warnings from the notes that shape this module:

* MAVSDK re-sends the last offboard setpoint at 20 Hz from its own C++ thread, so a stalled
  event loop would leave the vehicle flying a stale velocity. A watchdog *thread* here
  forces the autopilot's hold when our asyncio refresher (alive only while the loop runs
  and the agent's lease holds) stops refreshing.
* Blocking calls go to a dedicated executor (the default one has 6 workers on 2 cores and
  was starved by unanswered commands); telemetry comes from subscriptions, not getters.
* MAVSDK cannot sign MAVLink 2 messages: ``vehicle.signing_key`` is refused here.
* One ``Mavsdk`` per vehicle, speaking as the vehicle's system id with compid 191.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import functools
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from aeroweaver_edge.contracts.observation import VehicleState
from aeroweaver_edge.contracts.ports import Health
from aeroweaver_edge.contracts.wire import VehicleStatus
from aeroweaver_edge.vehicle.errors import VehicleError
from aeroweaver_edge.vehicle.mavlink import companion_failsafe
from aeroweaver_edge.vehicle.mavlink.geo import GeoOrigin
from aeroweaver_edge.vehicle.mavlink.personality import PERSONALITIES, ParamRule

if TYPE_CHECKING:
    from aeroweaver_edge.config import SafetyConfig, VehicleConfig

log = logging.getLogger(__name__)
T = TypeVar("T")
WATCHDOG_PERIOD_S = 0.05


def _import_mavsdk() -> Any:
    try:
        import mavsdk
        from mavsdk import asyncio as mavsdk_asyncio
    except ImportError:
        raise VehicleError(
            "vehicle.backend 'mavsdk' needs the optional extra: "
            "pip install 'aeroweaver-edge[mavsdk]'"
        ) from None
    if not str(getattr(mavsdk, "__version__", "0")).startswith("4."):
        raise VehicleError(f"mavsdk 4.x required, found {getattr(mavsdk, '__version__', '?')}")
    _route_mavsdk_log(mavsdk)
    return mavsdk_asyncio


MAVSDK_LOG = logging.getLogger("mavsdk")
_MAVSDK_LEVELS = (logging.DEBUG, logging.DEBUG, logging.WARNING, logging.ERROR)  # its 0..3


def _route_mavsdk_log(mavsdk: Any) -> None:
    """MAVSDK's C library prints its log lines on stdout by itself; send them through
    Python logging instead (logger ``mavsdk``: its INFO chatter at DEBUG), so the
    process's log level and handlers decide -- nothing reaches a terminal at --quiet.
    Called from MAVSDK's own threads; logging is thread-safe."""
    subscribe = getattr(mavsdk, "log_subscribe", None)
    if subscribe is None or getattr(_route_mavsdk_log, "done", False):
        return

    def forward(level: int, message: str, file: str | None, line: int) -> bool:
        lvl = _MAVSDK_LEVELS[level] if 0 <= int(level) < len(_MAVSDK_LEVELS) else logging.INFO
        MAVSDK_LOG.log(lvl, "%s", message)
        return True  # handled: MAVSDK prints nothing itself

    subscribe(forward)
    _route_mavsdk_log.done = True  # type: ignore[attr-defined]


class MavsdkVehicle:
    def __init__(self, cfg: VehicleConfig, safety: SafetyConfig, name: str = "uav") -> None:
        if cfg.url is None:
            raise ValueError("vehicle.url is required for the mavsdk backend")
        if cfg.signing_key:
            raise VehicleError(
                f"{name}: MAVSDK cannot sign MAVLink 2 (MAVSDK #1060); use backend 'mavlink' "
                "for a signed link"
            )
        self.cfg = cfg
        self.safety = safety
        self.name = name
        self.sysid = cfg.sysid or 1
        self._executor = concurrent.futures.ThreadPoolExecutor(
            max_workers=2, thread_name_prefix=f"{name}-mavsdk"
        )
        self._mavsdk: Any = None
        self._system: Any = None
        self._action: Any = None
        self._offboard: Any = None
        self._telemetry: Any = None
        self._param: Any = None
        self._geofence: Any = None
        self._types: Any = None
        self._subs: list[tuple[Any, Any]] = []
        # telemetry, updated on the loop from MAVSDK's callback thread
        self.pos: tuple[float, float, float] | None = None
        self.vel: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.pos_at = -math.inf
        self.armed = False
        self.in_air = False
        self.flight_mode = "UNKNOWN"
        self.connected = False
        self._was_fresh = True  # telemetry fresh at the last check (logs link lost / up)
        self.home: Any = None
        self.glob: tuple[float, float, float] | None = None
        self.refused: str | None = None
        self.problems: list[str] = []
        # offboard under a lease; the watchdog thread reads these two floats
        self._offboard_on = False
        self._lease_until = 0.0
        self._last_refresh = 0.0
        self._refresher: asyncio.Task[None] | None = None
        self._stop = threading.Event()
        self._watchdog: threading.Thread | None = None
        self.watchdog_holds = 0
        self._lock = asyncio.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None

    # -- plumbing ---------------------------------------------------------------------------

    async def _call(self, fn: Callable[[], T]) -> T:
        """A blocking MAVSDK call on our own executor, bounded in time."""
        loop = asyncio.get_running_loop()
        try:
            async with asyncio.timeout(
                self.cfg.command_timeout_s * (self.cfg.command_retries + 1) + 2.5
            ):
                return await loop.run_in_executor(self._executor, fn)
        except TimeoutError:
            raise VehicleError(f"{self.name}: MAVSDK call timed out") from None
        except VehicleError:
            raise
        except Exception as exc:  # MAVSDK raises ActionError, OffboardError, ...
            raise VehicleError(f"{self.name}: {type(exc).__name__}: {exc}") from None

    def _threadsafe(self, fn: Callable[..., None]) -> Callable[..., None]:
        loop = self._loop
        assert loop is not None

        def cb(data: Any, _ud: Any = None) -> None:
            with contextlib.suppress(RuntimeError):  # loop closed during shutdown
                loop.call_soon_threadsafe(fn, data)

        return cb

    # -- lifecycle --------------------------------------------------------------------------

    async def start(self) -> None:
        try:
            await self._start()
        except BaseException:
            await self.aclose()
            raise

    async def _start(self) -> None:
        m = _import_mavsdk()
        self._loop = asyncio.get_running_loop()
        from mavsdk.plugins.action import Action
        from mavsdk.plugins.geofence import Geofence
        from mavsdk.plugins.offboard import Offboard
        from mavsdk.plugins.param import Param
        from mavsdk.plugins.telemetry import Telemetry

        config = m.Configuration.create_manual(self.sysid, 191, True)
        self._mavsdk = m.Mavsdk(config)
        await self._mavsdk.add_any_connection(self.cfg.url)
        system = await self._mavsdk.first_autopilot(timeout_s=self.cfg.connect_timeout_s)
        if system is None:
            raise VehicleError(
                f"{self.name}: no autopilot on {self.cfg.url} "
                f"within {self.cfg.connect_timeout_s:g} s"
            )
        self._system = system
        raw = system._system
        # Plugins right after discovery, telemetry by subscription (docs/notes/mavlink.md).
        self._telemetry = Telemetry(raw)
        self._action = Action(raw)
        self._offboard = Offboard(raw)
        self._param = Param(raw)
        self._geofence = Geofence(raw)
        t = self._telemetry
        self._subs = [
            (t, t.subscribe_position_velocity_ned(self._threadsafe(self._on_pv))),
            (t, t.subscribe_armed(self._threadsafe(self._on_armed))),
            (t, t.subscribe_in_air(self._threadsafe(self._on_in_air))),
            (t, t.subscribe_flight_mode(self._threadsafe(self._on_mode))),
            (t, t.subscribe_home(self._threadsafe(self._on_home))),
            (t, t.subscribe_position(self._threadsafe(self._on_position))),
        ]
        self.connected = True
        deadline = time.monotonic() + self.cfg.connect_timeout_s
        while self.pos is None:
            if time.monotonic() > deadline:
                raise VehicleError(f"{self.name}: no position telemetry from MAVSDK")
            await asyncio.sleep(0.02)
        await self._preflight()
        self._refresher = asyncio.create_task(self._refresh(), name=f"{self.name}-mavsdk-lease")
        self._watchdog = threading.Thread(
            target=self._watch, name=f"{self.name}-mavsdk-watchdog", daemon=True
        )
        self._watchdog.start()
        log.info("%s: MAVSDK connected on %s", self.name, self.cfg.url)

    async def aclose(self) -> None:
        self._stop.set()
        if self._refresher is not None:
            self._refresher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._refresher
        if self._watchdog is not None:
            await asyncio.to_thread(self._watchdog.join, 2.0)
        self._subs.clear()  # destroying a plugin ends its subscriptions
        for plugin in (self._offboard, self._action, self._param, self._geofence, self._telemetry):
            if plugin is not None:
                with contextlib.suppress(Exception):
                    plugin.destroy()
        if self._mavsdk is not None:
            with contextlib.suppress(Exception):
                await self._mavsdk.destroy()
        self._executor.shutdown(wait=False, cancel_futures=True)

    # -- telemetry callbacks (on the loop) --------------------------------------------------

    def _on_pv(self, pv: Any) -> None:
        self.pos = (pv.position.north_m, pv.position.east_m, pv.position.down_m)
        self.vel = (pv.velocity.north_m_s, pv.velocity.east_m_s, pv.velocity.down_m_s)
        self.pos_at = time.monotonic()

    def _on_armed(self, armed: bool) -> None:
        self.armed = bool(armed)

    def _on_in_air(self, in_air: bool) -> None:
        self.in_air = bool(in_air)

    def _on_mode(self, mode: Any) -> None:
        self.flight_mode = getattr(mode, "name", str(mode))
        if self.flight_mode != "OFFBOARD":
            self._offboard_on = False

    def _on_home(self, home: Any) -> None:
        self.home = home

    def _on_position(self, p: Any) -> None:
        if math.isfinite(p.latitude_deg) and math.isfinite(p.longitude_deg):
            self.glob = (p.latitude_deg, p.longitude_deg, p.absolute_altitude_m)

    # -- preflight ----------------------------------------------------------------------------

    async def _read_param(self, name: str) -> float | None:
        getters: list[Callable[[str], Any]] = [
            self._param.get_param_int,
            self._param.get_param_float,
        ]
        for getter in getters:
            with contextlib.suppress(VehicleError):
                return float(await self._call(functools.partial(getter, name)))
        return None

    async def get(self, name: str) -> float | None:
        """``companion_failsafe.Params``: a parameter by name (None: not answered)."""
        return await self._read_param(name)

    async def set(self, name: str, value: float) -> float:
        """``companion_failsafe.Params``: write as an int, else as a float; the value read back."""
        p = self._param
        try:
            await self._call(functools.partial(p.set_param_int, name, int(value)))
            return float(await self._call(functools.partial(p.get_param_int, name)))
        except VehicleError:
            await self._call(functools.partial(p.set_param_float, name, float(value)))
            return float(await self._call(functools.partial(p.get_param_float, name)))

    async def _preflight(self) -> None:
        from mavsdk.plugins.geofence import FenceType, GeofenceData, Point, Polygon

        # MAVSDK maps modes itself; the failsafe names checked are PX4's (docs/flight.md)
        fs = await companion_failsafe.configure(
            self, "px4", self.sysid, self.cfg.companion_failsafe, self.cfg.companion_loss_s
        )
        self.problems.extend(fs.problems)
        if fs.ok:
            done = f" (set {', '.join(fs.changed)})" if fs.changed else " (as found)"
            log.info("%s: companion-loss failsafe: %s%s", self.name, fs.summary, done)
        pers = PERSONALITIES["px4"]()
        rules: tuple[ParamRule, ...] = pers.failsafe_rules
        for rule in rules:
            problem = rule.check(await self._read_param(rule.name))
            if problem:
                self.problems.append(problem)
        origin = await self._origin()
        if self.cfg.upload_fence and origin is not None:
            s = self.safety
            corners = [
                (s.geofence_north_m[0], s.geofence_east_m[0]),
                (s.geofence_north_m[1], s.geofence_east_m[0]),
                (s.geofence_north_m[1], s.geofence_east_m[1]),
                (s.geofence_north_m[0], s.geofence_east_m[1]),
            ]
            points = [Point(*origin.to_global(n, e)[:2]) for n, e in corners]
            data = GeofenceData(polygons=[Polygon(points, FenceType.INCLUSION)], circles=[])
            try:
                await self._call(lambda: self._geofence.upload_geofence(data))
            except VehicleError as exc:
                self.problems.append(f"geofence not uploaded: {exc}")
        elif self.cfg.upload_fence:
            self.problems.append("geofence not uploaded: no global position to anchor it")
        for p in self.problems:
            log.warning("%s: preflight: %s", self.name, p)
        if self.problems and self.cfg.failsafe_policy == "refuse":
            self.refused = "; ".join(self.problems)

    async def _origin(self) -> GeoOrigin | None:
        """The local frame's geodetic origin from one global + local position pair (the
        fence is given in the local frame; home need not be its origin)."""
        for _ in range(40):
            if self.glob is not None and self.pos is not None:
                lat, lon, alt = self.glob
                n, e, d = self.pos
                return GeoOrigin(*GeoOrigin(lat, lon, alt).to_global(-n, -e, -d))
            await asyncio.sleep(0.05)
        return None

    # -- lease refresher and watchdog -----------------------------------------------------------

    async def _refresh(self) -> None:
        period = 1.0 / self.cfg.setpoint_hz
        while True:
            await asyncio.sleep(period)
            now = time.monotonic()
            if not self._offboard_on:
                continue
            if now <= self._lease_until:
                self._last_refresh = now
            # else: lease over; the watchdog thread sees the refresh age and holds

    def _watch(self) -> None:
        """Runs in its own thread: holds the vehicle if the loop or the agent went silent."""
        # Like PX4's COM_OF_LOSS_T: half the lease (1 s by default), at least 3 periods.
        grace = max(3.0 / self.cfg.setpoint_hz, 0.5 * self.cfg.lease_s)
        while not self._stop.wait(WATCHDOG_PERIOD_S):
            if not self._offboard_on:
                continue
            if time.monotonic() - self._last_refresh > grace:
                self._offboard_on = False
                self.watchdog_holds += 1
                log.warning(
                    "%s: setpoints not refreshed: forcing hold from the watchdog", self.name
                )
                try:
                    self._offboard.stop()  # MAVSDK: stop re-sending and switch to Hold
                except Exception:
                    with contextlib.suppress(Exception):
                        self._action.hold()

    # -- the Vehicle port ---------------------------------------------------------------------

    def _fresh(self) -> bool:
        fresh = self.connected and time.monotonic() - self.pos_at <= self.cfg.link_timeout_s
        if self.connected and fresh != self._was_fresh:
            self._was_fresh = fresh  # for the operator's log: link down / up, once each
            if fresh:
                log.warning("%s: MAVSDK telemetry back: link up", self.name)
            else:
                log.warning("%s: no MAVSDK telemetry for %.1f s: link lost", self.name,
                            time.monotonic() - self.pos_at)  # fmt: skip
        return fresh

    async def state(self) -> VehicleState:
        if self.pos is None:
            raise VehicleError(f"{self.name}: no position telemetry yet")
        return VehicleState(self.pos, self.vel, armed=self.armed, in_air=self.in_air)

    def telemetry(self) -> VehicleStatus | None:
        """Mode and armed as MAVSDK last reported them (observers); no battery feed here."""
        if self.pos is None:
            return None
        return VehicleStatus(
            pos=self.pos, vel=self.vel, armed=self.armed, in_air=self.in_air,
            mode=self.flight_mode[:64],
        )  # fmt: skip

    async def health(self) -> Health:
        if not self._fresh():
            return Health(False, "telemetry stale or link lost")
        if self.refused:
            return Health(False, f"refused to arm: {self.refused}")
        return Health(True, f"mavsdk {self.flight_mode}")

    def _require(self) -> None:
        if not self._fresh():
            raise VehicleError(f"{self.name}: link lost or telemetry stale; no new motion")

    async def _until(self, cond: Callable[[], bool], timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not cond():
            if time.monotonic() > deadline:
                raise VehicleError(f"{self.name}: {what} not confirmed in {timeout_s:g} s")
            await asyncio.sleep(0.01)

    async def arm(self) -> None:
        if self.refused:
            raise VehicleError(f"{self.name}: refusing to arm: {self.refused}")
        self._require()
        if self.armed:
            return
        if self.in_air:
            raise VehicleError(f"{self.name}: refusing to arm a vehicle that reports in air")
        await self._call(self._action.arm)
        await self._until(lambda: self.armed, 2.0, "arming")

    async def takeoff(self, altitude_m: float) -> None:
        self._require()
        if self.in_air:
            raise VehicleError(f"{self.name}: refusing to take off: already in the air")
        await self._call(lambda: self._action.set_takeoff_altitude(float(altitude_m)))
        await self._call(self._action.takeoff)

    async def _offboard_velocity(self, n: float, e: float, d: float) -> None:
        from mavsdk.plugins.offboard import VelocityNedYaw

        await self._call(lambda: self._offboard.set_velocity_ned(VelocityNedYaw(n, e, d, 0.0)))

    async def _motion(self, send: Callable[[], Any]) -> None:
        if self.refused:
            raise VehicleError(f"{self.name}: no motion: {self.refused}")
        self._require()
        if not (self.armed and self.in_air):
            raise VehicleError(f"{self.name}: no motion on the ground")
        now = time.monotonic()
        self._lease_until = now + self.cfg.lease_s
        self._last_refresh = now
        async with self._lock:
            for _ in range(2):  # the watchdog thread may stop offboard while we send
                if not self._offboard_on or self.flight_mode != "OFFBOARD":
                    await self._offboard_velocity(0.0, 0.0, 0.0)  # zero setpoint first
                    await asyncio.sleep(0.5)
                    self._last_refresh = time.monotonic()
                    await self._call(self._offboard.start)
                    self._last_refresh = time.monotonic()
                    self._offboard_on = True
                await send()
                if self._offboard_on:
                    return
            raise VehicleError(f"{self.name}: offboard stopped by the watchdog twice")

    async def set_velocity(self, north: float, east: float, down: float) -> None:
        if not all(math.isfinite(v) for v in (north, east, down)):
            raise VehicleError(f"{self.name}: non-finite velocity")
        await self._motion(lambda: self._offboard_velocity(north, east, down))

    async def goto(self, north: float, east: float, down: float) -> None:
        from mavsdk.plugins.offboard import PositionNedYaw

        if not all(math.isfinite(v) for v in (north, east, down)):
            raise VehicleError(f"{self.name}: non-finite position")
        await self._motion(
            lambda: self._call(
                lambda: self._offboard.set_position_ned(PositionNedYaw(north, east, down, 0.0))
            )
        )

    async def hold(self) -> None:
        self._require()
        if not self.in_air:
            return
        if self._offboard_on and self.flight_mode == "OFFBOARD":
            now = time.monotonic()
            self._lease_until = now + self.cfg.lease_s
            self._last_refresh = now
            await self._offboard_velocity(0.0, 0.0, 0.0)
            return
        if self.flight_mode in ("HOLD", "LAND", "RETURN_TO_LAUNCH", "TAKEOFF"):
            return
        await self._call(self._action.hold)

    async def land(self) -> None:
        self._offboard_on = False
        self._require()
        await self._call(self._action.land)

    async def return_home(self) -> None:
        self._offboard_on = False
        self._require()
        await self._call(self._action.return_to_launch)
