"""Every reason to stop a real flight fires, and a take-off is refused for every reason it must be."""

from __future__ import annotations

import pytest

from aerobat.errors import ConfigError
from aerobat.firmware.betaflight.msp import (
    FEATURE_RX_MSP,
    Battery,
    BatteryAlert,
    MspModeRange,
    StatusEx,
    decode_arming_disable_flags,
)
from aerobat.firmware.betaflight.settings import ModeRange
from aerobat.plants.fc import SafetyLimits, SafetyMonitor, StopReason, configuration_problems, preflight

LIMITS = SafetyLimits()
HOME = (0.0, 0.0, 0.0)


def _status(mask: int = 0, armed: bool = False) -> StatusEx:
    return StatusEx(125, armed, int(armed), 0, mask, decode_arming_disable_flags(mask))


def _battery(volts: float = 16.4, cells: int = 4, alert: BatteryAlert = BatteryAlert.OK) -> Battery:
    return Battery(cells, 1500, volts, 0, 0.0, alert)


def _flying(now_s: float = 0.0) -> SafetyMonitor:
    monitor = SafetyMonitor(LIMITS, now_s)
    monitor.pose((0.0, 0.0, 1.0), now_s)
    monitor.link_answered(now_s)
    monitor.battery(_battery())
    return monitor


def test_nothing_stops_a_healthy_flight():
    monitor = _flying()
    for i in range(1, 100):
        t = i * 0.005
        monitor.pose((0.01 * i, 0.0, 1.0), t)
        monitor.link_answered(t)
        assert monitor.check(t) is None


def test_motion_capture_dropout_stops_the_flight_after_its_timeout():
    monitor = _flying()
    assert monitor.check(LIMITS.mocap_timeout_s * 0.9) is None
    monitor.link_answered(0.1)
    assert monitor.check(0.1) is StopReason.MOCAP_LOST
    assert "last pose 100 ms ago" in monitor.detail
    monitor.pose((0.0, 0.0, 1.0), 0.11)
    assert monitor.check(0.11) is StopReason.MOCAP_LOST  # a stopped flight stays stopped


def test_a_vehicle_never_tracked_is_preflights_to_refuse_not_a_dropout():
    monitor = SafetyMonitor(LIMITS, 0.0)
    monitor.link_answered(0.2)
    assert monitor.check(0.2) is None  # preflight says "not tracked" before any take-off
    monitor.pose((0.0, 0.0, 0.0), 0.2)
    monitor.link_answered(0.3)
    assert monitor.check(0.3) is StopReason.MOCAP_LOST


def test_leaving_the_geofence_stops_the_flight():
    monitor = _flying()
    monitor.pose((0.0, LIMITS.fence_y_m[1] + 0.01, 1.0), 0.01)
    assert monitor.check(0.01) is StopReason.GEOFENCE and "at (0.00, 2.01, 1.00) m" in monitor.detail


def test_link_loss_stops_the_flight():
    monitor = _flying()
    for i in range(1, 80):
        monitor.pose((0.0, 0.0, 1.0), i * 0.005)
    assert monitor.check(0.2) is None
    assert monitor.check(0.26) is not None
    monitor = _flying()
    t = LIMITS.link_timeout_s + 0.01
    monitor.pose((0.0, 0.0, 1.0), t)
    assert monitor.check(t) is StopReason.LINK_LOST


def test_kill_wins_over_everything_even_after_another_stop():
    monitor = _flying()
    monitor.pose((0.0, 9.0, 1.0), 0.0)
    assert monitor.check(0.0) is StopReason.GEOFENCE
    monitor.kill()
    assert monitor.check(0.0) is StopReason.KILL
    assert StopReason.KILL.meaning.startswith("the operator's kill")


@pytest.mark.parametrize("battery", [_battery(13.9), _battery(16.0, alert=BatteryAlert.CRITICAL)])
def test_low_battery_reported_by_the_firmware_stops_the_flight(battery):
    monitor = _flying()
    monitor.battery(battery)
    assert monitor.check(0.0) is StopReason.LOW_BATTERY


def test_preflight_clear_when_everything_holds():
    check = preflight(LIMITS, status=_status(), battery=_battery(), mocap_rate_hz=200.0,
                      position_m=(0.05, 0.0, 0.0), start_m=HOME)
    assert check.clear, check.problems


