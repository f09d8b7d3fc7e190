"""RotorPy plant settings: the TOML file, RotorPy parameter overrides and their validation."""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from aerobat.config import as_path, dataclass_from_table, dataclass_to_table, read_toml
from aerobat.core.bounds import Interval, Items, OneOf, bounded, validate
from aerobat.errors import ConfigError, MissingDependency
from aerobat.plants.world_params import MotionCapture, Supervisor, Volume

__all__ = [
    "INSTALL_HINT",
    "PAPER_RATE_GAINS_PER_S",
    "PAPER_ROTOR_THRUST_MAX_N",
    "PAPER_ROTOR_THRUST_MIN_N",
    "RotorPySettings",
    "WindSettings",
    "adapted_quad_params",
    "build_quad_params",
    "import_rotorpy",
    "load_rotorpy_settings",
    "settings_from_table",
    "settings_to_table",
    "shipped_quad_params",
    "validate_overrides",
]

INSTALL_HINT = "pip install 'aerobat[rotorpy]'"

#: The paper's onboard rate gains P_p, P_q, P_r (Table 1) [1/s]; RotorPy's shipped k_w is 1.
PAPER_RATE_GAINS_PER_S = (100.0, 100.0, 10.0)
#: Table 1 per-rotor thrust limits f_min, f_max [N].
PAPER_ROTOR_THRUST_MIN_N = 0.08
PAPER_ROTOR_THRUST_MAX_N = 2.8

Integrator = Literal["rk3", "rk4", "RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA"]
"""The fixed-step solvers written here (``rk3``, ``rk4``), then scipy ``solve_ivp`` methods."""


def import_rotorpy() -> tuple[Any, dict[str, Any]]:
    """RotorPy's ``Multirotor`` class and shipped Hummingbird ``quad_params`` (or ImportError with the hint)."""
    try:
        from rotorpy.vehicles.hummingbird_params import quad_params
        from rotorpy.vehicles.multirotor import Multirotor
    except ImportError as exc:
        raise MissingDependency("rotorpy", extra="rotorpy", purpose="the RotorPy plant", detail=str(exc)) from None
    return Multirotor, quad_params




WindModel = Literal["none", "constant", "sinusoid", "dryden"]
"""The RotorPy wind models :class:`WindSettings` offers."""
_WIND_SPEEDS = Items.each(Interval(-30.0, 30.0, unit="m/s"), 3)


