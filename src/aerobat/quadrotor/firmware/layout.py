"""The firmware model's two flat vectors: its constants (``K_*``) and its memory (``Z_*``), laid out once.

:func:`constants` turns a :class:`~aerobat.quadrotor.firmware.config.FirmwareConfig` into the
constants vector in the firmware's own scalings (``pidInitConfig``, ``pidInitFilters``,
``initRcProcessing``, ``mixerInit``): the PID gains times ``PTERM_SCALE`` & co., filter gains,
the throttle lookup table, the TPA and anti-gravity factors. The memory vector holds everything
the firmware remembers from one loop to the next (filter states included, coefficients with them
so a moving cutoff moves with its filter).
"""

from __future__ import annotations

import math

import numpy as np

from aerobat.quadrotor.firmware import filters
from aerobat.quadrotor.firmware.config import AXES, FirmwareConfig

__all__ = ["N_CONSTANTS", "N_MEMORY", "Q_ALL", "Q_GYRO", "Q_MOTORS", "Q_PULSES", "Q_THROTTLE", "constants",
           "rates_curve"]


class _Slots:
    """Consecutive indices, handed out in order."""

    def __init__(self) -> None:
        self.size = 0

    def __call__(self, n: int = 1) -> int:
        start = self.size
        self.size += n
        return start


Q_PULSES = 1  # RC pulses in whole microseconds
Q_THROTTLE = 2  # the throttle's integer map onto its curve
Q_GYRO = 4  # the gyro's LSB (truncated)
Q_MOTORS = 8  # the motor packet's whole microseconds (truncated)
Q_ALL = Q_PULSES | Q_THROTTLE | Q_GYRO | Q_MOTORS

_k = _Slots()
# the loop
K_GYRO_DT = _k()  # gyro sample period [s]
K_PID_DT = _k()  # PID period [s]
K_DENOM = _k()  # gyro samples per PID loop
K_QUANTIZE = _k()  # the firmware's integer steps kept (Q_* bits); 0: a smooth model
# stick to set point
K_RATES_TYPE = _k()  # 0 BETAFLIGHT, 1 RACEFLIGHT, 2 KISS, 3 ACTUAL, 4 QUICK
K_QUICK_EXPO = _k()
K_RC_RATE = _k(3)
K_SRATE = _k(3)
K_EXPO = _k(3)
K_RATE_LIMIT = _k(3)
K_MAX_RC_RATE = _k(3)  # the curve at full stick (feedforward's limit)
K_DEADBAND = _k(3)
K_MIDRC = _k()
K_MINCHECK = _k()
K_YAW_DIRECTION = _k()  # rcCommand yaw = this · (pulse − mid)
K_THROTTLE_TABLE = _k(12)  # lookupThrottleRC [µs]
K_THROTTLE_LIMIT_TYPE = _k()  # 0 off, 1 scale, 2 clip
K_THROTTLE_LIMIT = _k()  # fraction
K_SMOOTHING = _k()  # RC smoothing on
K_SMOOTH_HZ = _k(3)  # set point, throttle, feedforward smoothing cutoffs [Hz] (0: from the radio's rate)
K_SMOOTH_FACTOR = _k(2)  # auto factors: set point and feedforward, throttle
K_RX_INTERVAL = _k()  # the radio's frame period [s]
K_AIRMODE_START = _k()  # throttle fraction from which air mode is active
# feedforward
K_FF_SMOOTH = _k()
K_FF_JITTER_INV = _k()
K_FF_BOOST = _k()
K_FF_MAX_RATE_LIMIT = _k()
K_FF_TRANSITION = _k()
K_FF_TRANSITION_INV = _k()
K_FF_INTERPOLATE = _k()
K_FF_YAW_HOLD_GAIN = _k()
K_FF_YAW_HOLD_TIME = _k()  # [s]
# the PID
K_KP = _k(3)
K_KI = _k(3)
K_KD = _k(3)
K_KF = _k(3)
K_DMAX_PERCENT = _k(3)
K_DMAX_GYRO_GAIN = _k()
K_DMAX_SETPOINT_GAIN = _k()
K_PIDSUM_LIMIT = _k()
K_PIDSUM_LIMIT_YAW = _k()
K_ITERM_LIMIT = _k()
K_ITERM_LIMIT_YAW = _k()
K_RELAX = _k()  # 0 off, 1 RP, 2 RPY, 3 RP_INC, 4 RPY_INC
K_RELAX_TYPE = _k()  # 0 gyro, 1 set point
K_RELAX_HZ = _k()
K_AG_ENABLED = _k()
K_AG_GAIN = _k()
K_AG_P_GAIN = _k()
K_AG_HZ = _k()
K_TPA_D_ONLY = _k()  # tpa_mode D (P unscaled)
K_TPA_BREAKPOINT = _k()
K_TPA_MULTIPLIER = _k()
K_TPA_LOW_BREAKPOINT = _k()
K_TPA_LOW_MULTIPLIER = _k()
K_TPA_LOW_ALWAYS = _k()
K_YAW_LOWPASS_HZ = _k()
K_MAX_VELOCITY = _k(3)  # set point acceleration limits [deg/s per PID loop] (0: none)
# filters: kind (filters.*), dynamic, min, max, expo, static cutoff [Hz]
K_GYRO_LPF1 = _k(6)
K_GYRO_LPF2 = _k(2)  # kind, cutoff
K_GYRO_NOTCH = _k(4)  # notch 1 centre, cutoff, notch 2 centre, cutoff [Hz]
K_DTERM_LPF1 = _k(6)
K_DTERM_LPF2 = _k(2)
K_DTERM_NOTCH = _k(2)
# mixer and outputs
K_MIXER = _k()  # mixer_type: 0 LEGACY, 1 LINEAR, 2 DYNAMIC
K_AIRMODE = _k()
K_MOTOR_LOW = _k()  # motor output at zero mix [µs-like units]
K_MOTOR_HIGH = _k()
K_MIN_COMMAND = _k()  # the disarmed output; the output packet is (motor − this) / 1000
K_BOOST = _k()
K_BOOST_HZ = _k()
K_THRUST_LINEAR = _k()
K_THROTTLE_COMPENSATE = _k()
K_YAW_SIGN = _k()  # −1 unless yaw_motors_reversed
N_CONSTANTS = _k.size