@pytest.mark.parametrize("change, problem", [
    ({"status": None}, "link: the flight controller does not answer MSP"),
    ({"status": _status(mask=(1 << 2) | (1 << 3))}, "arming: the firmware refuses to arm (RXLOSS, NOT_DISARMED)"),
    ({"status": _status(armed=True)}, "arming: the flight controller is already armed"),
    ({"battery": None}, "battery: not reported"),
    ({"battery": _battery(0.0, cells=0, alert=BatteryAlert.NOT_PRESENT)}, "battery: none detected"),
    ({"battery": _battery(14.6, alert=BatteryAlert.WARNING)}, "battery: the firmware reports WARNING (14.60 V)"),
    ({"battery": _battery(13.6)}, "battery: 3.40 V per cell, below min_cell_voltage_v 3.5 V"),
    ({"mocap_rate_hz": 60.0}, "motion capture: 60 Hz, below min_mocap_rate_hz 100 Hz"),
    ({"position_m": None}, "motion capture: the vehicle is not tracked"),
    ({"position_m": (0.0, 0.0, 3.5)}, "geofence: the vehicle at (0.00, 0.00, 3.50) m is outside it"),
    ({"position_m": (0.5, 0.0, 0.0)}, "start: the vehicle is 0.50 m from the start (0.00, 0.00, 0.00) m"),
])
def test_preflight_names_what_forbids_a_take_off(change, problem):
    arguments = {"status": _status(), "battery": _battery(), "mocap_rate_hz": 200.0, "position_m": HOME,
                 "start_m": HOME, **change}
    check = preflight(LIMITS, **arguments)
    assert not check.clear
    assert any(p.startswith(problem) for p in check.problems), check.problems


def test_a_geofence_whose_sides_cross_is_refused():
    with pytest.raises(ConfigError, match=r"^fence_z_m\[1\] = 1 is out of range: allowed \(2, 50\] \(m\)$"):
        SafetyLimits(fence_z_m=(2.0, 1.0))


def test_a_flight_that_took_time_to_set_up_starts_its_safety_clocks_when_it_starts():
    monitor = SafetyMonitor(LIMITS, 0.0)
    monitor.start(1.0)  # e.g. a compiled estimate loaded for 1 s after the monitor was made
    for i in range(1, 60):
        t = 1.0 + i * 0.005
        monitor.pose((0.0, 0.0, 1.0), t)
        if t < 1.0 + LIMITS.link_timeout_s:
            assert monitor.check(t) is None, t  # no answer yet, but the link's clock started at 1.0
    assert monitor.check(1.0 + LIMITS.link_timeout_s + 0.01) is StopReason.LINK_LOST


SETTINGS_MODES = {  # aerobat's settings.toml: ARM on AUX1, ANGLE on AUX2, both 1700–2100 µs
    "ARM": ModeRange("ARM", 0, 1, 1700, 2100), "ANGLE": ModeRange("ANGLE", 1, 2, 1700, 2100)}
RIGHT = (MspModeRange(0, 1, 1700, 2100), MspModeRange(1, 2, 1700, 2100))


def test_a_board_configured_as_aerobat_flies_it_passes():
    assert configuration_problems(FEATURE_RX_MSP | (1 << 22), RIGHT, SETTINGS_MODES) == ()


@pytest.mark.parametrize("features, ranges, problem", [
    (1 << 3, RIGHT, "firmware: the receiver is not MSP (feature RX_MSP is off"),
    (FEATURE_RX_MSP, (MspModeRange(0, 3, 1300, 1700), RIGHT[1]),
     "firmware: ARM is not on AUX1 1700–2100 µs as aerobat sends it (found: AUX3 1300–1700 µs"),
    (FEATURE_RX_MSP, (RIGHT[0],), "firmware: ANGLE is not on AUX2 1700–2100 µs as aerobat sends it (found: no range"),
    (None, None, "firmware: the flight controller does not report its features and mode ranges over MSP"),
])
def test_a_board_configured_otherwise_is_refused_naming_what_differs(features, ranges, problem):
    problems = configuration_problems(features, ranges, SETTINGS_MODES)
    assert any(p.startswith(problem) for p in problems), problems
