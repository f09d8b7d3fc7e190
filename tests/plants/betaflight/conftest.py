"""Fixtures for the Betaflight plant tests.

The firmware is built through the same path as the plant (:func:`ensure_sitl`; about half a
minute the first time, then cached); tests that need it are skipped when it cannot be built
(no C compiler, no network), with the reason. After every test, no SITL process started by this
process may still be running.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest
from bf_processes import sitl_processes

from aerobat.firmware.betaflight.errors import FirmwareUnavailable


@pytest.fixture(autouse=True)
def no_firmware_left_behind() -> Iterator[None]:
    yield
    left = sitl_processes(os.getpid())
    assert left == [], f"SITL processes still running after the test: {left}"


@pytest.fixture(scope="session")
def firmware() -> tuple[Path, Path]:
    """(SITL binary, configured eeprom), built and configured once per cache."""
    from aerobat.firmware.betaflight.build import ensure_sitl
    from aerobat.firmware.betaflight.configure import ensure_eeprom

    try:
        binary = ensure_sitl()
    except FirmwareUnavailable as error:
        pytest.skip(f"Betaflight SITL unavailable: {error}")
    return binary, ensure_eeprom(binary)
