"""Fixtures for the Betaflight plant tests.

Tests that need the firmware are marked ``slow``; they build it on first use
(about half a minute, needs gcc, make, patch and PyPI) and are skipped when it
cannot be built.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from aerobat.plants.betaflight.errors import FirmwareUnavailable


@pytest.fixture(scope="session")
def firmware() -> tuple[Path, Path]:
    """(SITL binary, configured eeprom), built and configured once per cache."""
    from aerobat.plants.betaflight.build import ensure_sitl
    from aerobat.plants.betaflight.configure import ensure_eeprom

    try:
        binary = ensure_sitl()
    except FirmwareUnavailable as error:
        pytest.skip(f"Betaflight SITL unavailable: {error}")
    return binary, ensure_eeprom(binary)