@dataclass(frozen=True, kw_only=True)
class WindSettings:
    """Which RotorPy wind model blows during trials (world frame, evaluated before every 800 Hz step).

    Attributes
    ----------
    model : ``none``; ``constant`` (``ConstantWind``, ``velocity_m_s``); ``sinusoid``
        (``SinusoidWind``: ``velocity_m_s`` + ``amplitude_m_s``·sin(2π f (t + phase)));
        ``dryden`` (``DrydenGust``: mean ``velocity_m_s``, intensity ``sigma_m_s``; needs torch
        in RotorPy 3.0.0, and draws from numpy's global RNG, reseeded per trial).
    velocity_m_s : mean wind [m/s].
    amplitude_m_s, frequency_hz, phase_s : sinusoid amplitude [m/s], frequency [Hz], phase [s] per axis.
    sigma_m_s : Dryden turbulence intensity per axis [m/s].
    altitude_m : Dryden operating altitude (sets its length scales) [m].
    """

    model: WindModel = bounded("none", OneOf(WindModel))
    velocity_m_s: tuple[float, float, float] = bounded((0.0, 0.0, 0.0), _WIND_SPEEDS)
    amplitude_m_s: tuple[float, float, float] = bounded((0.0, 0.0, 0.0), _WIND_SPEEDS)
    frequency_hz: tuple[float, float, float] = bounded((1.0, 1.0, 1.0), Items.each(Interval(0.0, 100.0, unit="Hz"), 3))
    phase_s: tuple[float, float, float] = bounded((0.0, 0.0, 0.0), Items.each(Interval(-100.0, 100.0, unit="s"), 3))
    sigma_m_s: tuple[float, float, float] = bounded((0.1, 0.1, 0.1), Items.each(Interval(0.0, 10.0, unit="m/s"), 3))
    altitude_m: float = bounded(2.0, Interval(0.1, 1000.0, unit="m"))

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True, kw_only=True)
class RotorPySettings:
    """How the RotorPy plant is built and supervised.

    Attributes
    ----------
    quad_params : overrides of RotorPy's ``hummingbird_params.quad_params`` entries, applied
        after the adapted settings (any key of that dict; validated by :func:`validate_overrides`).
    adapt : apply aerobat's adapted settings (paper rate gains, Table 1 rotor-speed limits).
        Off: RotorPy's shipped Hummingbird exactly (k_w = 1, T/W ≈ 10).
    aero : RotorPy's ``aero`` switch (rotor H-force, parasitic drag, translational lift, flapping).
    integrator : ``rk3``/``rk4`` (fixed-step Runge–Kutta solvers written here, passed to
        ``solve_ivp`` through RotorPy's ``integrator_kwargs``; one step per 800 Hz tick) or a
        scipy ``solve_ivp`` method name (adaptive; ``RK45`` is RotorPy's default).
    command_rate_hz : onboard command-generator and rate-loop rate [Hz] (the paper: 800).
    supervisor_rate_hz : rate of the supervisor's PD hover controller [Hz] (>= 70, the arena's radio).
    wind : RotorPy wind model.
    motion_capture : the arena's motion-capture model (rate, noise, latency).
    volume : flyable volume relative to the start; leaving it is a crash.
    supervisor : the arena's PD gains and settle rules (``return_time_s`` is unused: the
        vehicle returns until settled).
    """

    quad_params: Mapping[str, Any] = field(default_factory=dict)
    adapt: bool = True
    aero: bool = True
    integrator: Integrator = bounded("rk3", OneOf(Integrator))
    command_rate_hz: float = bounded(800.0, Interval(50.0, 10000.0, unit="Hz"))
    supervisor_rate_hz: float = bounded(100.0, Interval(70.0, "command_rate_hz", unit="Hz"))
    wind: WindSettings = field(default_factory=WindSettings)
    motion_capture: MotionCapture = field(default_factory=MotionCapture)
    volume: Volume = field(default_factory=Volume)
    supervisor: Supervisor = field(default_factory=Supervisor)

    def __post_init__(self) -> None:
        validate(self)
        if not isinstance(self.quad_params, Mapping):
            raise ConfigError("quad_params must be a table of RotorPy parameters, "
                             f"got {type(self.quad_params).__name__}")


# -------------------------------------------------------------- quad_params


def shipped_quad_params() -> dict[str, Any]:
    """A deep copy of RotorPy's shipped Hummingbird ``quad_params``."""
    _, quad_params = import_rotorpy()
    return copy.deepcopy(quad_params)


def adapted_quad_params() -> dict[str, Any]:
    """RotorPy's Hummingbird with the settings that make it a plausible aerobatic Hummingbird.

    * ``k_w`` = (100, 100, 10) 1/s, the paper's rate gains P_p, P_q, P_r (Table 1). The shipped
      scalar 1 gives a ~1 s rate time constant; RotorPy multiplies ``k_w`` element-wise with the
      rate error, so a 3-vector is a per-axis gain.
    * ``rotor_speed_max`` = √(f_max/k_eta) with Table 1's f_max = 2.8 N (709 rad/s; the shipped
      1500 rad/s allows 12.5 N per rotor, thrust-to-weight ≈ 10).
    * ``rotor_speed_min`` = √(f_min/k_eta) with Table 1's f_min = 0.08 N (120 rad/s; motors idle,
      they do not stop, in flight).
    """
    qp = shipped_quad_params()
    qp["k_w"] = np.array(PAPER_RATE_GAINS_PER_S)
    qp["rotor_speed_max"] = math.sqrt(PAPER_ROTOR_THRUST_MAX_N / qp["k_eta"])
    qp["rotor_speed_min"] = math.sqrt(PAPER_ROTOR_THRUST_MIN_N / qp["k_eta"])
    return qp


