"""A vehicle from its own flight logs: read, fit, validate on other flights, write a vehicle file.

:func:`identify_from_logs` is what ``aerobat identify --log FILE`` runs. The logs named are
fitted together (every fifth block of each is held out); every *other* log in the same files
(a blackbox file often holds several flights of one quad) is a validation flight. The result
turns into a vehicle file that ``design``, ``learn`` and ``study`` accept
(:func:`vehicle_from_log_fit`) and, for the Betaflight plant, an ``[airframe]`` section
(:func:`airframe_from_log_fit`).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from aerobat.errors import ConfigError, IdentificationFailed
from aerobat.experiments.log_excitation import axis_excitation, with_prior_for_poorly_excited_axes
from aerobat.logs import read_logs
from aerobat.logs.files import LogFormat, check_log_file, detect_format
from aerobat.logs.refs import LogRef, parse_log_ref
from aerobat.quadrotor.flightlog import Channel, FlightLog
from aerobat.quadrotor.identification import envelope_margins
from aerobat.quadrotor.identification.battery import BatteryFit, fit_battery
from aerobat.quadrotor.identification.logdata import PreparedLog, prepare_log
from aerobat.quadrotor.identification.logfit import (
    ChannelMetrics,
    Geometry,
    LogFit,
    LogFitOptions,
    fit_log,
    thrust_curve,
    validate,
)
from aerobat.quadrotor.identification.vibration import VibrationFit, fit_vibration
from aerobat.quadrotor.vehicle import ModelEffects, VehicleConfig, VehicleParams

__all__ = ["KAPPA_RATIO_WARNING", "LogIdentification", "LogRef", "airframe_from_log_fit", "airframe_notes",
           "identification_warnings", "identify_from_logs", "parse_log_ref", "prior_for_log", "vehicle_from_log_fit"]


@dataclass(frozen=True)
class LogIdentification:
    """What :func:`identify_from_logs` found.

    Attributes
    ----------
    fit : the fit on the logs named.
    fitted : the logs fitted (``file#N``).
    validations : per other log of the same files, its prediction metrics, or the reason it
        could not be used.
    excitation : each axis's motion in the logs fitted (:class:`~.log_excitation.AxisExcitation`).
    excitation_notes : what identification did about a poorly excited axis (empty: nothing).
    """

    fit: LogFit
    fitted: tuple[str, ...]
    validations: tuple[tuple[str, tuple[ChannelMetrics, ...] | str], ...]
    logs: tuple[FlightLog, ...] = ()
    prepared: tuple[PreparedLog, ...] = ()
    excitation: Any = None
    excitation_notes: tuple[str, ...] = ()

    @property
    def battery_reference_v(self) -> float | None:
        """The battery voltage the fit's thrust holds at [V]: the median in flight over the logs fitted
        (:func:`~.log_replay.flying_voltage_v`, weighted by their lengths); None without a logged voltage."""
        from aerobat.experiments.log_replay import flying_voltage_v

        volts = [(flying_voltage_v(log), log.duration_s) for log in self.logs]
        volts = [(v, w) for v, w in volts if math.isfinite(v)]
        if not volts:
            return None
        return float(sum(v * w for v, w in volts) / sum(w for _, w in volts))

    @property
    def battery(self) -> BatteryFit | None:
        """The pack under load (:func:`~aerobat.quadrotor.identification.battery.fit_battery`) over the logs fitted;
        None without a logged voltage and motor commands, or too little flight."""
        from aerobat.experiments.log_replay import FLYING_MOTOR

        series = []
        for log in self.logs:
            if log.has(Channel.BATTERY_VOLTAGE) and log.has(Channel.MOTOR_COMMAND):
                motors = log.signals[Channel.MOTOR_COMMAND]
                series.append((motors.time_s, log.signals[Channel.BATTERY_VOLTAGE].at(motors.time_s)[:, 0],
                               motors.values))
        return fit_battery(series, flying_command=FLYING_MOTOR) if series else None

    @property
    def vibration(self) -> VibrationFit | None:
        """The rotors' speed through the folded rotor lines of the logs' unfiltered gyro
        (:func:`~aerobat.quadrotor.identification.vibration.fit_vibration`, around the Betaflight airframe's default
        thrust coefficient, with the fit's thrust curve); None when no log fitted records the unfiltered gyro
        (Betaflight's ``debug_mode`` GYRO_SCALED) with motor commands, or none has a steady window."""
        from aerobat.experiments.log_replay import FLYING_MOTOR
        from aerobat.quadrotor.xframe import Airframe

        series = []
        for log in self.logs:
            if log.has(Channel.GYRO_UNFILTERED) and log.has(Channel.MOTOR_COMMAND):
                motors = log.signals[Channel.MOTOR_COMMAND]
                series.append((motors.time_s, log.signals[Channel.GYRO_UNFILTERED].at(motors.time_s), motors.values))
        if not series:
            return None
        f_max = _require(self.fit, "thrust_max_n")
        ratio, shape = min(max(self.fit.model.r, 0.0), 0.9), min(max(self.fit.model.k, 0.0), 1.0)
        return fit_vibration(series, lambda u: f_max * thrust_curve(u, ratio, shape),
                             Airframe().thrust_coefficient_n_s2, flying_command=FLYING_MOTOR)

    @property
    def idle_command(self) -> float | None:
        """Betaflight's armed idle as a motor command (the low end of the header's motorOutput), else None."""
        for log in self.logs:
            low = log.metadata.parameters.get("motorOutput", "").split(",")[0].strip()
            if low.isdigit():
                return (float(low) - 48.0) / 1999.0
        return None


def _windowed(chosen: list[FlightLog], others: list[FlightLog], window_s: tuple[float, float]
              ) -> tuple[list[FlightLog], list[FlightLog]]:
    """The logs ``chosen`` cut to ``window_s`` (named ``file#N@a-b s``), and the parts outside it with ``others``."""
    start, end = window_s
    if not 0.0 <= start < end:
        raise ConfigError(f"--window-s {start:g} {end:g}: the window must start at 0 s or later and end after it")
    cut: list[FlightLog] = []
    rest: list[FlightLog] = []
    for log in chosen:
        if start >= log.duration_s:
            raise ConfigError(f"--window-s {start:g} {end:g}: {log.name} lasts {log.duration_s:.1f} s")
        cut.append(dataclasses.replace(log.window(start, end), window_s=(start, min(end, log.duration_s))))
        for a, b in ((0.0, start), (end, log.duration_s)):
            if b - a >= 8.0:  # enough flight to validate on
                rest.append(dataclasses.replace(log.window(a, b), window_s=(a, b)))
    return cut, [*rest, *others]


def _load(refs: Sequence[LogRef]) -> tuple[list[FlightLog], list[FlightLog]]:
    chosen: list[FlightLog] = []
    others: list[FlightLog] = []
    for ref in refs:
        logs = read_logs(ref.path)
        if ref.index is not None and ref.index > len(logs):
            raise ConfigError(f"{ref.path}: log {ref.index} does not exist; the file holds {len(logs)} "
                              f"log{'s' if len(logs) != 1 else ''}")
        for log in logs:
            (chosen if ref.index is None or log.index == ref.index else others).append(log)
    names = {log.name for log in chosen}
    return chosen, [log for log in others if log.name not in names]


def identify_from_logs(refs: Sequence[LogRef | str | os.PathLike[str]], geometry: Geometry, *,
                       options: LogFitOptions | None = None,
                       before_fit: Callable[[], None] | None = None,
                       prior: VehicleConfig | None = None,
                       window_s: tuple[float, float] | None = None) -> LogIdentification:
    """Fit ``geometry``'s vehicle on the logs ``refs`` and validate on the other logs of the same files.

    Each axis's excitation is measured (:func:`~.log_excitation.axis_excitation`); with a ``prior``, the inertia of
    a poorly excited roll or pitch axis comes from the other axis and the prior's ratio, and the notes say so
    (:func:`~.log_excitation.with_prior_for_poorly_excited_axes`). ``window_s`` (log time) fits only that window
    of each log named; the rest of each (before and after it) validates with the file's other logs.

    ``before_fit`` is called once the logs are read and found fit to identify (each a multirotor's, with
    enough flight, one motor layout), before the fit: where a caller says that it starts, so that a log
    refused is the only thing said about it.
    """
    parsed = [r if isinstance(r, LogRef) else parse_log_ref(r) for r in refs]
    if not parsed:
        raise ConfigError("identify: no log given")
    chosen, others = _load(parsed)
    if window_s is not None:
        chosen, others = _windowed(chosen, others, window_s)
    layouts = {log.motor_layout for log in chosen}
    prepared = [prepare_log(log) for log in chosen]
    if len(layouts) != 1 or None in layouts:
        raise ConfigError("identify: the logs have different motor layouts (" +
                          ", ".join(f"{log.name}: {log.motor_layout.mixer if log.motor_layout else 'none'}"
                                    for log in chosen) + "); fit one vehicle at a time")
    (layout,) = layouts
    assert layout is not None
    if before_fit is not None:
        before_fit()
    fit = fit_log(prepared, layout, geometry, options=options)
    excitation = axis_excitation(chosen)
    excitation_notes: list[str] = []
    if prior is not None:
        fit, excitation_notes = with_prior_for_poorly_excited_axes(fit, excitation, prior)
    validations: list[tuple[str, tuple[ChannelMetrics, ...] | str]] = []
    for log in others:
        try:
            validations.append((log.name, validate(fit, prepare_log(log, purpose="validation"))))
        except ConfigError as exc:
            validations.append((log.name, str(exc).split(": ", 1)[-1]))
    return LogIdentification(fit=fit, fitted=tuple(log.name for log in chosen), validations=tuple(validations),
                             logs=tuple(chosen), prepared=tuple(prepared), excitation=excitation,
                             excitation_notes=tuple(excitation_notes))


def _require(fit: LogFit, name: str) -> float:
    value = fit.value(name)
    if not math.isfinite(value) or value <= 0:
        raise IdentificationFailed(f"{fit.name}: {name} came out {value:g}; no vehicle file can be made from it")
    return value


def vehicle_from_log_fit(fit: LogFit, prior: VehicleConfig, *, name: str = "identified",
                         idle_command: float | None = None) -> VehicleConfig:
    """The identified vehicle as a design model: mass and geometry from ``fit.geometry``, the rest fitted.

    The arm length is the motors' distance from the centre, √(x² + y²), as the shipped FPV
    preset defines it; the reduced envelope keeps ``prior``'s margins; the prior's rate-loop
    gains are kept (a log of another firmware's loop does not give the paper's P gains).
    ``idle_command`` is the motor command of an armed, idling motor (Betaflight's idle), whose
    thrust is the lower limit; default: the fit's thrust at zero command.
    """
    g = fit.geometry
    f_max = _require(fit, "thrust_max_n")
    u_idle = max(idle_command if idle_command is not None else 0.0, 1e-6)
    f_min = float(f_max * thrust_curve(np.array([u_idle]), fit.model.r, fit.model.k)[0])
    lower, upper = envelope_margins(prior.vehicle)
    a_min, a_max = 4 * f_min / g.mass_kg, 4 * f_max / g.mass_kg
    span = a_max - a_min
    # Table 1's margins scale with the thrust span; on a vehicle with T/W of 5 and more they would put
    # β̲ above hover, so β̲ is at most 0.9 g (the shipped FPV preset's)
    beta_min = min(a_min + lower * span, 0.9 * prior.vehicle.gravity_m_s2)
    vehicle = VehicleParams(
        mass_kg=g.mass_kg, arm_length_m=math.hypot(g.motor_x_m, g.motor_y_m),
        inertia_xx_kg_m2=_require(fit, "inertia_xx_kg_m2"), inertia_yy_kg_m2=_require(fit, "inertia_yy_kg_m2"),
        inertia_zz_kg_m2=_require(fit, "inertia_zz_kg_m2"),
        motor_rate_up_per_s=1.0 / _require(fit, "motor_time_constant_s"),
        motor_rate_down_per_s=1.0 / _require(fit, "motor_time_constant_s"),
        rotor_thrust_min_n=f_min, rotor_thrust_max_n=f_max,
        collective_reduced_min_m_s2=beta_min, collective_reduced_max_m_s2=a_max - upper * span,
        drag_constant_m=min(max(_require(fit, "kappa_m"), 1e-5), 1.0), gravity_m_s2=prior.vehicle.gravity_m_s2,
    )
    source = {
        "summary": f"identified from flight logs {fit.name} (aerobat identify --log)",
        "mass_kg": f"[user] {g.mass_kg:g} kg given with --mass-kg",
        "geometry": f"[user] motors at (±{g.motor_x_m:g}, ±{g.motor_y_m:g}) m; arm length = sqrt(x² + y²)",
        "inertia_zz": f"[A] {g.inertia_zz_ratio:.3g} × (I_xx + I_yy): a log cannot separate I_zz from κ",
        "fit": "; ".join(f"{k} = {v:.5g} ± {s:.2g} {u}" for k, (v, s, u) in fit.values.items()),
        "controller": f"[prior] rate gains of {prior.name}",
    }
    return dataclasses.replace(prior.with_vehicle(vehicle, name=name), effects=ModelEffects(), source=source)


def airframe_from_log_fit(fit: LogFit, *, base: Any | None = None, battery_reference_v: float | None = None,
                          battery: BatteryFit | None = None) -> dict[str, Any]:
    """The Betaflight plant's ``[airframe]`` table for the identified quad (fields of ``Airframe``).

    ``base`` (an :class:`~aerobat.quadrotor.xframe.Airframe`) gives what a log does not
    tell: motor spread, rotor inertia, output delay; its defaults otherwise. ``battery_reference_v``
    (:attr:`LogIdentification.battery_reference_v`) is the voltage the fitted thrust holds at; with it,
    ``battery`` (:attr:`LogIdentification.battery`) makes thrust sag under load as the logged pack did
    (``battery_rest_v``, ``battery_sag_v``; a sag the log shows as negative is written as none).

    The output delay stays the base's (the SITL's ESC delay), not the fit's ``delay_s``: the fit
    measures from the logged motor command to the logged, *filtered* gyro, so its delay includes
    filtering that the SITL's firmware runs itself (not most of it: the ROMA F5's two PT1 gyro
    lowpasses, ≥ 190 and 238 Hz, delay by at most 1.5 ms), and a 250 Hz log cannot tell a delay
    from a lag. Flown as a pure delay, the ROMA F5's 12 ms made the tune's roll loop limit-cycle
    (motors between idle and full; docs/plants.md). :func:`airframe_notes` says so in the file.
    """
    from aerobat.logs.betaflight import props_out
    from aerobat.quadrotor.xframe import Airframe

    base = base or Airframe()
    g = fit.geometry
    tau = _require(fit, "motor_time_constant_s")
    table = dataclasses.asdict(base)
    table.update(
        mass_kg=g.mass_kg,
        inertia_kg_m2=[_require(fit, "inertia_xx_kg_m2"), _require(fit, "inertia_yy_kg_m2"),
                       _require(fit, "inertia_zz_kg_m2")],
        motor_x_m=g.motor_x_m, motor_y_m=g.motor_y_m,
        thrust_max_n=_require(fit, "thrust_max_n"),
        curve_min_speed_ratio=min(max(fit.model.r, 0.0), 0.9), curve_shape=min(max(fit.model.k, 0.0), 1.0),
        motor_tau_up_s=tau, motor_tau_down_s=tau,
        kappa_m=min(max(_require(fit, "kappa_m"), 1e-4), 0.5),
        props_out=props_out(fit.layout),
    )
    if battery_reference_v is not None:
        table["battery_reference_v"] = battery_reference_v
    else:
        table.pop("battery_reference_v", None)  # TOML has no null
    if battery is not None and battery_reference_v is not None and battery.sag_v > 0.0:
        table["battery_rest_v"] = battery.rest_v
        table["battery_sag_v"] = battery.sag_v
    else:
        table.pop("battery_rest_v", None)
        table["battery_sag_v"] = 0.0
    for key in _VIBRATION_AIRFRAME:  # left to the defaults: identify prints the vibration's, to be moved in by hand
        table.pop(key, None)
    for key, value in list(table.items()):
        if isinstance(value, tuple):
            table[key] = list(value)
    checked: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in table.items()}
    checked.setdefault("battery_reference_v", None)
    checked.setdefault("battery_rest_v", None)
    Airframe(**checked)  # validates
    return table


_FITTED_AIRFRAME = ("inertia_kg_m2", "thrust_max_n", "curve_min_speed_ratio", "curve_shape", "motor_tau_up_s",
                    "motor_tau_down_s", "kappa_m")
_GIVEN_AIRFRAME = ("mass_kg", "motor_x_m", "motor_y_m")
_LOG_AIRFRAME = ("props_out", "battery_reference_v", "battery_rest_v", "battery_sag_v")  # read from the log, not fitted
#: not written (the defaults: no vibration): ``identify`` prints the vibration it found as lines to move in
_VIBRATION_AIRFRAME = ("thrust_coefficient_n_s2", "vibration_rms_rad_s", "vibration_thrust_n")


def airframe_notes(fit: LogFit, base: Any | None = None) -> list[str]:
    """Comment lines for the written ``[airframe]``: which fields the log gave, which were given or assumed, which
    are the plant's defaults (a log does not tell them), and what the fit gave that the table does not use."""
    from aerobat.logs.betaflight import props_out
    from aerobat.quadrotor.xframe import Airframe

    defaults = [name for name in dataclasses.asdict(base or Airframe())
                if name not in _FITTED_AIRFRAME + _GIVEN_AIRFRAME + _LOG_AIRFRAME]
    return [f"fitted to the log: {', '.join(_FITTED_AIRFRAME)} (I_zz and kappa_m with the assumed I_zz ratio "
            f"{fit.geometry.inertia_zz_ratio:.3g} of I_xx + I_yy);",
            f"given, not identified: {', '.join(_GIVEN_AIRFRAME)} (--mass-kg, --motor-x-m, --motor-y-m, else the "
            f"prior's);",
            f"props_out = {'true' if props_out(fit.layout) else 'false'}: the log's mixer (the SITL's "
            f"yaw_motors_reversed and the physics' spins follow it);",
            "battery_reference_v (when the log records a voltage): its median in flight, where thrust_max_n "
            "holds; a log replay scales thrust by (V/battery_reference_v)²;",
            "battery_rest_v, battery_sag_v (with a logged voltage): the pack under load, V = rest - sag * mean(u^2) "
            "fitted to the logged voltage; the plant and the firmware design model scale thrust by "
            "(V/battery_reference_v)^2 (aerobat.quadrotor.identification.battery);",
            f"NOT identified, the Betaflight plant's defaults: {', '.join(defaults)};",
            f"the fit's delay from motor command to the logged (filtered) gyro: {fit.model.delay_s * 1e3:.1f} ms;",
            "not used as output_delay_s: it includes gyro filtering the SITL's firmware runs itself, a 250 Hz",
            "log cannot tell a delay from a lag, and a pure delay of that size made the tune's roll loop",
            "limit-cycle on the SITL (docs/plants.md)"]


KAPPA_RATIO_WARNING = 2.0
"""An identified κ more than this factor from the prior's is named in the notes: a log's yaw moments give κ only with
an assumed I_zz, and a factor of 2 is more than props and motors of one class differ by."""


def identification_warnings(fit: LogFit, prior: VehicleConfig) -> list[str]:
    """What in the fit a user should check before flying it: values far from the prior the log cannot pin down."""
    warnings = []
    kappa, prior_kappa = fit.value("kappa_m"), prior.vehicle.drag_constant_m
    if math.isfinite(kappa) and prior_kappa > 0 and not (
            1.0 / KAPPA_RATIO_WARNING <= kappa / prior_kappa <= KAPPA_RATIO_WARNING):
        warnings.append(f"kappa_m = {kappa:.3g} m is {kappa / prior_kappa:.1f}× the prior's ({prior.name}: "
                        f"{prior_kappa:.3g} m): it comes from the yaw response with an assumed I_zz (ratio "
                        f"{fit.geometry.inertia_zz_ratio:.3g} of I_xx + I_yy), which an I_zz off by that factor "
                        f"explains as well; check it (a measured I_zz, the props' data) before flying on it")
    return warnings

_PRIOR_FOR_FORMAT = {
    LogFormat.BLACKBOX: ("fpv5", "a Betaflight blackbox log: the 5-inch FPV quad Betaflight mostly flies"),
    LogFormat.CRAZYFLIE: ("crazyflie21", "a Crazyflie log"),
    LogFormat.ULOG: ("hummingbird", "a PX4 ULog: no preset is typical of PX4's airframes, the paper's Hummingbird"),
}


def prior_for_log(path: str | os.PathLike[str]) -> tuple[str, str]:
    """The vehicle preset a log's quad is fitted around when the user names none, and why (from the file's format).

    The prior sets what a log cannot: the mass and motor positions (unless given), the assumed I_zz ratio and the
    envelope's margins; a Betaflight log fitted around the paper's 0.468 kg Hummingbird was a 5-inch quad with a
    Hummingbird's arms.
    """
    return _PRIOR_FOR_FORMAT[detect_format(check_log_file(path))]
