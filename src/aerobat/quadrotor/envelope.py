"""The reduced control envelope and its bang-bang relations (Sect. 7.1, eqs 22–29).

Read as ``../shared/design.md`` explains (the extracted text lost over/underlines):
on the upper edge of the reduced envelope a collective ``f`` (mass-normalized)
leaves ``|â| = l·m·(β̄ − f)/(2·I)`` of angular acceleration; the corner of the
envelope is at ``f = (β̄ + β̲)/2`` with ``|â| = l·m·(β̄ − β̲)/(4·I)`` (eq 27).
"""

from __future__ import annotations

from dataclasses import dataclass

from aerobat.quadrotor.vehicle import VehicleParams

__all__ = ["ReducedEnvelope"]


@dataclass(frozen=True, kw_only=True)
class ReducedEnvelope:
    """Bang-bang relations between collective and angular acceleration about one axis.

    Attributes
    ----------
    collective_min_m_s2, collective_max_m_s2 : β̲ and β̄ [m/s²].
    mass_kg, arm_length_m : m and l.
    inertia_kg_m2 : inertia about the rotation axis (I_xx for roll, I_yy for pitch).
    """

    collective_min_m_s2: float
    collective_max_m_s2: float
    mass_kg: float
    arm_length_m: float
    inertia_kg_m2: float

    @classmethod
    def for_axis(cls, vehicle: VehicleParams, axis: str) -> ReducedEnvelope:
        inertia = {"roll": vehicle.inertia_xx_kg_m2, "pitch": vehicle.inertia_yy_kg_m2}[axis]
        return cls(
            collective_min_m_s2=vehicle.collective_reduced_min_m_s2,
            collective_max_m_s2=vehicle.collective_reduced_max_m_s2,
            mass_kg=vehicle.mass_kg,
            arm_length_m=vehicle.arm_length_m,
            inertia_kg_m2=inertia,
        )

    @property
    def _k(self) -> float:
        return self.arm_length_m * self.mass_kg / self.inertia_kg_m2

    @property
    def corner_collective_m_s2(self) -> float:
        """Collective at the envelope's corner, (β̄ + β̲)/2 [m/s²]."""
        return 0.5 * (self.collective_max_m_s2 + self.collective_min_m_s2)

    @property
    def max_acceleration_rad_s2(self) -> float:
        """Eq 27: |â|max = l m (β̄ − β̲)/(4 I) [rad/s²]."""
        return 0.25 * self._k * (self.collective_max_m_s2 - self.collective_min_m_s2)

    def acceleration_at_high(self, collective_m_s2: float) -> float:
        """Eq 25 inverted: |â| left on the upper edge at collective f, l m (β̄ − f)/(2 I)."""
        return 0.5 * self._k * (self.collective_max_m_s2 - collective_m_s2)

    def acceleration_at(self, collective_m_s2: float) -> float:
        """Eq 28: |â| on the envelope boundary for any collective in [β̲, β̄]."""
        half_span = 0.5 * (self.collective_max_m_s2 - self.collective_min_m_s2)
        return 0.5 * self._k * (half_span - abs(collective_m_s2 - self.corner_collective_m_s2))

    def collective_high(self, acceleration_rad_s2: float) -> float:
        """Eq 25 (mass-normalized): β̄ − 2|â| I/(l m) [m/s²]."""
        return self.collective_max_m_s2 - 2.0 * abs(acceleration_rad_s2) / self._k

    def collective_low(self, acceleration_rad_s2: float) -> float:
        """Eq 26 (mass-normalized): β̲ + 2|â| I/(l m) [m/s²]."""
        return self.collective_min_m_s2 + 2.0 * abs(acceleration_rad_s2) / self._k
