"""MSP (MultiWii Serial Protocol) v1/v2 client for Betaflight.

Frames (all little-endian)::

    v1 request   $ M <  size:u8 cmd:u8 payload checksum:u8   checksum = XOR(size, cmd, payload)
    v1 response  $ M >  (or $ M ! for an error), same layout
    v2 request   $ X <  flag:u8 cmd:u16 size:u16 payload crc:u8   crc = CRC-8/DVB-S2(flag..payload)
    v2 response  $ X >  (or $ X !), same layout

Decoders are given for the requests the plant needs; the payload layouts are
those of Betaflight 4.6 ``src/main/msp/msp.c`` (checked there).

MSP traffic reaches the firmware at wall-clock moments, so using it on a
lockstep SITL makes a run non-deterministic; use it for diagnosis only.
"""

from __future__ import annotations

import collections
import enum
import math
import struct
import time
from collections.abc import Sequence
from dataclasses import dataclass

from .errors import LinkTimeout, MspError
from .transport import Transport

__all__ = [
    "ARMING_DISABLE_FLAG_NAMES",
    "FEATURE_RX_MSP",
    "MSP_API_VERSION",
    "MSP_ATTITUDE",
    "MSP_BATTERY_STATE",
    "MSP_FAILSAFE_CONFIG",
    "MSP_FEATURE_CONFIG",
    "MSP_MODE_RANGES",
    "MSP_MOTOR",
    "MSP_RC",
    "MSP_SET_RAW_RC",
    "MSP_STATUS",
    "MSP_STATUS_EX",
    "ApiVersion",
    "Attitude",
    "Battery",
    "BatteryAlert",
    "FailsafeConfig",
    "FailsafeProcedure",
    "MspClient",
    "MspModeRange",
    "MspVersion",
    "StatusEx",
    "crc8_dvb_s2",
    "decode_arming_disable_flags",
    "encode_request",
]

MSP_API_VERSION = 1
MSP_MODE_RANGES = 34
MSP_FEATURE_CONFIG = 36
MSP_FAILSAFE_CONFIG = 75
MSP_STATUS = 101
MSP_MOTOR = 104
MSP_RC = 105
MSP_ATTITUDE = 108
MSP_BATTERY_STATE = 130
MSP_STATUS_EX = 150
MSP_SET_RAW_RC = 200

ARMING_DISABLE_FLAG_NAMES: tuple[str, ...] = (
    "NOGYRO", "FAILSAFE", "RXLOSS", "NOT_DISARMED", "BOXFAILSAFE", "RUNAWAY", "CRASH", "THROTTLE",
    "ANGLE", "BOOTGRACE", "NOPREARM", "LOAD", "CALIB", "CLI", "CMS", "BST", "MSP", "PARALYZE", "GPS",
    "RESCUE_SW", "DSHOT_TELEM", "REBOOT_REQD", "DSHOT_BBANG", "NO_ACC_CAL", "MOTOR_PROTO",
    "FLIP_SWITCH", "ALT_HOLD_SW", "POS_HOLD_SW", "ARM_SWITCH",
)  # fmt: skip
"""Bit i of the arming-disable mask is name i (``armingDisableFlagNames`` in fc/runtime_config.c)."""


class MspVersion(enum.Enum):
    """MSP protocol version used for requests."""

    V1 = 1
    V2 = 2


def crc8_dvb_s2(data: bytes, crc: int = 0) -> int:
    """CRC-8/DVB-S2 (polynomial 0xD5), as MSP v2 uses it."""
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0xD5) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def encode_request(command: int, payload: bytes = b"", version: MspVersion = MspVersion.V2) -> bytes:
    """Encode one MSP request frame.

    Parameters
    ----------
    command : int
        MSP command id (v1: 0..254, v2: 0..65535).
    payload : bytes
        Request payload (v1: at most 254 bytes).
    version : MspVersion
        Frame format.
    """
    if version is MspVersion.V1:
        if not 0 <= command < 255 or len(payload) > 254:
            raise ValueError("MSP v1 carries command ids < 255 and payloads <= 254 bytes")
        checksum = len(payload) ^ command
        for byte in payload:
            checksum ^= byte
        return b"$M<" + bytes((len(payload), command)) + payload + bytes((checksum,))
    body = struct.pack("<BHH", 0, command, len(payload)) + payload
    return b"$X<" + body + bytes((crc8_dvb_s2(body),))


