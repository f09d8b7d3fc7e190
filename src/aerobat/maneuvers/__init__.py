"""Maneuvers: the generic protocol and the paper's multi-flip."""

from .base import ErrorSpec, Maneuver, ParameterSpec
from .flip import MultiFlip

__all__ = ["ErrorSpec", "Maneuver", "MultiFlip", "ParameterSpec"]
