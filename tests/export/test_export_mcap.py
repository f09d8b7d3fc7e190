"""`aerobat export SESSION --format mcap` (issues 26, 44): Foxglove's schemas, read back with the mcap reader."""

from __future__ import annotations

import contextlib
import io
import json
import math

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from aerobat.cli import main
from aerobat.core.maneuver import ErrorKind
from aerobat.core.testing import ToyManeuver
from aerobat.export.mcap_scene import TrialPath, maneuver_marks, scene_update
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.maneuvers.translation import Translation
from aerobat.quadrotor.vehicle import VehicleParams
from aerobat.store import Store
from browse_fixtures import build_store, check_session_mcap

MEASURED_ONLY = ("p_rad_s", "q_rad_s", "r_rad_s", "f1_n", "f2_n", "f3_n", "f4_n")
"""What docs/browse.md says only the nominal plant fills (null for the motion-capture plants)."""


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def read_json(path, topic: str) -> list[dict]:
    with path.open("rb") as stream:
        return [json.loads(m.data) for _, _, m in make_reader(stream).iter_messages(topics=[topic])]


def test_an_arena_session_reads_back_from_its_mcap_file(tmp_path):
    db = tmp_path / "s.sqlite"
    build_store(db, sessions=1, study_vehicles=0, failed_jobs=0)
    code, out, err = call(["export", "1", "--db", str(db), "--format", "mcap", "--output", str(tmp_path / "s.mcap"),
                           "--json"])
    assert code == 0, err
    written = json.loads(out)
    with Store(db, create=False) as store:
        counts = check_session_mcap(tmp_path / "s.mcap", store, 1)
    assert written["messages"] == counts and written["trials"] == 2  # trials 1 and 3 were flown
    code, _, err = call(["export", "1", "--db", str(db), "--format", "mcap", "--output", str(tmp_path / "s.mcap")])
    assert code == 2 and "exists" in err and err.count("\n") == 1, err
    code, _, err = call(["export", "1", "--db", str(db), "--format", "mcap"])
    assert code == 2 and "--format mcap: give --output" in err, err


def test_an_arena_session_overlays_its_trials_and_draws_every_path(tmp_path):
    db, path = tmp_path / "s.sqlite", tmp_path / "s.mcap"
    build_store(db, sessions=1, study_vehicles=0, failed_jobs=0)
    assert call(["export", "1", "--db", str(db), "--format", "mcap", "--output", str(path)])[0] == 0
    samples = read_json(path, "/trials/state")
    first = [s for s in samples if s["trial"] == 1]
    third = [s for s in samples if s["trial"] == 3]
    assert [s["trial"] for s in samples] == [1] * len(first) + [3] * len(third)  # trial 2 was not measured
    for trial in (first, third):  # t_s starts again at the program's start: x = t_s overlays them
        t_s = np.array([s["t_s"] for s in trial])
        assert -1e-6 < t_s[0] < 0.01 and np.all(np.diff(t_s) > 0.0)
    assert third[0]["t_s"] < first[-1]["t_s"]
    assert first[-1]["roll_rad"] > 1.5 * math.pi  # a whole roll flip, unwrapped
    for name in MEASURED_ONLY:  # motion capture measures neither rates nor thrusts: null, never made up
        assert {s[name] for s in samples} == {None}, name
    errors = read_json(path, "/errors")  # the learning curve: x = trial, y = position_error_m
    assert [e["trial"] for e in errors] == [1, 2, 3] and None not in [e["position_error_m"] for e in errors]
    with path.open("rb") as stream:
        ((_, _, _, scene),) = make_reader(stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
            topics=["/scene"])
    entities = {e.id: e for e in scene.entities}
    assert list(entities) == ["trial/1", "trial/3", "maneuver"]
    assert [len(entities[f"trial/{i}"].lines[0].points) for i in (1, 3)] == [len(first), len(third)]
    assert entities["trial/1"].lines[0].color.b > entities["trial/3"].lines[0].color.b  # blue first, red last
    maneuver = entities["maneuver"]  # the 2-D roll flip starts and ends hovering at the origin; y and z are fixed
    start, target = maneuver.spheres[0].pose.position, maneuver.cubes[0].pose.position
    assert (start.x, start.y, start.z) == (target.x, target.y, target.z) == (0.0, 0.0, 0.0)
    assert {kv.key: kv.value for kv in maneuver.metadata} == {"target_axes": "y z"}


def test_a_nominal_session_fills_the_rates_and_thrusts_it_flew(tmp_path):
    db, path = tmp_path / "n.sqlite", tmp_path / "n.mcap"
    code, _, err = call(["learn", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800", "--plant",
                         "nominal", "--iterations", "2", "--db", str(db), "--out", str(tmp_path / "out")])
    assert code == 0, err
    assert call(["export", "last", "--db", str(db), "--format", "mcap", "--output", str(path)])[0] == 0
    with Store(db, create=False) as store:
        counts = check_session_mcap(path, store, 1)
    samples = read_json(path, "/trials/state")
    assert len(samples) == counts["/trials/state"] and {s["trial"] for s in samples} == {1, 2}
    for name in MEASURED_ONLY:  # the design model's own states: every sample has them
        assert None not in [s[name] for s in samples], name
    assert None not in [s["f1_n"] for s in read_json(path, "/trial/1/state")]
    assert all(s["f1_n"] > 0.0 for s in samples)


