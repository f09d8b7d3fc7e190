"""System identification: the nominal model of *your* vehicle from a few flights.

A short sequence of safe trials (:func:`identification_sequence`: collective steps and
limits, rate doublets per axis, optionally two slow flips) is flown on any plant and
measured with motion capture only; :func:`fit_vehicle` fits the model's identifiable
parameters (:data:`PARAMETERS`) with SciPy's least squares on the compiled model and
returns a :class:`VehicleFit` whose ``config`` is a vehicle every command accepts.
Flying the sequence and keeping it in the store is :mod:`aerobat.experiments.identify`.
"""

from aerobat.quadrotor.identification.fit import FitOptions, TrialFit, VehicleFit, fit_vehicle, usable_trials
from aerobat.quadrotor.identification.parameters import (
    PARAMETERS,
    ParameterInfo,
    config_from_parameters,
    envelope_margins,
    hover_command_m_s2,
    parameter_index,
    parameters_from_config,
)
from aerobat.quadrotor.identification.sequence import (
    IdentificationSequence,
    IdentificationTrial,
    TrialKind,
    identification_sequence,
    sequence_from_spec,
)

__all__ = [
    "PARAMETERS",
    "FitOptions",
    "IdentificationSequence",
    "IdentificationTrial",
    "ParameterInfo",
    "TrialFit",
    "TrialKind",
    "VehicleFit",
    "config_from_parameters",
    "envelope_margins",
    "fit_vehicle",
    "hover_command_m_s2",
    "identification_sequence",
    "parameter_index",
    "parameters_from_config",
    "sequence_from_spec",
    "usable_trials",
]