_z = _Slots()
Z_TIME_US = _z()  # the PID task's clock [µs]
Z_STEP = _z()  # gyro samples taken
Z_COUNTER = _z()  # pidUpdateCounter
Z_RC_COMMAND = _z(4)  # rcCommand roll, pitch, yaw (±500), throttle [µs]
Z_RX_NEW = _z()
Z_RX_INTERVAL = _z(2)  # current, previous [s]
Z_RAW_SETPOINT = _z(3)
Z_DEFLECTION = _z(3)
Z_SETPOINT = _z(3)  # the smoothed set point the PID tracks [deg/s]
Z_PREV_COMMAND = _z(3)
Z_PREV_DELTA_ABS = _z(3)
Z_PREV_SETPOINT = _z(3)
Z_PREV_SPEED = _z(3)
Z_PREV_SPEED_DELTA = _z(3)
Z_PREV_DUPLICATE = _z(3)
Z_PREV_RX_INTERVAL = _z()
Z_FF_RAW = _z(3)
Z_FF = _z(3)
Z_YAW_HOLD = _z()
Z_TO_SMOOTH = _z(4)
Z_SMOOTH = _z(4 * filters.SIZE)
Z_FF_SMOOTH = _z(3 * filters.SIZE)
Z_AIRMODE_ACTIVE = _z()
Z_ITERM_RESET = _z()
Z_GYRO_LPF2 = _z(3 * filters.SIZE)
Z_GYRO_SAMPLE = _z(3)
Z_GYRO_COUNT = _z()  # samples summed since the last filter run (no gyro lowpass 2)
Z_GYRO_NOTCH1 = _z(3 * filters.SIZE)
Z_GYRO_NOTCH2 = _z(3 * filters.SIZE)
Z_GYRO_LPF1 = _z(3 * filters.SIZE)
Z_GYRO = _z(3)  # gyroADCf [deg/s]
Z_DTERM_NOTCH = _z(3 * filters.SIZE)
Z_DTERM_LPF1 = _z(3 * filters.SIZE)
Z_DTERM_LPF2 = _z(3 * filters.SIZE)
Z_PREV_DTERM = _z(3)
Z_WINDUP = _z(3 * filters.SIZE)
Z_YAW_P = _z(filters.SIZE)
Z_DMAX_RANGE = _z(3 * filters.SIZE)
Z_DMAX_LOW = _z(3 * filters.SIZE)
Z_ACCEL_PREV = _z(3)
Z_PID = _z(4 * 3)  # P, I, D, F per axis (rows by term)
Z_PID_SUM = _z(3)
Z_PID_SETPOINT = _z(3)  # the set point the PID used (what blackbox logs)
Z_AG = _z(filters.SIZE)
Z_AG_D = _z()
Z_AG_PREV = _z()
Z_TPA = _z()
Z_TPA_FADED = _z()
Z_BOOST = _z(filters.SIZE)
Z_DYN_LAST_US = _z()
Z_DYN_PREV = _z()
Z_MIX = _z(4)  # the mixer's scratch
Z_MOTOR = _z(4)  # Betaflight's motor[] M1..M4 [output units]
Z_PACKET = _z(4)  # the SITL's motor packet, slot order [0, 1]
N_MEMORY = _z.size

