"""Putting a learning run together: the rule, the plant and the design, from objects or from stored tables.

One place for what the command line, durable sessions and study jobs all need,
so each is built the same way everywhere: an update rule (with the vehicle
layer's initial-state compensation when asked for), a plant from its stored
form (today's and every earlier store's), and a design from its record.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from aerobat.core.design import Design
from aerobat.core.maneuver import Maneuver
from aerobat.core.rules import RuleChoice, UpdateRule, make_rule
from aerobat.plants import PlantChoice
from aerobat.quadrotor.vehicle import VehicleConfig
from aerobat.store.records import DesignRecord

__all__ = ["build_rule", "design_from_record", "plant_choice_from_record", "plant_record_config"]


def build_rule(choice: RuleChoice, design: Design, model: VehicleConfig) -> UpdateRule:
    """The update rule ``choice`` for ``design``; ``+isc`` gets its sensitivity from ``model``."""
    isc = None
    if choice.isc:
        from aerobat.quadrotor.isc import quadrotor_isc

        isc = quadrotor_isc(design.maneuver, model, design.p_nominal)
    return make_rule(choice, design, isc=isc)


def plant_record_config(choice: PlantChoice) -> dict[str, Any]:
    """What the store keeps of a plant besides its kind and vehicle: ``{"settings": {...}}`` and, unless
    the plant flies the paper's open loop, ``"feedback": {"scheme", "gains"}``."""
    config: dict[str, Any] = {"settings": choice.settings_table()}
    if choice.feedback.enabled:
        config["feedback"] = choice.feedback.to_table()
    return config


def plant_choice_from_record(kind: str, config: Mapping[str, Any], seed: int | None, *, source: str) -> PlantChoice:
    """The plant a stored session flew, from today's form or an earlier store's.

    Today: ``{"settings": {...}}`` plus ``"feedback"`` when the plant ran onboard feedback (without
    it, the paper's open loop: every session stored before feedback existed). Before schema 4: the
    arena as ``{"arena": {...}}`` (a plant's settings under its own name), RotorPy as
    ``{"settings": path or null}`` (the file is read again; a missing file is an error).
    """
    settings_table: Any = config.get("settings") if isinstance(config, Mapping) else None
    if isinstance(config, Mapping) and kind in config:  # before schema 4: under the plant's own name
        settings_table = config[kind]
    table: dict[str, Any] = {"kind": kind, "settings": {}, "seed": int(seed or 0)}
    if isinstance(config, Mapping) and "feedback" in config:
        table["feedback"] = config["feedback"]
    if isinstance(settings_table, str):  # an old RotorPy session stored its settings file's path
        return PlantChoice.from_file(kind, settings_table, seed=int(seed or 0), feedback="none")
    if isinstance(settings_table, Mapping):
        table["settings"] = dict(settings_table)
    return PlantChoice.from_table(table, source=source)


def design_from_record(maneuver: Maneuver, record: DesignRecord) -> Design:
    """The :class:`Design` a :class:`~aerobat.store.DesignRecord` holds, arrays bit for bit (``record.design``)."""
    return record.design(maneuver)