_POSITIVE = ("mass", "Ixx", "Iyy", "Izz", "rotor_radius", "k_eta", "tau_m", "rotor_speed_max", "k_v",
             "kp_att", "kd_att")
_NON_NEGATIVE = ("c_Dx", "c_Dy", "c_Dz", "k_m", "k_d", "k_z", "k_h", "k_flap", "rotor_speed_min",
                 "motor_noise_std")


MAX_MAGNITUDE = 1e6
"""Largest magnitude of any RotorPy parameter aerobat accepts (SI units; the largest shipped is 3000)."""
ROTOR_POSITION_MAX_M = 2.0
"""Largest rotor position component from the centre of mass [m] (the Hummingbird's is 0.12 m)."""


def _number(value: Any, where: str, *, limit: float = MAX_MAGNITUDE, unit: str = "") -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{where}: expected a number, got {type(value).__name__} {value!r}")
    try:
        number = float(value)
    except OverflowError:
        raise ConfigError(f"{where}: {str(value)[:12]}… is out of range: allowed [{-limit:g}, {limit:g}]"
                          f"{unit}") from None
    if not math.isfinite(number):
        raise ConfigError(f"{where}: {value} is not finite")
    if abs(number) > limit:
        raise ConfigError(f"{where} = {number:g} is out of range: allowed [{-limit:g}, {limit:g}]{unit}")
    return number


def _vector(value: Any, length: int, where: str, **limits: Any) -> np.ndarray:
    if not isinstance(value, list | tuple | np.ndarray):
        raise ConfigError(f"{where}: expected an array of {length} numbers, got {type(value).__name__} {value!r}")
    if len(value) != length:
        raise ConfigError(f"{where}: expected an array of {length} numbers, got {len(value)}")
    return np.array([_number(v, f"{where}[{i}]", **limits) for i, v in enumerate(value)])


def validate_overrides(overrides: Mapping[str, Any], base: Mapping[str, Any], *, source: str) -> dict[str, Any]:
    """Check ``overrides`` against RotorPy's ``quad_params`` dict ``base``; return RotorPy-ready values.

    Unknown keys, wrong types and values RotorPy cannot fly raise :class:`ConfigError`
    naming ``source`` and the key.
    """
    out: dict[str, Any] = {}
    unknown = sorted(set(overrides) - set(base))
    if unknown:
        raise ConfigError(f"{source}: unknown RotorPy parameter(s) {', '.join(unknown)}; "
                          f"allowed: {', '.join(base)}")
    for key, value in overrides.items():
        where = f"{source}: quad_params.{key}"
        default = base[key]
        if key == "num_rotors":
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(f"{where}: expected an integer, got {type(value).__name__} {value!r}")
            if value != 4:
                raise ConfigError(f"{where}: RotorPy 3.0's Multirotor state has room for exactly 4 rotors, got {value}")
            out[key] = value
        elif key == "rotor_pos":
            if not isinstance(value, Mapping):
                raise ConfigError(f"{where}: expected a table of rotor positions r1…r4, got {type(value).__name__}")
            if set(value) != set(default):
                raise ConfigError(f"{where}: expected exactly the keys {', '.join(default)}, got {', '.join(value)}")
            out[key] = {name: _vector(value[name], 3, f"{where}.{name}", limit=ROTOR_POSITION_MAX_M, unit=" m")
                        for name in default}
        elif key == "k_w":
            if isinstance(value, list | tuple | np.ndarray):
                gains = _vector(value, 3, where)
            else:
                gains = np.array([_number(value, where)] * 3)
            if np.any(gains <= 0) or np.any(gains > 1e4):
                raise ConfigError(f"{where}: rate gains must be in (0, 1e4] 1/s, got {gains.tolist()}")
            out[key] = gains if isinstance(value, list | tuple | np.ndarray) else float(gains[0])
        elif isinstance(default, np.ndarray):
            vec = _vector(value, default.size, where)
            if key == "rotor_directions" and not np.all(np.isin(vec, (-1.0, 1.0))):
                raise ConfigError(f"{where}: each rotor direction must be +1 or -1, got {vec.tolist()}")
            out[key] = vec.astype(default.dtype) if key == "rotor_directions" else vec
        elif isinstance(default, int | float) and not isinstance(default, bool):
            number = _number(value, where)
            if key in _POSITIVE and number <= 0:
                raise ConfigError(f"{where}: must be > 0, got {number:g}")
            if key in _NON_NEGATIVE and number < 0:
                raise ConfigError(f"{where}: must be >= 0, got {number:g}")
            if key in ("Ixy", "Iyz", "Ixz") and abs(number) > 1.0:
                raise ConfigError(f"{where}: product of inertia {number:g} kg m² is out of range [-1, 1]")
            out[key] = number
        else:  # pragma: no cover - RotorPy added a key of a kind aerobat does not know
            raise ConfigError(f"{where}: aerobat does not know how to override a {type(default).__name__} entry")
    return out


