"""Update rules: the paper's (eq 4) and the ones beyond it, all behind one protocol.

Nothing here knows about quadrocopters: initial-state compensation takes the
model's sensitivity matrix and a deviation function as plain inputs
(:class:`~aerobat.core.rules.registry.IscModel`, built for the flips by
:func:`aerobat.quadrotor.isc.quadrotor_isc`). Build a rule by name with
:func:`make_rule`; the names are listed in :mod:`aerobat.core.rules.registry`.
"""

from aerobat.core.rules.base import ConstantSchedule, PaperRule, PaperSchedule, Schedule, UpdateRule
from aerobat.core.rules.broyden import BroydenJacobian
from aerobat.core.rules.isc import DeviationFn, InitialStateCompensation
from aerobat.core.rules.kalman import KalmanRule
from aerobat.core.rules.registry import RULES, IscModel, RuleChoice, RuleSpec, ScheduleChoice, ScheduleKind, make_rule
from aerobat.core.rules.regularized import BroydenRule, RegularizedRule
from aerobat.core.rules.scaled import KestenGamma, NoiseEstimator, filter_factors

__all__ = [
    "RULES",
    "BroydenJacobian",
    "BroydenRule",
    "ConstantSchedule",
    "DeviationFn",
    "InitialStateCompensation",
    "IscModel",
    "KalmanRule",
    "KestenGamma",
    "NoiseEstimator",
    "PaperRule",
    "PaperSchedule",
    "RegularizedRule",
    "RuleChoice",
    "RuleSpec",
    "Schedule",
    "ScheduleChoice",
    "ScheduleKind",
    "UpdateRule",
    "filter_factors",
    "make_rule",
]
