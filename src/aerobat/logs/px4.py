"""PX4 ULog files (``.ulg``), read with pyulog.

PX4 works in body FRD (x forward, y right, z down) and world NED; aerobat in body FLU and a
z-up world (here ENU: x east, y north, z up). The conversions are ``v_FLU = (x, −y, −z)`` of
the FRD vector, ``p_ENU = (E, N, −D)``, and the attitude ``R_ENU←FLU = P · R_NED←FRD · F``
with P the NED→ENU and F the FLU→FRD axis swaps.

Topics used: ``sensor_combined`` (gyro, accelerometer), ``actuator_outputs`` (PWM per motor,
scaled with the ``PWM_MIN``/``PWM_MAX`` parameters: 0 at PWM_MIN, 1 at PWM_MAX),
``vehicle_rates_setpoint``, ``vehicle_attitude``, ``vehicle_local_position``,
``battery_status``. Motors: PX4's quadrotor X (motor 1 front right and 2 rear left turn
counter-clockwise, 3 front left and 4 rear right clockwise).
"""

from __future__ import annotations

import contextlib
import io
from collections import Counter
from pathlib import Path

import numpy as np

from aerobat.errors import ConfigError, MissingDependency
from aerobat.quadrotor.flightlog import Channel, FlightLog, LogFormat, LogMetadata, MotorLayout, Signal

__all__ = ["PX4_QUADX_LAYOUT", "read_ulog"]

PX4_QUADX_LAYOUT = MotorLayout(
    names=("1", "2", "3", "4"),
    directions=((1.0, -1.0), (-1.0, 1.0), (1.0, 1.0), (-1.0, -1.0)),
    spins=(1, 1, -1, -1),
    mixer="PX4 quadrotor X",
)
# MAV_TYPE values of multirotors (MAVLink's enum: quadrotor, hexarotor, octorotor, tricopter,
# coaxial, dodecarotor, decarotor)
_MULTIROTOR_TYPES = {2: "quadrotor", 13: "hexarotor", 14: "octorotor", 15: "tricopter", 3: "coaxial helicopter",
                     29: "dodecarotor", 35: "decarotor"}
_MAV_TYPE_NAMES = {0: "generic", 1: "fixed wing", 4: "helicopter", 10: "ground rover", 11: "surface boat",
                   12: "submarine", 19: "VTOL", 20: "VTOL", 21: "VTOL", 22: "VTOL"}
