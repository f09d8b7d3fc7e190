from __future__ import annotations

import struct

from aerobat.firmware.betaflight.packets import (
    MOTOR_STRUCT,
    RC_STRUCT,
    STATE_STRUCT,
    SitlState,
    pack_rc,
    pack_state,
)


def test_sizes_match_target_h() -> None:
    assert (STATE_STRUCT.size, RC_STRUCT.size, MOTOR_STRUCT.size) == (144, 40, 76)


def test_state_layout() -> None:
    state = SitlState(1.5, (0.1, 0.2, 0.3), (0.0, 0.0, -9.80665), (1.0, 0.0, 0.0, 0.0), pressure_pa=100000.0)
    values = struct.unpack("<18d", pack_state(state))
    assert values[0] == 1.5 and values[1:4] == (0.1, 0.2, 0.3)
    assert values[4:7] == (0.0, 0.0, -9.80665) and values[7:11] == (1.0, 0.0, 0.0, 0.0)
    assert values[17] == 100000.0


def test_rc_layout() -> None:
    packet = pack_rc(0.25, tuple(range(1000, 1016)))
    assert struct.unpack("<d16H", packet) == (0.25, *range(1000, 1016))