def test_the_scene_marks_where_a_maneuver_starts_and_ends():
    vehicle = VehicleParams()
    positions = lambda maneuver: [e.kind is ErrorKind.POSITION for e in maneuver.errors]  # noqa: E731
    step = Translation(vehicle=vehicle, target_yz=(1.5, -0.5), final_angle_rad=0.0, interval_inputs=((10.0, 0.0),),
                       guess_times_s=(0.5,))
    marks = maneuver_marks(step, positions(step))
    assert marks.start_m.tolist() == [0.0, 0.0, 0.0] and marks.target_m.tolist() == [0.0, 1.5, -0.5]
    assert marks.target_axes == ("y", "z")
    flip = MultiFlip(vehicle=vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=3, axis="pitch")
    marks = maneuver_marks(flip, positions(flip))
    assert marks.target_m.tolist() == [0.0, 0.0, 0.0] and marks.target_axes == ("x", "y", "z")
    toy = ToyManeuver()  # a cart on a line: no 3-D position to probe, so no target is drawn
    assert maneuver_marks(toy, positions(toy)).target_m is None
    paths = [TrialPath(k, np.column_stack([np.linspace(0, k, 5)] * 3), "ok", 0.1 * k) for k in (1, 2, 4)]
    scene = scene_update(paths, maneuver_marks(step, positions(step)), 7)
    assert [e.id for e in scene.entities] == ["trial/1", "trial/2", "trial/4", "maneuver"]
    assert all(e.timestamp.ToNanoseconds() == 7 and e.frame_id == "world" for e in scene.entities)
    assert [len(e.lines[0].points) for e in scene.entities[:3]] == [5, 5, 5]
    assert scene.entities[2].spheres[0].pose.position.z == 4.0  # where trial 4 ended
    assert [round(e.lines[0].color.r, 3) for e in scene.entities[:3]] == [0.15, 0.575, 1.0]
    cube = scene.entities[3].cubes[0].pose.position
    assert (cube.x, cube.y, cube.z) == (0.0, 1.5, -0.5)


def test_a_plants_own_signals_are_exported_per_trial_and_overlaid(tmp_path):
    """A plant's Signals (schema 7; Betaflight's motors, set point, PID terms) on /trial/N/firmware and
    /trials/firmware, on the trial's timeline; a sample before the first pose (the radio's latency)
    starts the trial there; NaN is null."""
    import dataclasses

    from aerobat.core.learning import Iteration, IterationStatus
    from aerobat.core.plant import Signals
    from aerobat.plants import Arena
    from browse_fixtures import CONFIG, DESIGN, FLIP, VEHICLE

    db, path = tmp_path / "s.sqlite", tmp_path / "s.mcap"
    trial = Arena(CONFIG, seed=3).fly(FLIP.program(DESIGN.p_nominal))
    times = np.arange(-0.012, trial.times_s[-1], 0.004)
    values = np.column_stack([np.sin(times), 800.0 * np.cos(times), np.full(times.size, np.nan)])
    trial = dataclasses.replace(trial, signals=Signals(times, ("motor1", "setpoint_roll_deg_s", "p_roll"), values))
    with Store(db) as store:
        sid = store.create_session(vehicle=VEHICLE, plant_kind="arena", plant_config={}, maneuver=FLIP,
                                   design=DESIGN, seed=3, rule={"name": "paper"}, target_iterations=2,
                                   start_params=DESIGN.p_nominal)
        for index in (1, 2):
            store.append_iteration(sid, Iteration(index, index, IterationStatus.OK, DESIGN.p_nominal,
                                                  np.full(len(FLIP.errors), 0.1), 1.0, 1.0,
                                                  np.zeros_like(DESIGN.p_nominal), "measured", trial))
    assert call(["export", str(sid), "--db", str(db), "--format", "mcap", "--output", str(path)])[0] == 0
    with Store(db, create=False) as store:
        counts = check_session_mcap(path, store, sid)  # values, times and the timeline against the store
    assert counts["/trial/1/firmware"] == counts["/trial/2/firmware"] == times.size
    assert counts["/trials/firmware"] == 2 * times.size
    overlay = read_json(path, "/trials/firmware")
    assert [s["trial"] for s in overlay] == [1] * times.size + [2] * times.size
    assert {s["p_roll"] for s in overlay} == {None} and None not in [s["setpoint_roll_deg_s"] for s in overlay]
    with path.open("rb") as stream:
        reader = make_reader(stream)
        first_signal = next(reader.iter_messages(topics=["/trial/1/firmware"]))[2].log_time
        first_pose = next(reader.iter_messages(topics=["/trial/1/pose"]))[2].log_time
    assert first_pose - first_signal == round((trial.times_s[0] + 0.012) * 1e9)