@dataclass(frozen=True)
class _Frame:
    command: int
    payload: bytes
    is_error: bool


MAX_ANSWER_BYTES = 4112
"""The longest MSP answer Betaflight sends (msp_serial.h: ``MSP_PORT_OUTBUF_SIZE`` with dataflash reads): a
header that declares more is not a frame start but torn bytes."""


def _frame_at(buffer: bytearray, start: int) -> tuple[_Frame | None, int]:
    """The answer frame that starts at ``buffer[start]`` (a ``$``).

    Returns ``(frame, end)`` for a complete frame with a good checksum, ``(None, 0)`` when the bytes
    there cannot start one (another direction, a size no answer has, a bad checksum) and
    ``(None, -1)`` when they may, but it has not all arrived yet.
    """
    if len(buffer) - start < 3:
        return None, -1
    kind, direction = buffer[start + 1], buffer[start + 2]
    if kind not in b"MX" or direction not in b">!":
        return None, 0
    if kind == ord("M"):
        if len(buffer) - start < 5:
            return None, -1
        size, command = buffer[start + 3], buffer[start + 4]
        end = start + 5 + size + 1
        if len(buffer) < end:
            return None, -1
        payload = bytes(buffer[start + 5 : end - 1])
        checksum = size ^ command
        for byte in payload:
            checksum ^= byte
        if checksum != buffer[end - 1]:
            return None, 0
    else:
        if len(buffer) - start < 8:
            return None, -1
        _flag, command, size = struct.unpack_from("<BHH", buffer, start + 3)
        if size > MAX_ANSWER_BYTES:
            return None, 0
        end = start + 8 + size + 1
        if len(buffer) < end:
            return None, -1
        if crc8_dvb_s2(bytes(buffer[start + 3 : end - 1])) != buffer[end - 1]:
            return None, 0
        payload = bytes(buffer[start + 8 : end - 1])
    return _Frame(command, payload, direction == ord("!")), end


def _parse_frame(buffer: bytearray) -> tuple[_Frame | None, int]:
    """Find the first complete response frame in ``buffer``.

    Returns the frame (or None if none is complete yet) and how many bytes of
    ``buffer`` can be dropped. Bytes before a frame start and frames with a
    bad checksum are skipped. A frame start whose rest has not arrived is
    waited for, unless a complete frame follows it: then its bytes were torn
    (lost on the line, or a header whose size came from the next frame's bytes,
    which would otherwise hold every later answer back until kilobytes arrive)
    and the parser goes on from the complete frame.
    """
    start = 0
    while True:
        start = buffer.find(b"$", start)
        if start < 0:
            return None, len(buffer)
        frame, end = _frame_at(buffer, start)
        if frame is not None:
            return frame, end
        if end == 0:
            start += 1
            continue
        later = buffer.find(b"$", start + 1)
        while later >= 0:
            frame, end = _frame_at(buffer, later)
            if frame is not None:
                return frame, end
            later = buffer.find(b"$", later + 1)
        return None, start


@dataclass(frozen=True)
class ApiVersion:
    """MSP_API_VERSION: MSP protocol version and API version major.minor."""

    protocol: int
    major: int
    minor: int


@dataclass(frozen=True)
class Attitude:
    """MSP_ATTITUDE: the firmware's attitude estimate, in degrees (roll right +, pitch as Betaflight reports it)."""

    roll_deg: float
    pitch_deg: float
    yaw_deg: float


FEATURE_RX_MSP = 1 << 14
"""The feature bit of an MSP receiver (``featureConfig()->enabledFeatures``, config/feature.h)."""

_MODE_STEP_US, _MODE_RANGE_MIN_US = 25, 900  # fc/rc_modes.h: MODE_STEP_TO_CHANNEL_VALUE


@dataclass(frozen=True)
class MspModeRange:
    """One mode activation range as MSP_MODE_RANGES reports it.

    Attributes
    ----------
    permanent_id : the box's permanent id (msp/msp_box.c: ARM 0, ANGLE 1, …).
    aux : the AUX channel, counting from 1 (AUX1 is RC channel 5).
    low_us, high_us : the active range in microseconds (25 µs steps from 900).
    """

    permanent_id: int
    aux: int
    low_us: int
    high_us: int