_RATES = {"BETAFLIGHT": 0, "RACEFLIGHT": 1, "KISS": 2, "ACTUAL": 3, "QUICK": 4}
_LOWPASS = {"PT1": filters.PT1, "BIQUAD": filters.BIQUAD_DF2, "PT2": filters.PT2, "PT3": filters.PT3}
_RELAX = {"OFF": 0, "RP": 1, "RPY": 2, "RP_INC": 3, "RPY_INC": 4}
_THROTTLE_LIMIT = {"OFF": 0, "SCALE": 1, "CLIP": 2}
_PTERM_SCALE = 0.032029
_ITERM_SCALE = 0.244381
_DTERM_SCALE = 0.000529
_FEEDFORWARD_SCALE = 0.013754
_ANTIGRAVITY_KP = 0.0034
_D_MAX_LOWPASS_HZ = 35.0
_D_MAX_GAIN_FACTOR = 0.00008


def rates_curve(kind: int, rc_rate: float, srate: float, expo: float, x: float, quick_expo: bool = False) -> float:
    """Betaflight 4.6's rate curve at stick ``x`` ∈ [−1, 1] (``applyRates`` of fc/rc.c), before ``rate_limit``."""
    a = abs(x)
    if kind == 0:  # BETAFLIGHT
        e = expo / 100.0
        xc = x * a**3 * e + x * (1.0 - e) if expo else x
        rcr = rc_rate / 100.0
        if rcr > 2.0:
            rcr += 14.54 * (rcr - 2.0)
        rate = 200.0 * rcr * xc
        if srate:
            rate /= min(max(1.0 - a * srate / 100.0, 0.01), 1.0)
        return rate
    if kind == 1:  # RACEFLIGHT
        xc = (1.0 + 0.01 * expo * (x * x - 1.0)) * x
        return 10.0 * rc_rate * xc * (1.0 + a * srate * 0.01)
    if kind == 2:  # KISS
        e = expo / 100.0
        use = 1.0 / min(max(1.0 - a * srate / 100.0, 0.01), 1.0)
        return min(max(2000.0 * use * (x**3 * e + x * (1.0 - e)) * (rc_rate / 1000.0), -1998.0), 1998.0)
    if kind == 3:  # ACTUAL
        e = expo / 100.0
        curve = a * (x**5 * e + x * (1.0 - e))
        return x * rc_rate * 10.0 + max(0.0, srate * 10.0 - rc_rate * 10.0) * curve
    rcr = int(rc_rate) * 2  # QUICK: uint16 in the firmware
    top = max(srate * 10.0, rcr)
    factor = (top / rcr - 1.0) / (top / rcr)
    e = expo / 100.0
    if quick_expo:
        curve = x**3 * e + x * (1.0 - e)
        rate = curve * rcr / min(max(1.0 - a * factor, 0.01), 1.0)
    else:
        curve = a**3 * e + a * (1.0 - e)
        rate = x * rcr / min(max(1.0 - curve * factor, 0.01), 1.0)
    return min(max(rate, -1998.0), 1998.0)


