"""The method (Lupashin & D'Andrea 2012, Sects. 3–5), knowing no vehicle.

Maneuvers, plants and update rules are protocols; the design finds p⁰, J and C on
any model; learning corrects the parameters from any plant's trials. Only NumPy
and SciPy are needed here: importing :mod:`aerobat.core` loads no compiler, no
solver and no plotting library.
"""

from aerobat.core.design import Design, DesignStatus, FinalStateModel, design, finite_difference_jacobian
from aerobat.core.learning import Iteration, IterationStatus, Learner, Session, SessionStatus, learn
from aerobat.core.maneuver import ErrorKind, ErrorSpec, Maneuver, ParameterSpec
from aerobat.core.notes import IterationNote, NoteKind
from aerobat.core.plant import Plant, Signals, StatefulPlant, Trial, TrialStatus
from aerobat.core.registry import Registry, from_spec, register_maneuver
from aerobat.core.rules import RULES, RuleChoice, UpdateRule, make_rule

__all__ = [
    "RULES",
    "Design",
    "DesignStatus",
    "ErrorKind",
    "ErrorSpec",
    "FinalStateModel",
    "Iteration",
    "IterationNote",
    "IterationStatus",
    "Learner",
    "Maneuver",
    "NoteKind",
    "ParameterSpec",
    "Plant",
    "Registry",
    "RuleChoice",
    "Session",
    "SessionStatus",
    "Signals",
    "StatefulPlant",
    "Trial",
    "TrialStatus",
    "UpdateRule",
    "design",
    "finite_difference_jacobian",
    "from_spec",
    "learn",
    "make_rule",
    "register_maneuver",
]