class FailsafeProcedure(enum.IntEnum):
    """What the firmware does in failsafe's stage 2 (``failsafeProcedure_e`` in flight/failsafe.h)."""

    AUTO_LANDING = 0
    DROP = 1
    GPS_RESCUE = 2


@dataclass(frozen=True)
class FailsafeConfig:
    """MSP_FAILSAFE_CONFIG: what the firmware does when the receiver goes silent.

    Attributes
    ----------
    delay_s : stage 1 (sticks centred, throttle at ``failsafe_throttle``) lasts this long after the
        300 ms hold, before stage 2 (``failsafe_delay``, 0.1 s units).
    landing_time_s : AUTO_LANDING's time before the motors stop (``failsafe_landing_time``).
    procedure : stage 2's procedure (a number the enum does not know stays an ``int``).
    """

    delay_s: float
    landing_time_s: float
    procedure: FailsafeProcedure | int

    @classmethod
    def decode(cls, payload: bytes) -> FailsafeConfig:
        """From MSP_FAILSAFE_CONFIG's payload (delay u8, landing time u8, throttle u16, switch mode u8,
        throttle-low delay u16, procedure u8; msp/msp.c)."""
        delay, landing, _throttle, _switch, _low_delay, procedure = struct.unpack_from("<BBHBHB", payload)
        known = procedure in FailsafeProcedure._value2member_map_
        return cls(delay / 10.0, landing / 10.0, FailsafeProcedure(procedure) if known else procedure)


class BatteryAlert(enum.IntEnum):
    """The firmware's battery state (``batteryState_e`` in sensors/battery.h)."""

    OK = 0
    WARNING = 1
    CRITICAL = 2
    NOT_PRESENT = 3
    INIT = 4


@dataclass(frozen=True)
class Battery:
    """MSP_BATTERY_STATE: what the flight controller measures of its battery.

    Attributes
    ----------
    cell_count : cells detected (0: no battery detected).
    capacity_mah : the configured capacity.
    voltage_v : the pack voltage (0.01 V resolution).
    drawn_mah : charge drawn since power-up.
    current_a : the current (0.01 A resolution; 0 without a current sensor).
    alert : the firmware's own verdict (warning and critical come from its ``vbat_*_cell_voltage`` settings).
    """

    cell_count: int
    capacity_mah: int
    voltage_v: float
    drawn_mah: int
    current_a: float
    alert: BatteryAlert

    @classmethod
    def decode(cls, payload: bytes) -> Battery:
        """Decode the MSP_BATTERY_STATE payload (layout from msp.c, ``case MSP_BATTERY_STATE``)."""
        cells, capacity, _legacy_decivolt, drawn, current_centiamp, alert, centivolt = struct.unpack_from(
            "<BHBHhBH", payload, 0)
        return cls(cells, capacity, centivolt / 100.0, drawn, current_centiamp / 100.0, BatteryAlert(alert))

    @property
    def cell_voltage_v(self) -> float:
        """The mean cell voltage (NaN when no cell is detected)."""
        return self.voltage_v / self.cell_count if self.cell_count else float("nan")


def decode_arming_disable_flags(mask: int) -> tuple[str, ...]:
    """Names of the set bits of an arming-disable mask, lowest bit first."""
    return tuple(
        ARMING_DISABLE_FLAG_NAMES[bit] if bit < len(ARMING_DISABLE_FLAG_NAMES) else f"BIT{bit}"
        for bit in range(32)
        if mask >> bit & 1
    )