_FLU = np.array([1.0, -1.0, -1.0])
_NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _pyulog():
    try:
        from pyulog import ULog
    except ImportError as exc:
        raise MissingDependency("pyulog", extra="logs", purpose="reading PX4 ULog files", detail=str(exc)) from None
    return ULog


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    n = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def _matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices to (n, 4) quaternions w, x, y, z with w ≥ 0 (Shepperd's method)."""
    out = np.empty((r.shape[0], 4))
    for k, m in enumerate(r):
        tr = m[0, 0] + m[1, 1] + m[2, 2]
        i = int(np.argmax([tr, m[0, 0], m[1, 1], m[2, 2]]))
        if i == 0:
            s = 2.0 * np.sqrt(1.0 + tr)
            q = (0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s)
        elif i == 1:
            s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
            q = ((m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s)
        elif i == 2:
            s = 2.0 * np.sqrt(1.0 - m[0, 0] + m[1, 1] - m[2, 2])
            q = ((m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s)
        else:
            s = 2.0 * np.sqrt(1.0 - m[0, 0] - m[1, 1] + m[2, 2])
            q = ((m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s)
        out[k] = q if q[0] >= 0 else tuple(-c for c in q)
    return out


def _printed_notes(text: str) -> list[str]:
    """What pyulog printed, as notes: each distinct line once, with how often it came, at most five."""
    counts = Counter(line.strip() for line in text.splitlines() if line.strip())
    notes = [f"pyulog: {line}" + (f" ({n} times)" if n > 1 else "") for line, n in list(counts.items())[:5]]
    if len(counts) > 5:
        notes.append(f"pyulog printed {len(counts) - 5} more distinct lines")
    return notes


def read_ulog(path: Path) -> list[FlightLog]:
    """The log of a ULog file (a ULog holds one)."""
    ULog = _pyulog()
    printed = io.StringIO()
    try:
        # pyulog prints its warnings ("no subscription found", "File corruption detected"): they become notes,
        # never lines on standard output, where they would break `--json` and CSV sent there
        with contextlib.redirect_stdout(printed):
            ulog = ULog(str(path))
    except Exception as exc:  # noqa: BLE001 - pyulog raises bare exceptions on damaged files
        raise ConfigError(f"{path}: not a readable ULog ({type(exc).__name__}: {exc})") from None
    topics = {}
    for d in ulog.data_list:
        if d.multi_id == 0 and len(d.data.get("timestamp", ())) > 0:
            topics[d.name] = d.data
    if not topics:
        raise ConfigError(f"{path}: the ULog holds no data")
    t0 = ulog.start_timestamp
    params = ulog.initial_parameters
    signals: dict[Channel, Signal] = {}
    notes: list[str] = _printed_notes(printed.getvalue())
    if getattr(ulog, "file_corruption", False):
        notes.append("pyulog reports file corruption; the readable part was kept")

    def times(topic: dict) -> np.ndarray:
        return (topic["timestamp"].astype(np.int64) - t0) * 1e-6

    def cols(topic: dict, names: list[str]) -> np.ndarray | None:
        if not all(n in topic for n in names):
            return None
        return np.column_stack([topic[n].astype(float) for n in names])

    xyz = ("x", "y", "z")
    sc = topics.get("sensor_combined")
    if sc is not None:
        gyro = cols(sc, [f"gyro_rad[{i}]" for i in range(3)])
        if gyro is not None:
            signals[Channel.GYRO] = Signal(Channel.GYRO, times(sc), gyro * _FLU, xyz, "rad/s",
                                           ("sensor_combined.gyro_rad",))
        acc = cols(sc, [f"accelerometer_m_s2[{i}]" for i in range(3)])
        if acc is not None:
            t_acc = times(sc) + sc.get("accelerometer_timestamp_relative", np.zeros(len(acc))) * 1e-6
            signals[Channel.SPECIFIC_FORCE] = Signal(Channel.SPECIFIC_FORCE, t_acc, acc * _FLU, xyz, "m/s²",
                                                     ("sensor_combined.accelerometer_m_s2",))
    ao = topics.get("actuator_outputs")
    layout = None
    mav_type = int(params.get("MAV_TYPE", 2))
    if ao is not None:
        count = int(np.max(ao.get("noutputs", np.array([4])))) if "noutputs" in ao else 4
        motors = min(count, 4) if mav_type == 2 else count
        pwm = cols(ao, [f"output[{i}]" for i in range(motors)])
        if pwm is not None and motors > 0:
            lo, hi = float(params.get("PWM_MIN", 1000)), float(params.get("PWM_MAX", 2000))
            signals[Channel.MOTOR_COMMAND] = Signal(
                Channel.MOTOR_COMMAND, times(ao), np.clip((pwm - lo) / (hi - lo), 0.0, None),
                tuple(str(i + 1) for i in range(motors)), "fraction",
                tuple(f"actuator_outputs.output[{i}]" for i in range(motors)))
            if mav_type == 2 and motors == 4:
                layout = PX4_QUADX_LAYOUT
                notes.append(f"motor commands from PWM with PWM_MIN {lo:g} and PWM_MAX {hi:g}; quadrotor X "
                             "mixer assumed (the ULog does not record the geometry)")
    rs = topics.get("vehicle_rates_setpoint")
    if rs is not None:
        rates = cols(rs, ["roll", "pitch", "yaw"])
        if rates is not None:
            signals[Channel.RATE_SETPOINT] = Signal(Channel.RATE_SETPOINT, times(rs), rates * _FLU, xyz, "rad/s",
                                                    ("vehicle_rates_setpoint.roll/pitch/yaw",))
        if "thrust" in rs:
            signals[Channel.THROTTLE] = Signal(Channel.THROTTLE, times(rs), rs["thrust"].astype(float),
                                               ("throttle",), "fraction", ("vehicle_rates_setpoint.thrust",))
    att = topics.get("vehicle_attitude")
    if att is not None:
        q = cols(att, [f"q[{i}]" for i in range(4)])
        if q is not None:
            r = _NED_TO_ENU @ _quat_to_matrix(q) @ np.diag(_FLU)
            signals[Channel.ATTITUDE] = Signal(Channel.ATTITUDE, times(att), _matrix_to_quat(r),
                                               ("w", "x", "y", "z"), "1", ("vehicle_attitude.q",))
    lp = topics.get("vehicle_local_position")
    if lp is not None:
        pos = cols(lp, ["x", "y", "z"])
        vel = cols(lp, ["vx", "vy", "vz"])
        if pos is not None:
            signals[Channel.POSITION] = Signal(Channel.POSITION, times(lp), pos @ _NED_TO_ENU.T, xyz, "m",
                                               ("vehicle_local_position.x/y/z",))
        if vel is not None:
            signals[Channel.VELOCITY] = Signal(Channel.VELOCITY, times(lp), vel @ _NED_TO_ENU.T, xyz, "m/s",
                                               ("vehicle_local_position.vx/vy/vz",))
    bs = topics.get("battery_status")
    if bs is not None and "voltage_v" in bs:
        signals[Channel.BATTERY_VOLTAGE] = Signal(Channel.BATTERY_VOLTAGE, times(bs), bs["voltage_v"].astype(float),
                                                  ("v",), "V", ("battery_status.voltage_v",))
    status = topics.get("vehicle_status")
    if status is not None and "arming_state" in status and not np.any(status["arming_state"] == 2):
        notes.append("vehicle_status.arming_state is never ARMED (2): the vehicle did not fly in this log")
    info = ulog.msg_info_dict
    vehicle_type = "multirotor" if mav_type in _MULTIROTOR_TYPES else _MAV_TYPE_NAMES.get(mav_type,
                                                                                          f"MAV_TYPE {mav_type}")
    metadata = LogMetadata(
        firmware=str(info.get("sys_name", "PX4")),
        firmware_version=str(info.get("ver_sw_release", "") or info.get("ver_sw", "")),
        board=str(info.get("ver_hw", "")),
        craft_name=str(info.get("sys_uuid", "")),
        vehicle_type=vehicle_type,
        parameters={k: f"{v:g}" if isinstance(v, float) else str(v) for k, v in params.items()},
        start_time=str(info.get("time_ref_utc", "")),
    )
    return [FlightLog(path=path, index=1, logs_in_file=1, source=LogFormat.ULOG, metadata=metadata, signals=signals,
                      motor_layout=layout, notes=tuple(notes))]