def _bezier(x: float, p0x: float, p1x: float, p2x: float, p0y: float, p1y: float, p2y: float) -> float:
    a = p0x - 2.0 * p1x + p2x
    b = 2.0 * p1x - 2.0 * p0x
    c = p0x - x
    t = 0.0
    if abs(a) < 1e-6:
        if abs(b) > 1e-6:
            t = -c / b
    else:
        disc = b * b - 4.0 * a * c
        if disc >= 0.0:
            root = math.sqrt(disc)
            t1 = (-b + root) / (2.0 * a)
            t = t1 if 0.0 <= t1 <= 1.0 else (-b - root) / (2.0 * a)
    t = min(max(t, 0.0), 1.0)
    return (1.0 - t) ** 2 * p0y + 2.0 * (1.0 - t) * t * p1y + t * t * p2y


def _throttle_table(mid: float, hover: float, expo: float) -> list[float]:
    """lookupThrottleRC (fc/rc.c initRcProcessing): 12 points of the throttle curve, µs, rounded as lrintf."""
    out = []
    for i in range(12):
        x = i / 11.0
        if x <= mid:
            y = _bezier(x, 0.0, mid * 0.5, mid, 0.0, hover * 0.5 * (1.0 + expo), hover)
        else:
            y = _bezier(x, mid, (1.0 + mid) * 0.5, 1.0, hover, 1.0 + (hover - 1.0) * 0.5 * (1.0 + expo), 1.0)
        out.append(float(np.rint(1000.0 + 1000.0 * y)))
    return out


def _lowpass(c: FirmwareConfig, prefix: str, dynamic: bool) -> list[float]:
    kind = _LOWPASS[c.value(f"{prefix}_type")]
    static = c.number(f"{prefix}_static_hz")
    if not dynamic:
        return [float(kind if static > 0 else filters.NONE), static]
    dyn_min = c.number(f"{prefix}_dyn_min_hz")
    if dyn_min > 0 and kind == filters.BIQUAD_DF2:
        kind = filters.BIQUAD_DF1  # a biquad whose cutoff moves runs in direct form I
    start = dyn_min if dyn_min > 0 else static
    return [float(kind if start > 0 else filters.NONE), 1.0 if dyn_min > 0 else 0.0, dyn_min,
            c.number(f"{prefix}_dyn_max_hz"), c.number(f"{prefix}_dyn_expo"), start]