@dataclass(frozen=True)
class StatusEx:
    """MSP_STATUS_EX, the fields the plant uses.

    Attributes
    ----------
    pid_cycle_time_us : int
        Latest PID task interval (simulated microseconds on the lockstep SITL).
    armed : bool
        Bit 0 of the flight-mode flags (BOXARM is always the first active box).
    flight_mode_flags : int
        First 32 flight-mode bits, indexed by the active boxes (MSP_BOXIDS order).
    cpu_load_percent : int
        Average system load (0 on the SITL).
    arming_disable_mask : int
        Raw arming-disable bits.
    arming_disable_flags : tuple of str
        Their names (e.g. ``("RXLOSS", "CALIB")``); empty when arming is allowed.
    """

    pid_cycle_time_us: int
    armed: bool
    flight_mode_flags: int
    cpu_load_percent: int
    arming_disable_mask: int
    arming_disable_flags: tuple[str, ...]

    @classmethod
    def decode(cls, payload: bytes) -> StatusEx:
        """Decode the MSP_STATUS_EX payload (layout from msp.c, ``case MSP_STATUS_EX``)."""
        cycle_time_us, _i2c_errors, _sensors, mode_flags, _profile, load = struct.unpack_from("<HHHIBH", payload, 0)
        offset = 13 + 2  # pid profile count, rate profile index
        extra_mode_bytes = payload[offset]
        offset += 1 + extra_mode_bytes
        _flag_count = payload[offset]
        (mask,) = struct.unpack_from("<I", payload, offset + 1)
        return cls(
            pid_cycle_time_us=cycle_time_us,
            armed=bool(mode_flags & 1),
            flight_mode_flags=mode_flags,
            cpu_load_percent=load,
            arming_disable_mask=mask,
            arming_disable_flags=decode_arming_disable_flags(mask),
        )


def _rc_payload(channels_us: Sequence[int]) -> bytes:
    values = [int(c) for c in channels_us]
    if any(not 0 <= v <= 0xFFFF for v in values):
        raise ValueError(f"RC channels must be 0 … 65535 µs, got {values}")
    return struct.pack(f"<{len(values)}H", *values)


