"""What may stop a real flight, checked before it and at every frame of it.

A flight controller in a room is not a simulation: every way the ground side can lose the
vehicle must end the flight, and the firmware's own failsafe is the backstop when the ground
side itself is gone. :class:`SafetyMonitor` watches what the ground side knows at each frame
— the last motion-capture pose and when it arrived, the last answer over the link, the battery
the firmware reports, the operator's kill — and :meth:`SafetyMonitor.check` names the first
reason to stop (:class:`StopReason`) or None. :func:`preflight` lists what forbids a take-off.

The monitor decides; it does not act. The plant that owns the link acts on a reason: disarm
at once (kill, geofence, motion-capture loss) or stop sending frames (the link is already gone:
the firmware's RX-loss failsafe, ``failsafe_procedure`` DROP or LAND, takes over).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from aerobat.core.bounds import Interval, Span, bounded, validate
from aerobat.firmware.betaflight.msp import (
    FEATURE_RX_MSP,
    Battery,
    BatteryAlert,
    FailsafeConfig,
    FailsafeProcedure,
    MspModeRange,
    StatusEx,
)
from aerobat.firmware.betaflight.settings import ModeRange
from aerobat.plants.world_params import Volume

__all__ = ["Preflight", "SafetyLimits", "SafetyMonitor", "StopReason", "configuration_problems", "failsafe_problems",
           "preflight"]


class StopReason(StrEnum):
    """Why a flight was stopped."""

    KILL = "kill"
    GEOFENCE = "geofence"
    MOCAP_LOST = "mocap_lost"
    LINK_LOST = "link_lost"
    LOW_BATTERY = "low_battery"

    @property
    def meaning(self) -> str:
        """One sentence on what happened."""
        return _MEANINGS[self]


_MEANINGS = {
    StopReason.KILL: "the operator's kill: motors stopped at once",
    StopReason.GEOFENCE: "the vehicle left the geofence: disarmed",
    StopReason.MOCAP_LOST: "no fresh motion-capture pose of the vehicle: disarmed",
    StopReason.LINK_LOST: "the flight controller stopped answering: its RX-loss failsafe takes over",
    StopReason.LOW_BATTERY: "the battery is below its limit or the firmware reports it critical: disarmed",
}

_SIDE = Span(Interval(-50.0, 50.0, unit="m"), strict=True, end=50.0)
"""A side of the geofence: (low, high) in metres, low below high, both within ±50 m."""


@dataclass(frozen=True, kw_only=True)
class SafetyLimits:
    """The limits of a flight, in the motion-capture frame (metres, seconds, volts).

    Attributes
    ----------
    fence_x_m, fence_y_m, fence_z_m : the geofence, a box (low, high) per axis of the room.
    mocap_timeout_s : a pose older than this (its arrival time) stops the flight.
    min_mocap_rate_hz : pre-flight: the poses must arrive at least this often.
    link_timeout_s : no answer from the flight controller for this long stops the flight.
    min_cell_voltage_v : below this mean cell voltage the flight is stopped (and a take-off refused).
    start_tolerance_m : pre-flight: the vehicle must stand within this of the start.
    max_failsafe_delay_s : pre-flight: the firmware's RX-loss failsafe must reach its procedure (DROP or
        AUTO_LANDING) within this (its ``failsafe_delay``; the 0.3 s hold before it not counted).
    """

    fence_x_m: tuple[float, float] = bounded((-2.0, 2.0), _SIDE)
    fence_y_m: tuple[float, float] = bounded((-2.0, 2.0), _SIDE)
    fence_z_m: tuple[float, float] = bounded((-0.1, 3.0), _SIDE)
    mocap_timeout_s: float = bounded(0.05, Interval(0.005, 1.0, unit="s"))
    min_mocap_rate_hz: float = bounded(100.0, Interval(10.0, 2000.0, unit="Hz"))
    link_timeout_s: float = bounded(0.25, Interval(0.01, 5.0, unit="s"))
    min_cell_voltage_v: float = bounded(3.5, Interval(2.8, 4.2, unit="V"))
    start_tolerance_m: float = bounded(0.3, Interval(0.01, 5.0, unit="m"))
    max_failsafe_delay_s: float = bounded(2.0, Interval(0.0, 20.0, unit="s"))

    def __post_init__(self) -> None:
        validate(self)

    def with_fence_around(self, start_m: Sequence[float] | np.ndarray, volume: Volume,
                          margin_m: float = 0.1) -> SafetyLimits:
        """These limits with the geofence of the flight ``volume`` around ``start_m`` (widened by ``margin_m``).

        The supervisor's volume check ends a trial as crashed at the volume's walls; the fence, a
        little outside them, is the backstop that disarms.
        """
        sides: dict[str, Any] = {}
        for axis, (low, high), centre in zip("xyz", (volume.x_m, volume.y_m, volume.z_m), start_m, strict=True):
            sides[f"fence_{axis}_m"] = (centre + low - margin_m, centre + high + margin_m)
        return dataclasses.replace(self, **sides)

    def inside_fence(self, position_m: Sequence[float]) -> bool:
        """True if ``position_m`` (x, y, z in the room) is inside the geofence."""
        return all(low <= p <= high for p, (low, high) in
                   zip(position_m, (self.fence_x_m, self.fence_y_m, self.fence_z_m), strict=True))


@dataclass(frozen=True)
class Preflight:
    """What forbids a take-off (``problems``; empty: clear to fly) and what was checked."""

    problems: tuple[str, ...]
    checked: tuple[str, ...]

    @property
    def clear(self) -> bool:
        """Nothing forbids the take-off."""
        return not self.problems


def preflight(limits: SafetyLimits, *, status: StatusEx | None, battery: Battery | None,
              mocap_rate_hz: float, position_m: Sequence[float] | None,
              start_m: Sequence[float]) -> Preflight:
    """Check everything that must hold before the motors spin.

    Parameters
    ----------
    status, battery : the flight controller's answers (None: it did not answer), read while the ground
        side streams disarmed frames, so that no arming-disable flag (RXLOSS included) is expected.
    mocap_rate_hz : the rate the vehicle's poses arrived at just now.
    position_m : the vehicle's position now (None: not tracked).
    start_m : where it should stand.
    """
    problems = []
    if status is None:
        problems.append("link: the flight controller does not answer MSP")
    else:
        blocking = status.arming_disable_flags
        if status.armed:
            problems.append("arming: the flight controller is already armed")
        if blocking:
            problems.append(f"arming: the firmware refuses to arm ({', '.join(blocking)})")
    if battery is None:
        problems.append("battery: not reported")
    elif battery.alert is BatteryAlert.NOT_PRESENT or battery.cell_count == 0:
        problems.append("battery: none detected")
    elif battery.alert in (BatteryAlert.WARNING, BatteryAlert.CRITICAL):
        problems.append(f"battery: the firmware reports {battery.alert.name} ({battery.voltage_v:.2f} V)")
    elif battery.cell_voltage_v < limits.min_cell_voltage_v:
        problems.append(f"battery: {battery.cell_voltage_v:.2f} V per cell, below min_cell_voltage_v "
                        f"{limits.min_cell_voltage_v:g} V")
    if not mocap_rate_hz >= limits.min_mocap_rate_hz:
        problems.append(f"motion capture: {mocap_rate_hz:.0f} Hz, below min_mocap_rate_hz "
                        f"{limits.min_mocap_rate_hz:g} Hz")
    if position_m is None:
        problems.append("motion capture: the vehicle is not tracked")
    else:
        if not limits.inside_fence(position_m):
            problems.append(f"geofence: the vehicle at {_xyz(position_m)} is outside it")
        off_m = math.dist(position_m, start_m)
        if not off_m <= limits.start_tolerance_m:
            problems.append(f"start: the vehicle is {off_m:.2f} m from the start {_xyz(start_m)} "
                            f"(start_tolerance_m {limits.start_tolerance_m:g} m)")
    return Preflight(tuple(problems), ("link", "arming flags", "battery", "motion-capture rate", "geofence", "start"))


def configuration_problems(features: int | None, ranges: Sequence[MspModeRange] | None,
                           modes: Mapping[str, ModeRange]) -> tuple[str, ...]:
    """What in the flight controller's configuration (as MSP reports it) is not what the plant flies with.

    The sticks go out as MSP_SET_RAW_RC, so the receiver must be MSP; the mode switches the plant sends
    (ARM, ANGLE/ACRO) must be where aerobat's ``settings.toml`` puts them, or a frame meant to arm or to
    switch to ACRO would do something else. ``None``: the board did not answer.
    """
    problems = []
    if features is None or ranges is None:
        return ("firmware: the flight controller does not report its features and mode ranges over MSP",)
    if not features & FEATURE_RX_MSP:
        problems.append("firmware: the receiver is not MSP (feature RX_MSP is off; in the configurator's "
                        "Receiver tab choose 'MSP RX input')")
    for name, mode in modes.items():
        if not any(r.permanent_id == mode.permanent_id and r.aux == mode.aux and r.low_us == mode.low_us
                   and r.high_us == mode.high_us for r in ranges):
            found = [f"AUX{r.aux} {r.low_us}–{r.high_us} µs" for r in ranges if r.permanent_id == mode.permanent_id]
            problems.append(f"firmware: {name} is not on AUX{mode.aux} {mode.low_us}–{mode.high_us} µs as aerobat "
                            f"sends it (found: {', '.join(found) or 'no range'}; `aux` in the CLI)")
    return tuple(problems)


def failsafe_problems(failsafe: FailsafeConfig | None, limits: SafetyLimits) -> tuple[str, ...]:
    """What in the firmware's RX-loss failsafe (MSP_FAILSAFE_CONFIG) would not bring the vehicle down in a room.

    The failsafe is the backstop when the ground is gone (link loss): its procedure must stop the motors
    (DROP) or land (AUTO_LANDING), not fly somewhere (GPS_RESCUE needs a sky), and it must act within
    ``limits.max_failsafe_delay_s``. ``None``: the board did not answer.
    """
    if failsafe is None:
        return ("firmware: the flight controller does not report its failsafe configuration over MSP",)
    problems = []
    if failsafe.procedure not in (FailsafeProcedure.DROP, FailsafeProcedure.AUTO_LANDING):
        name = failsafe.procedure.name if isinstance(failsafe.procedure, FailsafeProcedure) else failsafe.procedure
        problems.append(f"firmware: failsafe_procedure is {name}; a room needs DROP (or AUTO_LANDING): "
                        f"`set failsafe_procedure = DROP` in the CLI")
    if failsafe.delay_s > limits.max_failsafe_delay_s:
        problems.append(f"firmware: failsafe_delay is {failsafe.delay_s:g} s, above max_failsafe_delay_s "
                        f"{limits.max_failsafe_delay_s:g} s (`set failsafe_delay` counts 0.1 s)")
    return tuple(problems)


def _xyz(p: Sequence[float]) -> str:
    return "(" + ", ".join(f"{v:.2f}" for v in p) + ") m"


class SafetyMonitor:
    """The reasons to stop a flight, from what the ground side saw last (all times: ``time.monotonic()`` s).

    Feed it as things happen (:meth:`pose`, :meth:`link_answered`, :meth:`battery`, :meth:`kill`)
    and ask :meth:`check` at every frame. Motion capture counts as lost once poses have come and
    stopped (a vehicle never tracked is :func:`preflight`'s to refuse); the link, once no answer
    came for its timeout, counted from ``now_s`` until the first. A reason, once found, stays (``stopped``): a flight
    that was stopped is not resumed by a pose that comes back.
    """

    def __init__(self, limits: SafetyLimits, now_s: float) -> None:
        self.limits = limits
        self._pose_at_s = now_s
        self._position_m: tuple[float, float, float] | None = None
        self._link_at_s = now_s
        self._battery: Battery | None = None
        self._killed = False
        self.stopped: StopReason | None = None
        self.detail = ""

    def start(self, now_s: float) -> None:
        """Start the clocks of the first pose and the first answer now (a flight that took time to set up)."""
        if self._position_m is None:
            self._pose_at_s = now_s
        self._link_at_s = max(self._link_at_s, now_s)

    def pose(self, position_m: Sequence[float], received_s: float) -> None:
        """A pose of the vehicle arrived at ``received_s``."""
        self._position_m = (float(position_m[0]), float(position_m[1]), float(position_m[2]))
        self._pose_at_s = received_s

    def link_answered(self, at_s: float) -> None:
        """The flight controller answered at ``at_s``."""
        self._link_at_s = at_s

    def battery(self, battery: Battery) -> None:
        """The firmware reported its battery."""
        self._battery = battery

    def kill(self) -> None:
        """The operator's kill: the next :meth:`check` says KILL, whatever else holds."""
        self._killed = True

    def check(self, now_s: float) -> StopReason | None:
        """The first reason to stop now, or None to fly on (kill, then geofence, mocap, link, battery)."""
        if self.stopped is not None and not self._killed:
            return self.stopped
        reason, detail = self._first_reason(now_s)
        if reason is not None and (self.stopped is None or reason is StopReason.KILL):
            self.stopped, self.detail = reason, detail
        return self.stopped

    def _first_reason(self, now_s: float) -> tuple[StopReason | None, str]:
        limits = self.limits
        if self._killed:
            return StopReason.KILL, "kill"
        if self._position_m is not None and not limits.inside_fence(self._position_m):
            return StopReason.GEOFENCE, f"at {_xyz(self._position_m)}"
        age_s = now_s - self._pose_at_s
        if self._position_m is not None and age_s > limits.mocap_timeout_s:
            return StopReason.MOCAP_LOST, (f"last pose {age_s * 1e3:.0f} ms ago "
                                           f"(mocap_timeout_s {limits.mocap_timeout_s:g} s)")
        silent_s = now_s - self._link_at_s
        if silent_s > limits.link_timeout_s:
            return StopReason.LINK_LOST, (f"no answer for {silent_s * 1e3:.0f} ms "
                                          f"(link_timeout_s {limits.link_timeout_s:g} s)")
        b = self._battery
        if b is not None and (b.alert is BatteryAlert.CRITICAL or
                              (b.cell_count and b.cell_voltage_v < limits.min_cell_voltage_v)):
            return StopReason.LOW_BATTERY, f"{b.voltage_v:.2f} V, {b.alert.name}"
        return None, ""
