"""UDP packet formats of the Betaflight SITL (``target/SITL/target.h``), all little-endian.

* State in (``fdm_packet``, 144 bytes, 18 doubles): timestamp [s]; gyro p, q, r
  [rad/s] in body FRD; accelerometer = specific force in body FRD [m/s^2]
  (level at rest: 0, 0, -9.80665); quaternion w, x, y, z rotating body FRD
  into world NED; velocity (3); position (3); pressure [Pa]. The firmware
  flies on this quaternion (``USE_IMU_CALC`` is off in the SITL target).
  Velocity and position would feed the virtual GPS (as ENU velocity and
  longitude deg, latitude deg, altitude m), but this build has no GPS
  (``USE_GPS`` is not defined for SITL in 4.6.0): they are ignored.
* RC in (``rc_packet``, 40 bytes): timestamp [s] (ignored by the firmware),
  16 uint16 channels in microseconds, AETR1234 (:mod:`.rc`).
* Motors out (``servo_packet``, 16 bytes): 4 floats in [0, 1]; 0 disarmed,
  ``motor_idle`` (0.055) armed at idle, 1 full. Resolution 0.001 (sitl.c
  keeps them as integer microseconds above ``mincommand``).

Motor order of the packet (``pwmCompleteMotorUpdate`` in sitl.c maps
Betaflight M1..M4 to packet slots 3, 0, 1, 2) with the default QUADX mixer and
``yaw_motors_reversed = OFF`` (props in):

====  ===========  ========  ===================  ===================
slot  Betaflight   position  spin (seen from top)  raised by
====  ===========  ========  ===================  ===================
0     M2           front-R   CCW                   roll left, pitch up, yaw right
1     M3           rear-L    CCW                   roll right, pitch down, yaw right
2     M4           front-L   CW                    roll right, pitch up, yaw left
3     M1           rear-R    CW                    roll left, pitch down, yaw left
====  ===========  ========  ===================  ===================
"""

from __future__ import annotations

import struct
from enum import StrEnum
from typing import NamedTuple

from aerobat.quadrotor.xframe import MOTOR_POSITIONS_FRD, MOTOR_SPIN_CCW

__all__ = [
    "Exchange",
    "MOTOR_COUNT",
    "MOTOR_POSITIONS_FRD",
    "MOTOR_SPIN_CCW",
    "MOTOR_LOG_ORDER",
    "MOTOR_PACKET_FLOATS",
    "MOTOR_STRUCT",
    "RC_STRUCT",
    "STATE_STRUCT",
    "SitlState",
    "SpinPolicy",
    "pack_rc",
    "pack_state",
]



class Exchange(StrEnum):
    """How the per-step state, RC and motor packets travel between the driver and the lockstep firmware."""

    UDP = "udp"
    """Datagrams on loopback sockets (two system calls per packet on each side)."""
    SHM = "shm"
    """A shared memory region (:mod:`.shm`): a spin, then a futex sleep; no system call while both run."""


class SpinPolicy(StrEnum):
    """Whether the driver spins for the firmware's answer over shared memory (up to ``spin_us``)."""

    MEASURED = "measured"
    """Spin or sleep at once, whichever steps faster, measured as the flight goes (a loaded machine
    sleeps: spinning there takes the core the firmware or another process needs)."""
    ALWAYS = "always"
    """Spin up to ``spin_us`` on every wait (the fastest on a machine with a core free for each side)."""


STATE_STRUCT = struct.Struct("<18d")
RC_STRUCT = struct.Struct("<d16H")
MOTOR_STRUCT = struct.Struct("<4f3f12f")
"""The lockstep firmware's answer to a state packet (76 bytes; aerobat's lockstep patch, sitl.c):
the 4 motor commands (0..1), then the rate loop's set point (3, deg/s, what blackbox logs) and
the P, I, D, F terms per axis (roll, pitch, yaw: 12). Its layout is defined here only."""
MOTOR_PACKET_FLOATS = 19
MOTOR_LOG_ORDER = (3, 0, 1, 2)
"""Packet slot of Betaflight's motors M1..M4 (rear right, front right, rear left, front left):
the SITL's packet is front right, rear left, front left, rear right (:mod:`aerobat.plants.betaflight.physics`)."""
MOTOR_COUNT = 4



class SitlState(NamedTuple):
    """One state packet, in the units and frames of the SITL.

    Attributes
    ----------
    time_s : float
        Simulated time; must increase. Send multiples of the gyro period
        (125 us at 8 kHz) so the firmware's gyro task runs once per packet.
    gyro_frd_rad_s : tuple of 3 float
        Body rates p, q, r (body FRD).
    specific_force_frd_m_s2 : tuple of 3 float
        Accelerometer reading: (non-gravitational force) / mass, body FRD.
    quat_wxyz_frd_to_ned : tuple of 4 float
        Unit quaternion rotating body FRD vectors into world NED.
    velocity_m_s : tuple of 3 float
        Virtual-GPS velocity (ENU; ignored: no GPS in this build).
    position_gps : tuple of 3 float
        Virtual-GPS longitude deg, latitude deg, altitude m (ignored: no GPS in this build).
    pressure_pa : float
        Barometric pressure.
    """

    time_s: float
    gyro_frd_rad_s: tuple[float, float, float]
    specific_force_frd_m_s2: tuple[float, float, float]
    quat_wxyz_frd_to_ned: tuple[float, float, float, float]
    velocity_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    position_gps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    pressure_pa: float = 101325.0


def pack_state(state: SitlState) -> bytes:
    """Encode a :class:`SitlState` as the 144-byte state packet."""
    return STATE_STRUCT.pack(
        state.time_s,
        *state.gyro_frd_rad_s,
        *state.specific_force_frd_m_s2,
        *state.quat_wxyz_frd_to_ned,
        *state.velocity_m_s,
        *state.position_gps,
        state.pressure_pa,
    )


def pack_rc(time_s: float, channels_us: tuple[int, ...]) -> bytes:
    """Encode the 40-byte RC packet (16 channels in microseconds, AETR1234)."""
    if len(channels_us) != 16:
        raise ValueError(f"an RC packet has 16 channels, got {len(channels_us)}")
    return RC_STRUCT.pack(time_s, *channels_us)
