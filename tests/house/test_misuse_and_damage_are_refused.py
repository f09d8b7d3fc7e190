"""Misuse and damage are refused with one clear line, and nothing is lost or silent.

The store is never an output, ``--db`` is always a path, a damaged or re-identified store is not
written, losing it mid-session is a failure; bad command lines and wrong-typed library arguments
get one line naming the option (``ConfigError`` from the API). Each test reproduces what an
adversarial pass of issue 19 found, and failed on the code before the fix.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import math
import os
import socket
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from aerobat.cli import main
from aerobat.store import Store, checksums

SMALL = ["flip", "--dims", "2", "--flips", "1", "--max-rate-deg-s", "800"]


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def one_error_line(err: str, *fragments: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("aerobat: error:") and "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in lines[0], err


@pytest.fixture()
def store_with_a_session(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, err = call(["learn", *SMALL, "--plant", "nominal", "--iterations", "2", "--db", "s.sqlite"])
    assert code == 0, err
    return tmp_path / "s.sqlite"


# ------------------------------------------------------------------ 1, 2: outputs never overwrite the store


def test_export_refuses_the_store_and_existing_files(store_with_a_session):
    db = store_with_a_session
    before = digest(db)
    code, _, err = call(["export", "1", "--db", str(db), "--format", "csv", "--output", str(db)])
    assert code == 2
    one_error_line(err, "that is the experiment store")
    code, _, err = call(["export", "1", "--db", str(db), "--format", "csv", "--output", str(db), "--force"])
    assert code == 2  # never the store, not even with --force
    assert digest(db) == before
    other = db.parent / "x.csv"
    other.write_text("keep me")
    code, _, err = call(["export", "1", "--db", str(db), "--output", str(other)])
    assert code == 2 and other.read_text() == "keep me"
    one_error_line(err, "exists", "--force")
    code, _, err = call(["export", "1", "--db", str(db), "--output", str(other), "--force"])
    assert code == 0 and other.read_text().startswith("session,")


def test_benchmark_map_output_cannot_be_the_store(store_with_a_session):
    db = store_with_a_session
    before = digest(db)
    code, _, err = call(["benchmark", "map", "--y=1:1:1", "--z=1:1:1", "--workers", "1", "--db", str(db),
                         "--out", str(db)])
    assert code == 2 and "--out" in err
    assert digest(db) == before
    with Store(db, create=False) as store:
        assert store.integrity_check() == [] and len(store.list_sessions()) == 1


# ------------------------------------------------------------------ 3: --db is always a path


def test_a_db_that_looks_like_an_sqlite_uri_is_a_plain_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    name = "file:m.sqlite?mode=memory"
    code, _, err = call(["learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--db", name])
    assert code == 0, err
    assert (tmp_path / name).is_file()  # on disk, under exactly that name
    code, out, err = call(["sessions", "--db", name, "--json"])
    assert code == 0 and '"id": 1' in out, err


# ------------------------------------------------------------------ 4: damaged or re-identified stores


def _damage(db: Path) -> None:
    with sqlite3.connect(db) as conn:
        # the meta table: one small leaf page, so the damage is always of the same kind (a cell pointer out of
        # range), which quick_check reports and which reading sessions does not touch
        root = conn.execute("SELECT rootpage FROM sqlite_master WHERE name = 'meta'").fetchone()[0]
        size = conn.execute("PRAGMA page_size").fetchone()[0]
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    data = bytearray(db.read_bytes())
    offset = (root - 1) * size
    data[offset + 8: offset + 12] = b"\xff\xff\xff\xff"  # cell pointers out of range: quick_check reports it
    db.write_bytes(bytes(data))


def test_a_damaged_store_is_refused_for_writing_and_reported_for_reading(store_with_a_session):
    db = store_with_a_session
    _damage(db)
    before = digest(db)
    for argv in (["learn", "--resume", "1", "--iterations", "4"], ["learn", *SMALL, "--iterations", "1"]):
        code, out, err = call([*argv, "--db", str(db)])
        assert code == 2, err
        one_error_line(err)
        assert "quick_check" in err or "malformed" in err  # SQLite's own check, or SQLite gave up reading
        assert "session" not in out  # nothing was flown
    assert digest(db) == before
    code, out, err = call(["sessions", "--db", str(db)])
    # reading: shown with a warning, or (when SQLite cannot read the damaged page at all) one clear line
    assert (code == 0 and "warning:" in err and "damaged" in err) or (code == 2 and "malformed" in err), err


def test_a_store_whose_identity_was_changed_is_not_written(store_with_a_session):
    db = store_with_a_session
    with sqlite3.connect(db) as conn:
        conn.execute("PRAGMA application_id = 7")
    before = digest(db)
    code, _, err = call(["learn", "--resume", "1", "--iterations", "4", "--db", str(db)])
    assert code == 2
    one_error_line(err, "application_id", "changed")
    assert digest(db) == before
    code, out, err = call(["show", "1", "--db", str(db)])
    assert code == 0 and "warning:" in err


# ------------------------------------------------------------------ 5: losing the store mid-session


def test_deleting_the_store_mid_session_stops_it_with_a_failure(tmp_path):
    db = tmp_path / "gone.sqlite"
    proc = subprocess.Popen([sys.executable, "-m", "aerobat.cli", "learn", *SMALL, "--plant", "arena",
                             "--iterations", "3000", "--db", str(db), "--out", str(tmp_path / "o")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 120
        while time.time() < deadline:
            line = proc.stdout.readline() if proc.stdout else ""
            if line.strip().startswith("2  ok"):
                break
        for suffix in ("", "-wal", "-shm"):
            with contextlib.suppress(FileNotFoundError):
                os.remove(f"{db}{suffix}")
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1, err
    assert "deleted or replaced" in err and "Traceback" not in err


# ------------------------------------------------------------------ 7, 8: no internal errors, clear messages


@pytest.mark.parametrize("argv, fragments", [
    (["design", "translation", "--to", "0,0"], ["target is the start"]),
    (["learn", *SMALL, "--seed", "9223372036854775808"], ["--seed"]),
    (["learn", *SMALL, "--seed", "-1"], ["--seed"]),
    (["sessions", "--limit", "1e23"], ["--limit"]),
    (["design", "flip", "--max-rate-deg-s", "99999"], ["--max-rate-deg-s", "deg/s"]),
    (["learn", *SMALL, "--plant", "nominal", "--arena", "a.toml"], ["--arena", "--plant arena"]),
    (["learn", *SMALL, "--to", "1,2"], ["--to", "does not apply"]),
    (["design", "translation", "--to=-1e9,3"], ["--to", "1000"]),
    (["design", "translation", "--flips", "2"], ["--flips", "does not apply"]),
])
def test_bad_input_is_one_line_naming_the_option(tmp_path, monkeypatch, argv, fragments):
    monkeypatch.chdir(tmp_path)
    started = time.perf_counter()
    code, _, err = call(argv)
    assert code == 2, err
    one_error_line(err, *fragments)
    assert time.perf_counter() - started < 30  # refused before any long solve


def test_an_impossible_vehicle_says_it_cannot_hover(tmp_path):
    heavy = tmp_path / "heavy.toml"
    heavy.write_text("[vehicle]\nmass_kg = 100.0\n")
    code, _, err = call(["design", *SMALL, "--vehicle", str(heavy)])
    assert code == 2
    one_error_line(err, "rotor_thrust_max_n", "cannot hover", str(heavy))


def test_a_benchmark_map_with_one_point_per_axis_draws(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, err = call(["benchmark", "map", "--y=2:2:1", "--z=1:1:1", "--workers", "1"])
    assert code == 0, err
    assert next((tmp_path / "out").glob("aerobat-*/study-1")).joinpath("benchmark_map.png").stat().st_size > 1000


def test_closing_stdout_interrupts_the_session_cleanly(tmp_path):
    db = tmp_path / "p.sqlite"
    learn = subprocess.Popen([sys.executable, "-m", "aerobat.cli", "learn", *SMALL, "--iterations", "40", "--db",
                              str(db), "--out", str(tmp_path / "o")], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert learn.stdout is not None
    for _ in range(2):
        learn.stdout.readline()
    learn.stdout.close()  # as `| head -2` does
    _, err = learn.communicate(timeout=120)
    assert learn.returncode == 141, err  # 128 + SIGPIPE
    assert b"standard output was closed" in err and b"resume with" in err
    with Store(db, create=False) as store:
        rec = store.session(1)
        assert rec.state == "interrupted" and rec.n_measured >= 1


def test_a_read_only_store_fails_before_the_design_and_still_reads(store_with_a_session, monkeypatch):
    db = store_with_a_session
    real_access = os.access

    def file_read_only(path, mode, *args, **kwargs):  # as chmod 444 is for a normal user (root ignores it)
        if mode == os.W_OK and Path(path).resolve() == db.resolve():
            return False
        return real_access(path, mode, *args, **kwargs)

    monkeypatch.setattr(os, "access", file_read_only)
    started = time.perf_counter()
    code, out, err = call(["learn", "flip", "--flips", "3", "--dims", "3", "--iterations", "1", "--db", str(db)])
    assert code == 2 and time.perf_counter() - started < 5 and "session" not in out
    one_error_line(err, "read-only")
    assert call(["sessions", "--db", str(db)])[0] == 0


def test_a_store_in_a_read_only_folder_can_be_read(store_with_a_session, monkeypatch):
    db = store_with_a_session
    real_access = os.access

    def folder_read_only(path, mode, *args, **kwargs):
        if mode == os.W_OK and Path(path).resolve() == db.parent.resolve():
            return False
        return real_access(path, mode, *args, **kwargs)

    monkeypatch.setattr(os, "access", folder_read_only)
    code, out, err = call(["sessions", "--db", str(db)])
    assert code == 0 and "2D 1x roll flip" in out and "read-only" in err
    code, _, err = call(["learn", *SMALL, "--iterations", "1", "--db", str(db)])
    assert code == 2 and "read-only" in err


def test_a_session_of_another_machine_needs_take_over(store_with_a_session):
    db = store_with_a_session
    with sqlite3.connect(db) as conn:
        checksums.update(conn, db, "sessions", {"id": 1}, {"state": "running", "owner": "elsewhere:4242:1",
                                                           "host": "elsewhere", "pid": 4242})
    code, _, err = call(["learn", "--resume", "1", "--iterations", "3", "--db", str(db)])
    assert code == 2
    one_error_line(err, "another machine", "--take-over")
    code, _, err = call(["learn", "--resume", "1", "--iterations", "3", "--db", str(db), "--take-over"])
    assert code == 0, err
    assert socket.gethostname() in Store(db, create=False).session(1).owner


def test_waiting_for_another_writer_is_announced(store_with_a_session):
    db = store_with_a_session
    holder = sqlite3.connect(db, isolation_level=None, check_same_thread=False)
    holder.execute("BEGIN IMMEDIATE")
    release = threading.Timer(2.5, lambda: holder.execute("COMMIT"))
    release.start()
    try:
        code, _, err = call(["learn", "--resume", "1", "--iterations", "3", "--db", str(db)])
    finally:
        release.join()
        holder.close()
    assert code == 0, err
    assert "waiting for another process's lock" in err


# ------------------------------------------------------------------ 10: the API meets misuse with clear errors


def test_the_api_refuses_misuse_with_config_errors():
    from aerobat import Arena, MultiFlip, NominalModel, design, hummingbird, learn
    from aerobat.errors import ConfigError

    config = hummingbird()
    with pytest.raises(ConfigError, match="VehicleConfig"):
        MultiFlip(vehicle=config)
    flip = MultiFlip(vehicle=config.vehicle, flips=1, dims=2, max_rate_rad_s=np.radians(800))
    nominal = design(flip, NominalModel(config))
    for bad in ({"rule": "bogus"}, {"iterations": float("nan")}, {"iterations": 2.5}, {"iterations": float("inf")},
                {"iterations": -1}):
        kwargs = {"iterations": 2, **bad}
        with pytest.raises(ConfigError):
            learn(flip, nominal, Arena(config), **kwargs)
    with pytest.raises(ConfigError, match="Design"):
        learn(flip, "not a design", Arena(config), iterations=1)  # type: ignore[arg-type]


# ------------------------------------------------- the library's entry points, found by scripts/fuzz_campaign.py


def _refused(fn, *args, fragment: str = "", **kwargs) -> str:
    """``fn(...)`` raises an AerobatError (never a TypeError or AttributeError from inside); its message."""
    from aerobat.errors import AerobatError

    with pytest.raises(AerobatError) as info:
        fn(*args, **kwargs)
    assert fragment in str(info.value), str(info.value)
    return str(info.value)


@pytest.mark.parametrize("bad", [None, 5, 1.5, [], ("a",), np.zeros(2), {"a": 1}, b"bytes", "nul\x00.toml",
                                 "飞" * 100 + ".toml"])
def test_file_functions_refuse_what_cannot_be_a_file(tmp_path, bad):
    from aerobat import Store, hummingbird, load_program, load_vehicle, save_program, save_vehicle
    from aerobat.experiments.studies import load_ranges
    from aerobat.plants.arena.params import ArenaParams, load_arena, save_arena
    from aerobat.quadrotor.maneuvers import load_maneuver_file

    if isinstance(bad, str) and "飞" in bad:
        bad = str(tmp_path / bad)
    config = hummingbird()
    for loader in (load_vehicle, load_program, load_arena, load_ranges):
        _refused(loader, bad)
    _refused(load_maneuver_file, bad, config.vehicle)
    _refused(save_vehicle, config, bad)
    _refused(save_arena, ArenaParams(), bad)
    _refused(Store, bad)
    program = load_program(Path(__file__).resolve().parents[2] / "examples" / "hover.toml")
    _refused(save_program, program, bad)


def test_savers_refuse_objects_of_the_wrong_kind(tmp_path):
    from aerobat import hummingbird, save_program, save_vehicle
    from aerobat.plants.arena.params import save_arena

    _refused(save_vehicle, "hummingbird", tmp_path / "v.toml", fragment="config")
    _refused(save_program, hummingbird(), tmp_path / "p.toml", fragment="program")
    _refused(save_arena, None, tmp_path / "a.toml", fragment="params")
    _refused(save_vehicle, hummingbird(), "/proc/version", fragment="/proc/version")  # cannot write: OutputError
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("timeout", [{}, "1", float("nan"), -1.0, None])
def test_store_busy_timeout_must_be_a_number(tmp_path, timeout):
    from aerobat import Store

    _refused(Store, tmp_path / "s.sqlite", busy_timeout_s=timeout, fragment="busy_timeout_s")


EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.parametrize("changes, fragment", [
    ({"program": "hover.toml"}, "program"), ({"config": None}, "config"), ({"max_step_s": None}, "max_step_s"),
    ({"max_step_s": 5e-324}, "max_step_s"), ({"max_step_s": 5e-324, "record": False}, "max_step_s"),
    ({"mode": "sampled", "substeps": 10**9}, "substeps"), ({"mode": "sampled", "tick_s": 1e-300}, "tick_s"),
    ({"substeps": 2.5}, "substeps"), ({"plant": 0}, "plant"), ({"record": np.zeros(3)}, "record"),
    ({"mode": np.zeros(2)}, "mode"), ({"initial_state": 10**400}, "initial_state"),
    ({"initial_state": np.zeros(3)}, "initial_state")])
def test_simulate_refuses_bad_arguments(changes, fragment):
    from aerobat import hummingbird, load_program, simulate

    kwargs = {"program": load_program(EXAMPLES / "single_flip.toml"), "config": hummingbird(), **changes}
    _refused(simulate, kwargs.pop("program"), kwargs.pop("config"), fragment=fragment, **kwargs)


@pytest.mark.parametrize("changes, fragment", [
    ({"configs": 0}, "configs"), ({"configs": [None]}, "configs[0]"), ({"programs": np.int64(3)}, "programs"),
    ({"programs": [None]}, "programs[0]"), ({"initial_states": 1 + 2j}, "initial_states"),
    ({"plants": {}}, "plants"), ({"max_step_s": 1e-300}, "max_step_s")])
def test_simulate_batch_refuses_bad_arguments(changes, fragment):
    from aerobat import NominalModel, hummingbird, load_program, simulate_batch

    kwargs = {"programs": [load_program(EXAMPLES / "single_flip.toml")], "configs": hummingbird(), **changes}
    _refused(simulate_batch, kwargs.pop("programs"), kwargs.pop("configs"), fragment=fragment, **kwargs)
    _refused(NominalModel, [], fragment="config")
    _refused(NominalModel, hummingbird(), max_step_s=0.0, fragment="max_step_s")
    _refused(NominalModel(hummingbird()).final_states, -1e308, fragment="programs")


def test_plants_refuse_bad_arguments():
    from aerobat import Arena, ArenaParams, NominalPlant, PlantChoice, hummingbird

    config = hummingbird()
    _refused(Arena, "hummingbird", fragment="config")
    _refused(Arena, config, {"a": 1}, fragment="params")
    for seed in (-1, "1", math.inf, np.full(3, np.nan), 2**64):
        _refused(Arena, config, ArenaParams(), seed=seed, fragment="seed")
    _refused(NominalPlant, b"x", fragment="config")
    for rate in ("abc", np.full(3, np.nan), 0.0, 1e308):
        _refused(NominalPlant, config, sample_rate_hz=rate, fragment="sample_rate_hz")
    for plant in (Arena(config, seed=1), NominalPlant(config)):
        for program in (None, {}, "hover.toml", np.zeros((2, 2)), config):
            _refused(plant.fly, program, fragment="program")
    for kind in ([], {"a": 1}, np.zeros((2, 2)), None):
        _refused(PlantChoice, kind, fragment="plant")
        _refused(PlantChoice.from_file, kind, None, fragment="plant")


@pytest.fixture(scope="module")
def small_design():
    from aerobat import MultiFlip, NominalModel, design, hummingbird

    config = hummingbird()
    flip = MultiFlip(vehicle=config.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
    return config, flip, design(flip, NominalModel(config))


def test_design_and_learn_refuse_bad_arguments(small_design):
    from aerobat import NominalModel, NominalPlant, RuleChoice, design, learn, make_rule

    config, flip, nominal = small_design
    model = NominalModel(config)
    for bad in (1e308, {"a": 1}, np.full(5, np.nan), (1, 2), None):
        _refused(design, bad, model, fragment="maneuver")
        _refused(design, flip, bad, fragment="model")
        _refused(learn, bad, nominal, NominalPlant(config), iterations=1, fragment="maneuver")
        _refused(learn, flip, nominal, bad, iterations=1, fragment="plant")
        _refused(make_rule, bad, nominal, fragment="choice")
        _refused(make_rule, "paper", bad, fragment="design")
    for name, value in (("tolerance", np.zeros((2, 2))), ("tolerance", 10**400), ("tsvd_rtol", config),
                        ("damping", None), ("max_iterations", -30), ("raise_on_failure", math.inf),
                        ("correction", "qr"), ("p_guess", np.zeros(2)), ("p_guess", "abc")):
        _refused(design, flip, model, fragment=name, **{name: value})
    _refused(learn, flip, nominal, NominalPlant(config), iterations=1, max_attempts=config, fragment="max_attempts")
    _refused(learn, flip, nominal, NominalPlant(config), iterations=1, start_params={}, fragment="start parameters")
    _refused(RuleChoice, "paper", schedule=[1.0], fragment="schedule")
    _refused(RuleChoice, "paper", isc="yes", fragment="isc")


def test_sessions_and_store_queries_refuse_bad_arguments(store_with_a_session, small_design):
    from aerobat import PlantChoice, RuleChoice, resume_session, start_session
    from aerobat.experiments.reports import load_session

    config, flip, nominal = small_design
    with Store(store_with_a_session) as store:
        for ref in (math.inf, -math.inf, math.nan, 1.5, True, 2**64, {}, None):
            _refused(store.resolve_session, ref, fragment="session")
            _refused(store.resolve_study, ref, fragment="study")
        for session_id in (2**64, -(2**70)):
            _refused(store.session, session_id)
            _refused(load_session, store, session_id)
        _refused(store.list_sessions, limit=2**63, fragment="limit")
        _refused(store.list_sessions, limit="", fragment="limit")
        _refused(store.list_sessions, newest_first=np.zeros(0), fragment="newest_first")
        base = {"model": config, "plant": PlantChoice("nominal"), "rule": RuleChoice(), "iterations": 1,
                "design_result": nominal}
        for name, value in (("model", np.int64(3)), ("plant", "nominal"), ("rule", np.zeros((2, 2))),
                            ("design_result", "converged"), ("command", config), ("warm_start_from", 1.5),
                            ("study_id", "x")):
            _refused(start_session, store, flip, fragment=name, **{**base, name: value})
        _refused(start_session, store, b"x", fragment="maneuver", **base)
        for bad in ({"a": 1}, np.zeros(0), "abc"):
            _refused(start_session, bad, flip, fragment="store", **base)
            _refused(resume_session, bad, "last", fragment="store")
            _refused(load_session, bad, 1, fragment="store")


def test_maneuvers_and_programs_refuse_bad_arguments(small_design):
    from aerobat import MultiFlip, Program, RampDown, Translation, from_spec, solve_translation, translation_maneuver

    config, flip, nominal = small_design
    for name, value in (("max_rate_rad_s", {"a": 1}), ("max_rate_rad_s", np.full(5, np.nan)),
                        ("max_rate_rad_s", 10**400), ("coast_collective", np.zeros(0)), ("axis", ["roll"]),
                        ("dims", np.zeros(2)), ("ramp_collective_s", "0.1"), ("name", 5)):
        _refused(MultiFlip, vehicle=config.vehicle, fragment=name, **{name: value})
    for params in ("", {}, 10**400, config, np.zeros((2, 2))):
        _refused(flip.program, params, fragment="parameters")
    for name, value in (("config", b"x"), ("target_yz", 1 + 2j), ("target_yz", 1), ("target_yz", [1.0]),
                        ("final_angle_rad", 10**400), ("ramp_s", [])):
        kwargs = {"config": config, "target_yz": (1.0, 1.0), name: value}
        _refused(translation_maneuver, kwargs.pop("config"), kwargs.pop("target_yz"), fragment=name, **kwargs)
    translation = Translation(vehicle=config.vehicle, target_yz=(1.0, 1.0), final_angle_rad=0.0,
                              interval_inputs=((10.0, 0.0),), guess_times_s=(1.0,))
    for name, value in (("interval_inputs", 1e308), ("interval_inputs", ((1.0, "x"),)), ("guess_times_s", None),
                        ("vehicle", config), ("target_yz", "ab")):
        fields = {"vehicle": translation.vehicle, "target_yz": translation.target_yz, "final_angle_rad": 0.0,
                  "interval_inputs": translation.interval_inputs, "guess_times_s": translation.guess_times_s}
        _refused(Translation, fragment=name, **{**fields, name: value})
    _refused(RampDown, collective_s=10**400, fragment="collective_s")
    for switches in (10**400, Path("/nonexistent"), "abc"):
        _refused(Program, switches=switches, duration_s=1.0, fragment="switches")
    _refused(Program, switches=(), duration_s=10**400, fragment="duration_s")
    _refused(config.with_mass, 10**400, fragment="mass_kg")
    _refused(solve_translation, 1.0, 1.0, intervals=2**64, fragment="intervals")
    _refused(solve_translation, 10**400, 1.0, fragment="target_y_m")
    _refused(from_spec, flip.spec(), source={"a": 1}, fragment="source")


def test_more_entry_points_refuse_bad_arguments(tmp_path, small_design):
    from aerobat import ControllerParams, PlantChoice, hummingbird, simulate_batch, start_session
    from aerobat.experiments.reports import session_from_json

    config, flip, nominal = small_design
    for order in (10**400, config, (1, 2, 3, "4"), (1.0, 2.0, 3.0, 4.0), None):
        _refused(ControllerParams, motor_order=order, fragment="motor_order")
    _refused(simulate_batch, [], hummingbird(), max_step_s=10**400, fragment="max_step_s")
    with Store(tmp_path / "s.sqlite") as store:
        for params in ("abc", np.zeros(2), {}):
            _refused(start_session, store, flip, model=config, plant=PlantChoice("nominal"), iterations=1,
                     design_result=nominal, start_params=params, fragment="start_params")
    for data in (np.full(5, np.nan), [], "x", {"maneuver": flip.spec(), "design": [1]}, {"iterations": 5}):
        _refused(session_from_json, data, fragment="session JSON")


def test_ctrl_c_while_a_local_pool_runs_is_raised_between_waits():
    """A KeyboardInterrupt inside the pool's locks can leave one released twice (RuntimeError: release
    unlocked lock, an internal error found by the fuzz campaign's budget); the executor defers it."""
    import signal

    from aerobat.experiments.execution import LocalExecutor
    from aerobat.experiments.job import Job

    pool = LocalExecutor(2)
    seen = []
    try:
        with pytest.raises(KeyboardInterrupt):
            for _job, _result in pool.run([Job(f"k{i}", "no-such-kind", {}) for i in range(4)]):
                seen.append(signal.getsignal(signal.SIGINT))
                signal.raise_signal(signal.SIGINT)  # Ctrl-C while jobs are still running or queued
    finally:
        pool.close()
    assert len(seen) == 1 and seen[0] is not signal.default_int_handler
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_out_folder_whose_name_is_not_text_is_refused_before_the_study(tmp_path):
    """Found by the fuzz campaign: the study ran, then storing its folder raised UnicodeEncodeError."""
    out = os.fsdecode(bytes(tmp_path) + b"/\xff\xfe")
    db = tmp_path / "s.sqlite"
    code, stdout, err = call(["study", "envelope", "--dims", "2", "--workers", "1", "--rates-deg-s", "800",
                              "--flips", "1", "--out", out, "--db", str(db)])
    assert code == 2
    one_error_line(err, "--out", "not valid UTF-8")
    assert "jobs to run" not in stdout


def test_arena_sections_of_the_wrong_type_are_config_errors():
    """Found by the fuzz campaign: ArenaParams(links=5) raised AttributeError."""
    from aerobat.errors import ConfigError
    from aerobat.plants import ArenaParams

    with pytest.raises(ConfigError, match="links: expected a Links, got int 5"):
        ArenaParams(links=5)


@pytest.mark.parametrize("kwargs, fragment", [({"create": np.full(5, np.nan)}, "create = "),
                                              ({"create": "yes"}, "create"), ({"synchronous": ["full"]}, "synchronous"),
                                              ({"on_wait": 3}, "on_wait")])
def test_store_options_of_the_wrong_type_are_refused_naming_them(tmp_path, kwargs, fragment):
    """Found by the fuzz campaign: ``Store(path, create=array)`` raised numpy's 'truth value … ambiguous'."""
    from aerobat.store import Store

    _refused(Store, tmp_path / "s.sqlite", fragment=fragment, **kwargs)
    assert not (tmp_path / "s.sqlite").exists()