def _check_flyable(qp: Mapping[str, Any], source: str) -> None:
    """The combined parameters must allow a hover with margin, and the rotors must reach every moment."""
    # RotorPy's control allocation (thrust, roll, pitch, yaw moments from the four rotor thrusts) is
    # inverted when the vehicle is built: rotors on a line or at the centre make it singular
    arm = qp["k_m"] / qp["k_eta"]
    positions = [np.asarray(qp["rotor_pos"][name], dtype=float) for name in qp["rotor_pos"]]
    allocation = np.array([[1.0] * len(positions), [r[1] for r in positions], [-r[0] for r in positions],
                           [arm * d for d in np.asarray(qp["rotor_directions"], dtype=float)]])
    if not np.all(np.isfinite(allocation)) or np.linalg.cond(allocation) > 1e8:
        raise ConfigError(f"{source}: quad_params.rotor_pos with rotor_directions and k_m/k_eta = {arm:g} m give no "
                          f"control of every moment (rotors at the centre or on one line): place the rotors "
                          f"around the centre of mass, e.g. RotorPy's ±0.12 m in x and y")
    if qp["rotor_speed_min"] >= qp["rotor_speed_max"]:
        raise ConfigError(f"{source}: rotor_speed_min = {qp['rotor_speed_min']:g} must be below "
                          f"rotor_speed_max = {qp['rotor_speed_max']:g} rad/s")
    hover = math.sqrt(qp["mass"] * 9.81 / (4.0 * qp["k_eta"]))
    if not qp["rotor_speed_min"] < hover < qp["rotor_speed_max"]:
        raise ConfigError(f"{source}: the vehicle cannot hover: hover rotor speed {hover:.1f} rad/s is outside "
                          f"[rotor_speed_min, rotor_speed_max] = [{qp['rotor_speed_min']:g}, "
                          f"{qp['rotor_speed_max']:g}] rad/s")


