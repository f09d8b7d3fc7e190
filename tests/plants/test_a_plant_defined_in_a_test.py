"""A plant defined only here — its class and its spec, nothing registered anywhere else (issue 43).

It is the nominal model with a heavier true vehicle (``mass_scale``), registered by importing this
module: its spec names the module, so that a study's spawned workers and a stored session find it. It
passes the conformance kit, and the library's learning, identification and studies fly it, the
robustness study sampling it as its spec says and the feedback study running its own scenario; the
command line's ``fly`` and ``learn`` take it as ``--plant``.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import aerobat
from aerobat import hummingbird
from aerobat.cli import main
from aerobat.core.design import design
from aerobat.core.plant import Trial
from aerobat.core.testing import check_plant
from aerobat.experiments.execution import LocalExecutor
from aerobat.experiments.identify import identify
from aerobat.experiments.sessions import resume_session, start_session
from aerobat.experiments.studies import feedback_study, robustness_study, rules_study
from aerobat.plants import PLANTS, NominalPlant, PlantChoice, PlantSpec
from aerobat.plants.sampling import DEFAULT_SCENARIO, RobustnessRanges, Sampling, Scenario
from aerobat.quadrotor.feedback import Feedback, FeedbackScheme
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.program import Program
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import VehicleConfig
from aerobat.store import Store


@dataclasses.dataclass(frozen=True)
class HeavySettings:
    mass_scale: float = 1.04
    """The true vehicle's mass over the model's."""


class HeavyPlant:
    """The nominal model flying a vehicle ``settings.mass_scale`` heavier than ``config``."""

    name = "heavy_test"

    def __init__(self, config: VehicleConfig, settings: HeavySettings) -> None:
        vehicle = dataclasses.replace(config.vehicle, mass_kg=config.vehicle.mass_kg * settings.mass_scale)
        self.inner = NominalPlant(dataclasses.replace(config, vehicle=vehicle))

    def fly(self, program: Program) -> Trial:
        return self.inner.fly(program)


def _build(config: VehicleConfig, settings: Any, *, seed: int, feedback: Feedback,
           design_model: VehicleConfig | None) -> HeavyPlant:
    return HeavyPlant(config, settings)


def _from_table(table: Any, source: str) -> HeavySettings:
    return HeavySettings(float(table.get("mass_scale", 1.04)))


def _sample(ranges: RobustnessRanges, seed: int, base: Any) -> tuple[dict[str, Any], dict[str, float]]:
    scale = float(np.random.default_rng(seed).uniform(*ranges.mass_scale))
    return {"mass_scale": scale}, {"mass_scale": scale}


SPEC = PlantSpec(
    "heavy_test", "the nominal model with a heavier vehicle (defined in a test)", _build,
    settings_from_table=_from_table, settings_to_table=dataclasses.asdict, default_settings=HeavySettings,
    robustness=Sampling(_sample, ("mass_scale",)),
    scenarios=(DEFAULT_SCENARIO, Scenario("heavier", "2 % heavier still",
                                          lambda s: dataclasses.replace(s, mass_scale=s.mass_scale * 1.02))),
    module=__name__)
PLANTS.register(SPEC.name, SPEC, replace=True)

CONFIG = hummingbird()
FLIP = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=math.radians(1200), dims=2)


@pytest.fixture(scope="module")
def nominal():
    d = design(FLIP, NominalModel(CONFIG))
    assert d.converged
    return d


@pytest.fixture(scope="module")
def pool():
    executor = LocalExecutor(2)
    yield executor
    executor.close()


def test_it_passes_the_conformance_kit_and_is_listed_as_a_plant():
    assert "heavy_test" in PLANTS.names()
    trial = check_plant(PlantChoice("heavy_test").build(CONFIG), FLIP)
    assert trial.ok
    assert PlantChoice("heavy_test").to_table() == {"kind": "heavy_test", "settings": {"mass_scale": 1.04},
                                                   "seed": 0, "module": __name__}


def test_a_session_learns_on_it_and_resumes(tmp_path, nominal):
    with Store(tmp_path / "s.sqlite") as store:
        run = start_session(store, FLIP, model=CONFIG, plant=PlantChoice("heavy_test", seed=2), iterations=3,
                            design_result=nominal)
        outcome = run.run()
        resume_session(store, outcome.session_id, iterations=5).run()
        errors = [float(np.linalg.norm(it.error)) for it in store.iterations(outcome.session_id)]
    assert len(errors) == 5
    assert errors[-1] < 0.25 * errors[0], errors  # the heavier vehicle is learned, not only flown


def test_the_command_line_flies_and_learns_it(tmp_path):
    maneuver = Path(aerobat.__file__).parent / "examples" / "maneuvers" / "triple_flip_2d.toml"
    assert main(["fly", "--maneuver", str(maneuver), "--plant", "heavy_test", "--out", str(tmp_path / "fly")]) == 0
    assert main(["learn", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "1200", "--plant",
                 "heavy_test", "--trials", "3", "--db", str(tmp_path / "s.sqlite"),
                 "--out", str(tmp_path / "learn")]) == 0


def test_identification_flies_it_and_finds_the_heavier_vehicle(tmp_path):
    with Store(tmp_path / "s.sqlite") as store:
        run = identify(PlantChoice("heavy_test"), CONFIG, store=store, flips=False)
    assert run.fit is not None and run.flights
    # noiseless flights of the model's own dynamics: the fit finds the heavier vehicle's mass within 2 %
    assert run.fit.config.vehicle.mass_kg == pytest.approx(1.04 * CONFIG.vehicle.mass_kg, rel=0.02)


def test_every_study_that_flies_a_plant_runs_it_in_spawned_workers(tmp_path, nominal, pool):
    with Store(tmp_path / "s.sqlite") as store:
        robust = robustness_study(store, FLIP, nominal, CONFIG, vehicles=2, iterations=3, seed=5,
                                  plant="heavy_test", executor=pool)
        assert robust.ran == 2 and not robust.failed
        assert robust.properties == ("mass_scale",)
        lo, hi = RobustnessRanges().mass_scale
        assert all(lo <= r.properties["mass_scale"] <= hi for r in robust.rows)
        feedback = feedback_study(store, FLIP, nominal, CONFIG, schemes=[FeedbackScheme.NONE],
                                  scenarios=["default", "heavier"], seeds=1, trials=3,
                                  plant=PlantChoice("heavy_test"), executor=pool)
        assert [r.scenario for r in feedback.rows] == ["default", "heavier"] and not feedback.outcome.failed
        rules = rules_study(store, FLIP, nominal, CONFIG, methods=["paper"], seeds=1, trials=3,
                            plant=PlantChoice("heavy_test"), executor=pool)
        assert rules.rows[0].runs == 1 and rules.rows[0].failures == 0
        modules = {job.spec["plant"]["module"] for job in store.study_jobs(robust.study_id)}
    assert modules == {__name__}