def constants(c: FirmwareConfig, *, radio_period_s: float, quantize: int = 0, duplicates: bool = False) -> np.ndarray:
    """The constants vector for ``c`` flown by a radio sending a frame every ``radio_period_s``.

    ``quantize``: the firmware's integer steps kept (``Q_*`` bits; else their mean effect);
    ``duplicates``: feedforward treats a frame equal to the last as a repeat, as 4.6 does with any
    receiver but CRSF (else every frame is news, as with CRSF: the flight is smooth in the program).
    """
    k = np.zeros(N_CONSTANTS)
    denom = c.pid_process_denom
    k[K_GYRO_DT] = c.gyro_period_s
    k[K_PID_DT] = c.pid_period_s
    k[K_DENOM] = denom
    k[K_QUANTIZE] = float(quantize)
    kind = _RATES[c.value("rates_type")]
    k[K_RATES_TYPE] = kind
    k[K_QUICK_EXPO] = 1.0 if c.on("quickrates_rc_expo") else 0.0
    for i, axis in enumerate(AXES):
        k[K_RC_RATE + i] = c.number(f"{axis}_rc_rate")
        k[K_SRATE + i] = c.number(f"{axis}_srate")
        k[K_EXPO + i] = c.number(f"{axis}_expo")
        k[K_RATE_LIMIT + i] = c.number(f"{axis}_rate_limit")
        k[K_MAX_RC_RATE + i] = rates_curve(kind, k[K_RC_RATE + i], k[K_SRATE + i], k[K_EXPO + i], 1.0,
                                           bool(k[K_QUICK_EXPO]))
        k[K_DEADBAND + i] = c.number("yaw_deadband" if axis == "yaw" else "deadband")
    k[K_MIDRC] = c.number("mid_rc")
    k[K_MINCHECK] = c.number("min_check")
    k[K_YAW_DIRECTION] = 1.0 if c.on("yaw_control_reversed") else -1.0
    k[K_THROTTLE_TABLE:K_THROTTLE_TABLE + 12] = _throttle_table(
        c.number("thr_mid") / 100.0, c.number("thr_hover") / 100.0, c.number("thr_expo") / 100.0)
    k[K_THROTTLE_LIMIT_TYPE] = _THROTTLE_LIMIT[c.value("throttle_limit_type")]
    k[K_THROTTLE_LIMIT] = c.number("throttle_limit_percent") / 100.0
    k[K_SMOOTHING] = 1.0 if c.on("rc_smoothing") else 0.0
    k[K_SMOOTH_HZ:K_SMOOTH_HZ + 3] = [c.number("rc_smoothing_setpoint_cutoff"),
                                      c.number("rc_smoothing_throttle_cutoff"),
                                      c.number("rc_smoothing_feedforward_cutoff")]
    k[K_SMOOTH_FACTOR] = 1.5 / (1.0 + c.number("rc_smoothing_auto_factor") / 10.0)
    k[K_SMOOTH_FACTOR + 1] = 1.5 / (1.0 + c.number("rc_smoothing_auto_factor_throttle") / 10.0)
    k[K_RX_INTERVAL] = radio_period_s
    k[K_AIRMODE_START] = c.number("airmode_start_throttle_percent") / 100.0
    k[K_FF_SMOOTH] = 1.0 - 0.01 * c.number("feedforward_smooth_factor")
    k[K_FF_JITTER_INV] = 1.0 / (1.0 + c.number("feedforward_jitter_factor"))
    k[K_FF_BOOST] = 0.001 * c.number("feedforward_boost")
    k[K_FF_MAX_RATE_LIMIT] = c.number("feedforward_max_rate_limit")
    transition = c.number("feedforward_transition")
    k[K_FF_TRANSITION] = transition / 100.0
    k[K_FF_TRANSITION_INV] = 100.0 / transition if transition else 0.0
    k[K_FF_INTERPOLATE] = 1.0 if duplicates else 0.0
    hold_ms = c.number("feedforward_yaw_hold_time")
    hold_gain = c.number("feedforward_yaw_hold_gain")
    k[K_FF_YAW_HOLD_GAIN] = hold_gain * 150.0 / (hold_ms + 50.0) if hold_ms < 100 else hold_gain
    k[K_FF_YAW_HOLD_TIME] = 0.001 * hold_ms
    for i, axis in enumerate(AXES):
        d = c.number(f"d_{axis}")
        k[K_KP + i] = _PTERM_SCALE * c.number(f"p_{axis}")
        k[K_KI + i] = _ITERM_SCALE * c.number(f"i_{axis}") * (2.5 if axis == "yaw" else 1.0)
        k[K_KD + i] = _DTERM_SCALE * d
        k[K_KF + i] = _FEEDFORWARD_SCALE * c.number(f"f_{axis}") * 0.01
        d_max = c.number(f"d_max_{axis}")
        k[K_DMAX_PERCENT + i] = d_max / d if d > 0 and d_max > d else 1.0
    gain = c.number("d_max_gain")
    k[K_DMAX_GYRO_GAIN] = _D_MAX_GAIN_FACTOR * gain / _D_MAX_LOWPASS_HZ
    k[K_DMAX_SETPOINT_GAIN] = _D_MAX_GAIN_FACTOR * gain * c.number("d_max_advance") / 100.0 / _D_MAX_LOWPASS_HZ
    k[K_PIDSUM_LIMIT] = c.number("pidsum_limit")
    k[K_PIDSUM_LIMIT_YAW] = c.number("pidsum_limit_yaw")
    windup = c.number("iterm_windup")
    k[K_ITERM_LIMIT] = 0.01 * windup * k[K_PIDSUM_LIMIT]
    k[K_ITERM_LIMIT_YAW] = 0.01 * windup * k[K_PIDSUM_LIMIT_YAW]
    k[K_RELAX] = _RELAX[c.value("iterm_relax")]
    k[K_RELAX_TYPE] = 1.0 if c.value("iterm_relax_type") == "SETPOINT" else 0.0
    k[K_RELAX_HZ] = c.number("iterm_relax_cutoff")
    k[K_AG_ENABLED] = 1.0  # FEATURE_ANTI_GRAVITY: always on in 4.6
    k[K_AG_GAIN] = c.number("anti_gravity_gain")
    k[K_AG_P_GAIN] = c.number("anti_gravity_p_gain") / 100.0 * _ANTIGRAVITY_KP
    k[K_AG_HZ] = c.number("anti_gravity_cutoff_hz")
    k[K_TPA_D_ONLY] = 1.0 if c.value("tpa_mode") == "D" else 0.0
    breakpoint_ = min(max((c.number("tpa_breakpoint") - 1000.0) / 1000.0, 0.0), 0.99)
    k[K_TPA_BREAKPOINT] = breakpoint_
    k[K_TPA_MULTIPLIER] = (c.number("tpa_rate") / 100.0) / (1.0 - breakpoint_)
    low = min(min(max((c.number("tpa_low_breakpoint") - 1000.0) / 1000.0, 0.01), 1.0), breakpoint_)
    k[K_TPA_LOW_BREAKPOINT] = low
    k[K_TPA_LOW_MULTIPLIER] = c.number("tpa_low_rate") / (100.0 * low)
    k[K_TPA_LOW_ALWAYS] = 1.0 if c.on("tpa_low_always") else 0.0
    k[K_YAW_LOWPASS_HZ] = c.number("yaw_lowpass_hz")
    pid_dt = c.pid_period_s
    k[K_MAX_VELOCITY] = c.number("acc_limit") * 100.0 * pid_dt
    k[K_MAX_VELOCITY + 1] = k[K_MAX_VELOCITY]
    k[K_MAX_VELOCITY + 2] = c.number("acc_limit_yaw") * 100.0 * pid_dt
    k[K_GYRO_LPF1:K_GYRO_LPF1 + 6] = _lowpass(c, "gyro_lpf1", True)
    k[K_GYRO_LPF2:K_GYRO_LPF2 + 2] = _lowpass(c, "gyro_lpf2", False)
    k[K_GYRO_NOTCH:K_GYRO_NOTCH + 4] = [c.number("gyro_notch1_hz"), c.number("gyro_notch1_cutoff"),
                                         c.number("gyro_notch2_hz"), c.number("gyro_notch2_cutoff")]
    k[K_DTERM_LPF1:K_DTERM_LPF1 + 6] = _lowpass(c, "dterm_lpf1", True)
    k[K_DTERM_LPF2:K_DTERM_LPF2 + 2] = _lowpass(c, "dterm_lpf2", False)
    k[K_DTERM_NOTCH:K_DTERM_NOTCH + 2] = [c.number("dterm_notch_hz"), c.number("dterm_notch_cutoff")]
    mixer = c.value("mixer_type")
    if mixer not in ("LEGACY", "LINEAR", "DYNAMIC"):
        from aerobat.errors import ConfigError

        raise ConfigError(f"firmware configuration: mixer_type = {mixer}: the design model mixes LEGACY, LINEAR "
                          f"and DYNAMIC (design on the paper's model instead: --design-model paper)")
    k[K_MIXER] = ("LEGACY", "LINEAR", "DYNAMIC").index(mixer)
    k[K_AIRMODE] = 1.0 if c.airmode else 0.0
    min_command = c.number("min_command")
    low_output = min_command + c.number("motor_idle") * 0.1
    limit = min(c.number("motor_output_limit"), 100.0) / 100.0
    max_throttle = c.number("max_throttle")
    k[K_MOTOR_LOW] = low_output
    k[K_MOTOR_HIGH] = max_throttle - (max_throttle - low_output) * (1.0 - limit)
    k[K_MIN_COMMAND] = min_command
    k[K_BOOST] = c.number("throttle_boost") * 0.1
    k[K_BOOST_HZ] = c.number("throttle_boost_cutoff")
    linear = c.number("thrust_linear") / 100.0
    k[K_THRUST_LINEAR] = linear
    k[K_THROTTLE_COMPENSATE] = linear - 0.5 * linear * linear
    k[K_YAW_SIGN] = 1.0 if c.on("yaw_motors_reversed") else -1.0
    return k