class MspClient:
    """Request/response MSP over a :class:`~.transport.Transport`.

    Parameters
    ----------
    transport : Transport
        Byte link to the flight controller.
    version : MspVersion
        Frame format for requests (Betaflight answers in the same format).
    timeout_s : float
        Default time to wait for a complete answer.
    """

    def __init__(self, transport: Transport, version: MspVersion = MspVersion.V2, timeout_s: float = 1.0) -> None:
        self._transport = transport
        self._version = version
        self._timeout_s = timeout_s
        self._buffer = bytearray()
        self.discarded: collections.Counter[int] = collections.Counter()
        """Answers :meth:`request` read and dropped (another command's), counted by command."""
        self.answered_at_s = -math.inf
        """``time.monotonic()`` when the last complete answer (any command's) was read: the link's sign of life."""

    def request(self, command: int, payload: bytes = b"", timeout_s: float | None = None) -> bytes:
        """Send one request and return the payload of its answer.

        Answers to other commands (late answers to earlier requests, acknowledgements of
        :meth:`post`-ed frames) are discarded and counted in :attr:`discarded` by command, so
        that a caller pairing acknowledgements with what it posted stays in step.

        Raises
        ------
        LinkTimeout
            No answer within the timeout.
        MspError
            The firmware answered with an error frame (unknown command, bad payload).
        """
        timeout_s = self._timeout_s if timeout_s is None else timeout_s
        self._transport.write(encode_request(command, payload, self._version))
        deadline = time.monotonic() + timeout_s
        while True:
            frame, consumed = _parse_frame(self._buffer)
            del self._buffer[:consumed]
            if frame is not None:
                self.answered_at_s = time.monotonic()
                if frame.command != command:
                    self.discarded[frame.command] += 1
                    continue
                if frame.is_error:
                    raise MspError(f"the flight controller rejected MSP command {command}")
                return frame.payload
            remaining_s = deadline - time.monotonic()
            if remaining_s <= 0:
                raise LinkTimeout(f"no answer to MSP command {command} within {timeout_s} s")
            self._buffer += self._transport.read(4096, remaining_s)

    def post(self, command: int, payload: bytes = b"") -> None:
        """Send a request without waiting for its answer (a stream of RC frames: the answers are collected later)."""
        self._transport.write(encode_request(command, payload, self._version))

    def collect(self, timeout_s: float = 0.0) -> list[tuple[int, bytes]]:
        """Read what has arrived (waiting at most ``timeout_s`` for the first bytes) and return its answers.

        The answers are ``(command, payload)`` pairs, oldest first (an error frame's payload is empty): the
        acknowledgements of :meth:`post`-ed requests, a sign of life of the flight controller, and the
        answers of requests posted to be read later. A :meth:`request` later is not confused by a partial
        answer left over: it resynchronizes on the next frame.
        """
        self._buffer += self._transport.read(4096, timeout_s)
        answers: list[tuple[int, bytes]] = []
        while True:
            frame, consumed = _parse_frame(self._buffer)
            del self._buffer[:consumed]
            if frame is None:
                return answers
            self.answered_at_s = time.monotonic()
            answers.append((frame.command, b"" if frame.is_error else frame.payload))

    def api_version(self) -> ApiVersion:
        """MSP_API_VERSION (Betaflight 4.6: protocol 0, API 1.47)."""
        protocol, major, minor = struct.unpack_from("<BBB", self.request(MSP_API_VERSION))
        return ApiVersion(protocol, major, minor)

    def status_ex(self, timeout_s: float | None = None) -> StatusEx:
        """MSP_STATUS_EX: arming state and arming-disable flags (``timeout_s``: this request's, else the client's)."""
        return StatusEx.decode(self.request(MSP_STATUS_EX, timeout_s=timeout_s))

    def features(self, timeout_s: float | None = None) -> int:
        """MSP_FEATURE_CONFIG: the enabled feature bits (e.g. :data:`FEATURE_RX_MSP`)."""
        (mask,) = struct.unpack_from("<I", self.request(MSP_FEATURE_CONFIG, timeout_s=timeout_s))
        return int(mask)

    def mode_ranges(self, timeout_s: float | None = None) -> tuple[MspModeRange, ...]:
        """MSP_MODE_RANGES: the configured mode ranges (unused slots, whose range is empty, left out)."""
        payload = self.request(MSP_MODE_RANGES, timeout_s=timeout_s)
        out = []
        for offset in range(0, len(payload) - 3, 4):
            box, aux_index, start, end = payload[offset:offset + 4]
            if end > start:
                out.append(MspModeRange(box, aux_index + 1, _MODE_RANGE_MIN_US + _MODE_STEP_US * start,
                                        _MODE_RANGE_MIN_US + _MODE_STEP_US * end))
        return tuple(out)

    def failsafe(self, timeout_s: float | None = None) -> FailsafeConfig:
        """MSP_FAILSAFE_CONFIG: the RX-loss failsafe's delay and procedure."""
        return FailsafeConfig.decode(self.request(MSP_FAILSAFE_CONFIG, timeout_s=timeout_s))

    def battery(self, timeout_s: float | None = None) -> Battery:
        """MSP_BATTERY_STATE: voltage, cells, charge drawn and the firmware's battery alert."""
        return Battery.decode(self.request(MSP_BATTERY_STATE, timeout_s=timeout_s))

    def post_raw_rc(self, channels_us: Sequence[int]) -> None:
        """:meth:`set_raw_rc` without waiting for the acknowledgement (collect it with :meth:`collect`)."""
        self.post(MSP_SET_RAW_RC, _rc_payload(channels_us))

    def set_raw_rc(self, channels_us: Sequence[int], timeout_s: float | None = None) -> None:
        """MSP_SET_RAW_RC: one RC frame (AETR1234… order, microseconds) for a receiver set to MSP.

        The firmware takes it only with ``serialrx_provider``/``receiver`` set to MSP (``RX_MSP``);
        Betaflight acknowledges the frame with an empty answer, which this waits for, so a frame
        is known to have arrived. Raises :class:`MspError` when the firmware refuses it (too many
        channels) and :class:`ValueError` for a channel outside 0 … 65535 µs.
        """
        self.request(MSP_SET_RAW_RC, _rc_payload(channels_us), timeout_s=timeout_s)

    def rc_us(self) -> tuple[int, ...]:
        """MSP_RC: the channels as the firmware sees them, in microseconds.

        Order is Betaflight's internal one after ``map``: roll, pitch, YAW,
        THROTTLE, AUX1.. (not the AETR order of the receiver).
        """
        payload = self.request(MSP_RC)
        return struct.unpack(f"<{len(payload) // 2}H", payload)

    def motor_outputs(self) -> tuple[int, ...]:
        """MSP_MOTOR: motor outputs in Betaflight order M1..M8, in the protocol's units (PWM: 1000..2000)."""
        payload = self.request(MSP_MOTOR)
        return struct.unpack(f"<{len(payload) // 2}H", payload)

    def attitude(self) -> Attitude:
        """MSP_ATTITUDE: roll and pitch in 0.1 degree, yaw in degrees."""
        roll_decideg, pitch_decideg, yaw_deg = struct.unpack_from("<hhh", self.request(MSP_ATTITUDE))
        return Attitude(roll_decideg / 10.0, pitch_decideg / 10.0, float(yaw_deg))