def settings_from_table(data: Mapping[str, Any], *, source: str) -> RotorPySettings:
    """Settings from a table of the file's form (:func:`load_rotorpy_settings`), checked as the file is."""
    allowed = {"quad_params", "simulation", "wind", "motion_capture", "volume", "supervisor"}
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ConfigError(f"{source}: unknown table(s) {', '.join(unknown)}; allowed: {', '.join(sorted(allowed))}")
    kwargs: dict[str, Any] = {}
    if "quad_params" in data:
        table = data["quad_params"]
        if not isinstance(table, Mapping):
            raise ConfigError(f"{source}: quad_params: expected a table, got {type(table).__name__}")
        validate_overrides(table, adapted_quad_params(), source=source)
        kwargs["quad_params"] = dict(table)
    if "simulation" in data:
        sim = data["simulation"]
        if not isinstance(sim, Mapping):
            raise ConfigError(f"{source}: simulation: expected a table, got {type(sim).__name__}")
        known = {"adapt", "aero", "integrator", "command_rate_hz", "supervisor_rate_hz"}
        bad = sorted(set(sim) - known)
        if bad:
            raise ConfigError(f"{source}: simulation: unknown field(s) {', '.join(bad)}; "
                              f"allowed: {', '.join(sorted(known))}")
        for key in ("adapt", "aero"):
            if key in sim and not isinstance(sim[key], bool):
                raise ConfigError(f"{source}: simulation.{key}: expected true or false, got {sim[key]!r}")
        if "integrator" in sim and not isinstance(sim["integrator"], str):
            raise ConfigError(f"{source}: simulation.integrator: expected a string, got {sim['integrator']!r}")
        for key in ("command_rate_hz", "supervisor_rate_hz"):
            if key in sim:
                _number(sim[key], f"{source}: simulation.{key}")
        kwargs.update({k: (float(v) if k.endswith("_hz") else v) for k, v in sim.items()})
    sections = {"wind": WindSettings, "motion_capture": MotionCapture, "volume": Volume, "supervisor": Supervisor}
    for name, cls in sections.items():
        if name in data:
            kwargs[name] = dataclass_from_table(cls, data[name], source=f"{source}: {name}")
    try:
        return RotorPySettings(**kwargs)
    except ValueError as exc:
        text = str(exc)
        raise ConfigError(text if text.startswith(source) else f"{source}: {text}") from None


def settings_to_table(settings: RotorPySettings) -> dict[str, Any]:
    """The table :func:`settings_from_table` reads back to equal settings (JSON- and TOML-ready)."""
    return {
        "quad_params": _plain(dict(settings.quad_params)),
        "simulation": {"adapt": settings.adapt, "aero": settings.aero, "integrator": settings.integrator,
                       "command_rate_hz": settings.command_rate_hz,
                       "supervisor_rate_hz": settings.supervisor_rate_hz},
        "wind": dataclass_to_table(settings.wind),
        "motion_capture": dataclass_to_table(settings.motion_capture),
        "volume": dataclass_to_table(settings.volume),
        "supervisor": dataclass_to_table(settings.supervisor),
    }


def _plain(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def load_rotorpy_settings(path: str | Path) -> RotorPySettings:
    """Read a RotorPy plant TOML file (``--rotorpy FILE.toml``).

    Tables (all optional): ``[quad_params]`` overrides any entry of RotorPy's Hummingbird
    ``quad_params`` (``rotor_pos`` as ``[quad_params.rotor_pos]`` with r1…r4); ``[simulation]``
    with ``adapt``, ``aero``, ``integrator``, ``command_rate_hz``, ``supervisor_rate_hz``;
    ``[wind]``; and the arena's ``[motion_capture]``, ``[volume]``, ``[supervisor]``.
    Unknown tables or keys and wrong types raise :class:`ConfigError` naming the file and key.
    """
    path = as_path(path)
    return settings_from_table(read_toml(path), source=str(path))


def build_quad_params(settings: RotorPySettings, *, source: str = "settings") -> dict[str, Any]:
    """The RotorPy parameter dict a plant flies: shipped → adapted (if ``adapt``) → overrides."""
    qp = adapted_quad_params() if settings.adapt else shipped_quad_params()
    qp.update(validate_overrides(settings.quad_params, qp, source=source))
    _check_flyable(qp, source)
    return qp


