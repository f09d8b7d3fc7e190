"""Plants by name: a :class:`PlantSpec` per kind, and :class:`PlantChoice`, the edge form users write.

A choice is a plant kind, its settings (a dataclass, or None for none) and a seed.
``PlantChoice.to_table()`` is what the store and the study jobs keep — the
settings' *content*, never a path — so a stored session or a job on another
machine builds the same plant.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any, Protocol

from aerobat.core.bounds import SEEDS, bounded, validate
from aerobat.core.plant import Plant
from aerobat.core.registry import Registry
from aerobat.errors import ConfigError, MissingDependency
from aerobat.plants.sampling import DEFAULT_SCENARIO, Sampling, Scenario
from aerobat.quadrotor.feedback import OPEN_LOOP, Feedback, FeedbackScheme, as_feedback
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["PLANTS", "DesignModel", "Kernels", "PlantChoice", "PlantFactory", "PlantSpec", "plant_spec"]


class DesignModel(StrEnum):
    """Which model a nominal design runs on (Sect. 5: p⁰, J and C)."""

    PAPER = "paper"
    """The paper's first-principles model: rigid body, first-order motors, the onboard P rate loop
    (:class:`aerobat.quadrotor.simulate.NominalModel`)."""
    FIRMWARE = "firmware"
    """The plant's flight controller as configured, around the vehicle the user believes
    (:class:`aerobat.quadrotor.firmware.FirmwareModel`; plants with a firmware only)."""

    @property
    def meaning(self) -> str:
        """One sentence for listings and help."""
        return {DesignModel.PAPER: "the paper's model (its P rate loop and nominal motors)",
                DesignModel.FIRMWARE: "the plant's flight controller as configured (rates, RC smoothing, PID with "
                                      "feedforward, filters, mixer, throttle path) around the airframe"}[self]


class PlantFactory(Protocol):
    """What builds one plant: every plant kind's ``build`` has this one signature.

    ``config`` is the nominal vehicle the plant is built around; ``settings`` the kind's settings (its
    dataclass, or None for a kind without); ``seed`` seeds its random generator; ``feedback`` is what its
    onboard loop mixes into the program (one of the kind's :attr:`PlantSpec.feedback` schemes);
    ``design_model`` the vehicle the programs were designed on when it is not ``config`` (None: the same),
    whose flight of each program the feedback tracks. A kind that has no use for an argument says so in
    its spec's summary or docs; none is dropped silently by the registry.
    """

    def __call__(self, config: VehicleConfig, settings: Any, *, seed: int, feedback: Feedback,
                 design_model: VehicleConfig | None) -> Plant:
        """The plant."""


@dataclass(frozen=True)
class Kernels:
    """Compiled kernels a plant calls, and how to compile them before its first trial (``aerobat setup``)."""

    group: str
    """Which of setup's groups compiles them (:data:`aerobat.experiments.warmup.PARTS`: ``arena``,
    ``plants``, ``firmware``; another name joins ``plants``); groups compile side by side."""
    compile: Callable[[], None]
    """Runs each kernel once with the argument types the plant passes (numba caches what it compiles)."""


@dataclass(frozen=True)
class PlantSpec:
    """How to build one kind of plant.

    Attributes
    ----------
    name : what users write (``"arena"``).
    summary : one line for listings.
    build : the :class:`PlantFactory`: ``build(config, settings, *, seed, feedback, design_model) -> plant``.
    load_settings : ``load_settings(path) -> settings`` from a TOML file (None: the kind takes no file).
    settings_from_table, settings_to_table : the settings' stored form and back (None: no settings).
    default_settings : the settings used when no file is given.
    requires : ``(module, extra)`` pairs of optional packages the plant needs.
    option : the command-line option that takes the settings file (``--arena``).
    feedback : the feedback schemes the plant's onboard loop can run (:mod:`aerobat.quadrotor.feedback`).
    default_feedback : the scheme used when none is chosen.
    cores : ``cores(settings) -> int``, the cores one instance keeps busy (None: 1). A study runs
        ``cpu_count // cores`` instances at once unless told otherwise
        (:func:`aerobat.experiments.execution.default_workers`).
    firmware_model : ``firmware_model(config, settings) -> (model, table)``: the design model that
        contains the plant's flight controller, around the vehicle ``config``, and its stored form
        (None: the plant has no firmware to model; designs run on the paper's model).
    robustness : how a robustness study draws one vehicle of this plant (None: the plant is not sampled,
        and ``study robustness --plant NAME`` says so).
    scenarios : the feedback study's scenarios on this plant, ``default`` first (default: ``default`` only).
    kernels : the compiled kernels the plant calls, each group with what compiles it (``aerobat setup``).
    replay : ``replay(settings, *, tune, props_out, seed) -> replayer``: a blackbox log's sticks flown through
        this plant's firmware (``aerobat log replay``; the replayer as
        :class:`aerobat.plants.betaflight.replay.LogReplayer`); None: the plant replays no log.
    tune : ``tune(settings, tune) -> settings``: the settings with a real quad's firmware configuration
        applied (a :class:`~aerobat.firmware.betaflight.tune.Tune`, ``--tune FILE``); None: the plant flies
        no firmware tune.
    in_studies : whether the comparative studies (rules, feedback) offer the plant; False for one where
        there is nothing to compare (the nominal model) or a study's thousands of trials cannot fly (a
        vehicle on the wall clock).
    module : for a plant outside aerobat's built-ins registered without an entry point, the module whose
        import registers it (usually ``__name__`` where the spec is made). Every stored choice of the plant
        carries it, so that a study's spawned workers, a resumed session or a stored job find the plant.
    """

    name: str
    summary: str
    build: PlantFactory
    load_settings: Callable[[str | Path], Any] | None = None
    settings_from_table: Callable[[Mapping[str, Any], str], Any] | None = None
    settings_to_table: Callable[[Any], dict[str, Any]] | None = None
    default_settings: Callable[[], Any] | None = None
    requires: tuple[tuple[str, str], ...] = ()
    option: str | None = None
    feedback: tuple[FeedbackScheme, ...] = (FeedbackScheme.NONE,)
    default_feedback: FeedbackScheme = FeedbackScheme.NONE
    cores: Callable[[Any], int] | None = None
    firmware_model: Callable[[VehicleConfig, Any], tuple[Any, dict[str, Any]]] | None = None
    robustness: Sampling | None = None
    scenarios: tuple[Scenario, ...] = (DEFAULT_SCENARIO,)
    kernels: tuple[Kernels, ...] = ()
    replay: Callable[..., Any] | None = None
    tune: Callable[[Any, Any], Any] | None = None
    in_studies: bool = True
    module: str | None = None

    def scenario(self, name: str, *, source: str = "--scenarios") -> Scenario:
        """The scenario ``name`` of this plant; :class:`ConfigError` naming the ones it has."""
        for scenario in self.scenarios:
            if scenario.name == name:
                return scenario
        raise ConfigError(f"{source}: the {self.name} plant has no scenario {name!r}; it has "
                          f"{', '.join(s.name for s in self.scenarios)}")

    @property
    def design_models(self) -> tuple[DesignModel, ...]:
        """The design models this plant offers."""
        return (DesignModel.PAPER, DesignModel.FIRMWARE) if self.firmware_model is not None else (DesignModel.PAPER,)

    @property
    def default_design_model(self) -> DesignModel:
        """The model a design runs on unless told otherwise: the firmware's where there is one."""
        return DesignModel.FIRMWARE if self.firmware_model is not None else DesignModel.PAPER

    def check_design_model(self, kind: DesignModel) -> None:
        """Raise ConfigError if this plant cannot design on ``kind``."""
        if kind not in self.design_models:
            raise ConfigError(f"--design-model {kind.value}: the {self.name} plant designs on "
                              f"{', '.join(k.value for k in self.design_models)} (no firmware to model)")

    def check_feedback(self, feedback: Feedback) -> None:
        """Raise ConfigError if this plant cannot run ``feedback``'s scheme."""
        if feedback.scheme not in self.feedback:
            raise ConfigError(f"--feedback {feedback.scheme.value}: the {self.name} plant runs "
                              f"{', '.join(s.value for s in self.feedback)}")

    def check_available(self) -> None:
        """Raise :class:`MissingDependency` with the install hint if a required package is missing."""
        for module, extra in self.requires:
            try:
                importlib.import_module(module)
            except ImportError as exc:
                raise MissingDependency(module, extra=extra, purpose=f"the {self.name} plant",
                                        detail=str(exc)) from None


