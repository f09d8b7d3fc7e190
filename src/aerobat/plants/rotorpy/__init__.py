"""RotorPy as an independent physical vehicle (``pip install 'aerobat[rotorpy]'``).

:class:`RotorPyPlant` flies RotorPy's shipped Hummingbird, supervised like the arena;
:mod:`aerobat.plants.rotorpy.settings` holds its TOML settings. ``rotorpy`` itself is
imported only when a plant is built.
"""

from aerobat.plants.rotorpy.plant import RotorPyPlant
from aerobat.plants.rotorpy.settings import (
    INSTALL_HINT,
    PAPER_RATE_GAINS_PER_S,
    PAPER_ROTOR_THRUST_MAX_N,
    PAPER_ROTOR_THRUST_MIN_N,
    RotorPySettings,
    WindSettings,
    adapted_quad_params,
    build_quad_params,
    load_rotorpy_settings,
    settings_from_table,
    settings_to_table,
    shipped_quad_params,
    validate_overrides,
)
from aerobat.plants.rotorpy.spec import SPEC

__all__ = [
    "SPEC",
    "INSTALL_HINT",
    "PAPER_RATE_GAINS_PER_S",
    "PAPER_ROTOR_THRUST_MAX_N",
    "PAPER_ROTOR_THRUST_MIN_N",
    "RotorPyPlant",
    "RotorPySettings",
    "WindSettings",
    "adapted_quad_params",
    "build_quad_params",
    "load_rotorpy_settings",
    "settings_from_table",
    "settings_to_table",
    "shipped_quad_params",
    "validate_overrides",
]