PLANTS: Registry[PlantSpec] = Registry("plant", "aerobat.plants")


def plant_spec(kind: Any, module: Any = None, *, source: str) -> PlantSpec:
    """The registered plant ``kind``; an unknown kind whose stored choice names its ``module`` (a plant
    registered by importing it, :attr:`PlantSpec.module`) is looked up after importing that module."""
    if isinstance(kind, str) and kind not in PLANTS and isinstance(module, str) \
            and module.replace(".", "").replace("_", "").isalnum():
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ConfigError(f"{source}.module: the module {module!r} of plant {kind!r} cannot be imported: "
                              f"{exc}") from None
    return PLANTS.get(kind, source=source)


@dataclass(frozen=True)
class PlantChoice:
    """Which plant flies: its kind, its settings and its seed.

    Attributes
    ----------
    kind : a registered plant (:data:`PLANTS`).
    settings : the kind's settings (e.g. :class:`~aerobat.plants.arena.ArenaParams`), or None for defaults.
    seed : seeds the plant's random generator.
    feedback : what the plant's onboard loop mixes into the program: a :class:`Feedback`, a scheme
        name, or None for the plant's default (the best scheme measured on the arena and RotorPy).
    """

    kind: str = "arena"
    settings: Any = field(default=None, compare=False)
    seed: int = bounded(0, SEEDS)
    feedback: Any = None

    def __post_init__(self) -> None:
        spec = PLANTS.get(self.kind, source="plant")
        validate(self)
        if self.settings is None and spec.default_settings is not None:
            object.__setattr__(self, "settings", spec.default_settings())
        feedback = Feedback(spec.default_feedback) if self.feedback is None else as_feedback(self.feedback)
        spec.check_feedback(feedback)
        object.__setattr__(self, "feedback", feedback)

    def cores(self) -> int:
        """The cores one instance of this plant keeps busy (its kind's ``cores``; 1 if it says none)."""
        spec = self.spec
        return 1 if spec.cores is None else int(spec.cores(self.settings))

    @property
    def spec(self) -> PlantSpec:
        """The registered plant kind this choice names (its factory, settings option and feedback)."""
        return PLANTS.get(self.kind, source="plant")

    @classmethod
    def from_file(cls, kind: str, path: str | Path | None, *, seed: int = 0, feedback: Any = None) -> PlantChoice:
        """The plant ``kind`` with settings read from ``path`` (None: defaults)."""
        spec = PLANTS.get(kind, source="--plant")
        if path is None:
            return cls(kind, None, seed, feedback)
        if spec.load_settings is None:
            raise ConfigError(f"--plant {kind} takes no settings file (got {path})")
        return cls(kind, spec.load_settings(path), seed, feedback)

    def settings_table(self) -> dict[str, Any]:
        """The settings as a JSON-ready table ({} when the kind has none)."""
        spec = self.spec
        if spec.settings_to_table is None or self.settings is None:
            return {}
        return spec.settings_to_table(self.settings)

    def to_table(self) -> dict[str, Any]:
        """``{"kind", "settings", "seed"}`` and, unless it is the open loop, ``"feedback"``; JSON-ready.

        (A table without ``feedback`` is the paper's open loop: what every store written before
        feedback existed holds.)
        """
        table: dict[str, Any] = {"kind": self.kind, "settings": self.settings_table(), "seed": self.seed}
        if self.spec.module is not None:
            table["module"] = self.spec.module
        if self.feedback.enabled:
            table["feedback"] = self.feedback.to_table()
        return table

    @classmethod
    def from_table(cls, table: Mapping[str, Any], *, source: str) -> PlantChoice:
        """Inverse of :meth:`to_table`."""
        if not isinstance(table, Mapping) or not isinstance(table.get("kind"), str):
            raise ConfigError(f"{source}: expected a plant table with a kind, got {table!r}")
        spec = plant_spec(table["kind"], table.get("module"), source=source)
        settings = None
        stored = table.get("settings") or {}
        if stored:
            if spec.settings_from_table is None:
                raise ConfigError(f"{source}: plant {spec.name} takes no settings")
            settings = spec.settings_from_table(stored, f"{source}.settings")
        feedback = (Feedback.from_table(table["feedback"], source=f"{source}.feedback") if "feedback" in table
                    else OPEN_LOOP)
        return cls(spec.name, settings, int(table.get("seed", 0)), feedback)

    def build(self, config: VehicleConfig, *, design_model: VehicleConfig | None = None) -> Plant:
        """The plant, flying a true vehicle around the nominal ``config``.

        ``design_model`` is the model the programs are designed on when it is not ``config`` (a vehicle
        identified on the arena, which stays built around the vehicle it was identified from): the
        onboard feedback then tracks the design model's flight of each program, as it does when the
        two are the same.
        """
        spec = self.spec
        spec.check_available()
        return spec.build(config, self.settings, seed=self.seed, feedback=self.feedback,
                          design_model=None if design_model == config else design_model)

    def __repr__(self) -> str:
        return f"PlantChoice({self.kind!r}, seed={self.seed}, feedback={self.feedback.scheme.value!r})"
