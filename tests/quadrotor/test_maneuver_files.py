"""Issue 17: maneuvers in files, plugins, guard rails (aerobat.quadrotor.maneuvers.staged, .plugins)."""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aerobat import Arena, MultiFlip, NominalModel, design, hummingbird, learn
from aerobat.cli import main
from aerobat.config import read_toml
from aerobat.core.expressions import parse_expression
from aerobat.core.registry import from_spec
from aerobat.core.testing import check_maneuver
from aerobat.errors import ConfigError
from aerobat.quadrotor.maneuvers import StagedManeuver, load_maneuver_file
from aerobat.store import Store

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples" / "maneuvers"
PLUGINS = Path(__file__).resolve().parent / "plugins"
CONFIG = hummingbird()


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


# ------------------------------------------------------------------ the triple flip, re-expressed


def test_the_file_triple_flip_designs_to_the_built_in_p0():
    from_file = load_maneuver_file(EXAMPLES / "triple_flip_2d.toml", CONFIG.vehicle)
    built_in = MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=2)
    np.testing.assert_allclose(from_file.guess(), built_in.guess(), rtol=0, atol=1e-12)
    a, b = design(from_file, NominalModel(CONFIG)), design(built_in, NominalModel(CONFIG))
    assert a.converged and b.converged
    np.testing.assert_allclose(a.p_nominal, b.p_nominal, rtol=0, atol=1e-9)


def test_the_file_triple_flip_learns_identically_for_the_same_seed():
    from_file = load_maneuver_file(EXAMPLES / "triple_flip_2d.toml", CONFIG.vehicle)
    built_in = MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=2)
    a = learn(from_file, design(from_file, NominalModel(CONFIG)), Arena(CONFIG, seed=3), iterations=6)
    b = learn(built_in, design(built_in, NominalModel(CONFIG)), Arena(CONFIG, seed=3), iterations=6)
    assert [it.error.tobytes() for it in a.iterations] == [it.error.tobytes() for it in b.iterations]


@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_maneuver_conforms_and_designs(path):
    maneuver = load_maneuver_file(path, CONFIG.vehicle)
    result = check_maneuver(maneuver, model=NominalModel(CONFIG), rebuild=from_spec)
    assert result is not None and result.converged


@pytest.mark.slow
@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_maneuver_learns_on_the_arena(path):
    maneuver = load_maneuver_file(path, CONFIG.vehicle)
    session = learn(maneuver, design(maneuver, NominalModel(CONFIG)), Arena(CONFIG, seed=1, feedback="none"),
                    iterations=30)
    assert session.status.value == "completed"
    assert session.position_errors_m()[-10:].mean() <= 0.12


def test_a_zero_duration_stage_is_valid():
    maneuver = load_maneuver_file(EXAMPLES / "sideways_step.toml", CONFIG.vehicle)
    p = maneuver.guess()
    p[2] = 0.0  # the reverse tilt at its lower bound: two stages start at the same instant
    program = maneuver.program(p)
    assert program.duration_s > 0 and maneuver.is_valid(p)


def test_a_file_session_resumes_without_the_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    copy = tmp_path / "hop.toml"
    copy.write_text((EXAMPLES / "yaw_pirouette.toml").read_text())
    code, _, err = call(["learn", "--maneuver", str(copy), "--plant", "nominal", "--iterations", "2"])
    assert code == 0, err
    copy.unlink()  # the store keeps the file's content
    code, out, err = call(["learn", "--resume", "1", "--iterations", "3"])
    assert code == 0, err
    with Store("aerobat.sqlite", create=False) as store:
        assert store.maneuver(store.session(1).maneuver_id).spec["maneuver"]["name"] == "360° yaw pirouette"


# ------------------------------------------------------------------ guard rails


def test_learn_refuses_a_design_that_did_not_converge_unless_forced(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    far = read_toml(EXAMPLES / "climb_pitch_flip.toml")
    far["errors"][2]["target"] = 3.0  # 3 m higher with one flip: the design does not get there
    path = tmp_path / "far.toml"
    path.write_text(tomli_w.dumps(far))
    code, out, err = call(["learn", "--maneuver", str(path), "--plant", "nominal", "--iterations", "2"])
    assert code == 1 and "design failed" in err and "largest error" in err and "--force" in err
    assert not Path("aerobat.sqlite").exists() or Store("aerobat.sqlite", create=False).list_sessions() == []


def test_expressions_are_safe_and_errors_point_at_the_text():
    assert parse_expression("0.5 * (a + b) ** 2", where="w").evaluate({"a": 1.0, "b": 1.0}) == 2.0
    for text, fragment in (("__import__('os')", "unknown function"), ("a.real", "not allowed"), ("p0 +* 2", "column"),
                           ("open(1)", "unknown function"), ("'x'", "only numbers"), ("sqrt", "function")):
        with pytest.raises(ConfigError, match=fragment):
            parse_expression(text, where="f.toml: stages[0].duration_s").evaluate({"p0": 1.0})


@pytest.mark.parametrize(("text", "fragment"), [
    ("sqrt(1, 2)", "sqrt takes 1 argument, got 2"), ("abs(-1, 2)", "abs takes 1 argument, got 2"),
    ("atan2(1)", "atan2 takes 2 arguments, got 1"), ("min(1)", "min takes at least 2 arguments, got 1"),
    ("max(p0)", "max takes at least 2 arguments"), ("(-8)**(1/3)", "a negative number to a fractional power"),
    ("1" + "0" * 400, r"1000000000…000000 \(401 digits\) is too large for a float"),
    ("1e400", "not finite"), ("10 ** 400", "cannot be evaluated here"),
])
def test_expressions_refuse_wrong_arity_complex_powers_and_huge_numbers(text, fragment):
    """Issue 31 I2: TypeError, a complex number and OverflowError became aerobat's one-line errors."""
    with pytest.raises(ConfigError, match=fragment) as info:
        parse_expression(text, where="f.toml: stages[0].duration_s").evaluate({"p0": 1.0}, where="f.toml: x")
    assert "\n" not in str(info.value) and str(info.value).startswith("f.toml")
    assert parse_expression("(-8) ** 2 + max(1, 2, 3)", where="w").evaluate({}) == 67.0


def test_a_bad_expression_in_a_file_exits_2_naming_the_file(tmp_path):
    table = json.loads(json.dumps(read_toml(EXAMPLES / "yaw_pirouette.toml")))
    table["stages"][0]["duration_s"] = "sqrt(1, 2)"
    path = tmp_path / "arity.toml"
    path.write_text(tomli_w.dumps(table))
    code, _, err = call(["design", "--maneuver", str(path)])
    assert code == 2 and str(path) in err and "sqrt takes 1 argument" in err and len(err.strip().splitlines()) == 1


BASE = read_toml(EXAMPLES / "yaw_pirouette.toml")


def _variant(change) -> dict:
    table = json.loads(json.dumps(BASE))
    change(table)
    return table


BROKEN = {
    "unknown top field": (lambda t: t.update(stagez=[]), "stagez"),
    "unknown stage field": (lambda t: t["stages"][0].update(colective_m_s2=9.0), "stages[0]"),
    "string duration": (lambda t: t["stages"][0].update(duration_s=[1, 2]), "stages[0].duration_s"),
    "broken expression": (lambda t: t["stages"][0].update(duration_s="p0 *"), "stages[0].duration_s"),
    "unknown name": (lambda t: t["stages"][0].update(duration_s="p9"), "p9"),
    "cyclic derived": (lambda t: t.update(derived={"a": "b + 1", "b": "a * 2"}), "cyclic"),
    "bad quantity": (lambda t: t["errors"][0].update(quantity="spin"), "errors[0].quantity"),
    "negative scale": (lambda t: t["errors"][0].update(scale=-1.0), "errors[0].scale"),
    "no parameters": (lambda t: t.update(parameters={}), "parameters"),
    "guess out of bounds": (lambda t: t["parameters"]["p0"].update(guess=99.0), "guess"),
    "too many errors": (lambda t: t["errors"].extend([{"quantity": "position_x"}] * 3), "errors but only"),
    "bad name": (lambda t: t["parameters"].update({"1x": {"guess": 1.0}}), "not a valid name"),
    # issue 31 I3: a list where a name belongs raised "TypeError: unhashable type"
    "list quantity": (lambda t: t["errors"][2].update(quantity=["a", "b", "c"]), "errors[2].quantity: expected one"),
    "list description": (lambda t: t["parameters"]["p0"].update(description=["a"]), "p0.description: expected a str"),
    "list stage name": (lambda t: t["stages"][0].update(name={"a": 1}), "stages[0].name: expected a string"),
    "list error name": (lambda t: t["errors"][0].update(name=[1]), "errors[0].name"),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_broken_maneuver_file_is_one_line_naming_file_and_field(tmp_path, case):
    change, fragment = BROKEN[case]
    path = tmp_path / f"{case.replace(' ', '_')}.toml"
    path.write_text(tomli_w.dumps(_variant(change)))
    code, _, err = call(["design", "--maneuver", str(path)])
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("aerobat: error:") and "Traceback" not in err
    assert str(path) in lines[0] and fragment in lines[0], lines[0]


_values = st.one_of(st.integers(-10**6, 10**6), st.floats(allow_nan=False, allow_infinity=False, width=32),
                    st.text(max_size=12), st.booleans(), st.lists(st.integers(-3, 3), max_size=3))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture],
          derandomize=True)
@given(path=st.sampled_from([("stages", 0, "duration_s"), ("stages", 0, "collective_m_s2"),
                             ("parameters", "p0", "guess"), ("parameters", "p0", "lower"),
                             ("errors", 0, "target"), ("errors", 0, "scale"), ("constants", "W", None),
                             ("ramp_down", "collective_s", None), ("initial", "position_m", None)]),
       value=_values)
def test_fuzzed_maneuver_files_never_crash(tmp_path_factory, path, value):
    table = json.loads(json.dumps(BASE))
    container = table.setdefault(path[0], {})
    if path[2] is None:
        container[path[1]] = value
    else:
        container[path[1]][path[2]] = value
    target = tmp_path_factory.mktemp("fuzz") / "m.toml"
    target.write_text(tomli_w.dumps(table))
    code, _, err = call(["design", "--maneuver", str(target)])
    assert "Traceback" not in err and code in (0, 1, 2), err
    if code:
        assert len(err.strip().splitlines()) == 1, err


# ------------------------------------------------------------------ plugins


@pytest.fixture()
def plugin_path(monkeypatch):
    monkeypatch.syspath_prepend(str(PLUGINS))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(PLUGINS), os.environ.get("PYTHONPATH", "")]))
    yield "aerobat_test_plugin:VerticalHop"
    sys.modules.pop("aerobat_test_plugin", None)


def test_a_plugin_maneuver_runs_through_the_cli_store_and_a_study(tmp_path, monkeypatch, plugin_path):
    monkeypatch.chdir(tmp_path)
    code, _, err = call(["learn", "--maneuver", plugin_path, "--plant", "arena", "--iterations", "4"])
    assert code == 0, err
    for argv in (["sessions"], ["show", "1"], ["plot", "1"], ["export", "1", "--format", "json"], ["replay", "1"]):
        code, out, err = call(argv)
        assert code == 0, (argv, err)
    code, _, err = call(["learn", "--resume", "1", "--iterations", "5"])
    assert code == 0, err
    code, out, err = call(["study", "robustness", "--maneuver", plugin_path, "--vehicles", "2", "--iterations",
                           "3", "--workers", "2", "--json"])
    assert code == 0, err
    assert json.loads(out)["learned"] == 2


def test_a_plugin_reference_that_is_wrong_is_one_line(tmp_path, monkeypatch, plugin_path):
    monkeypatch.chdir(tmp_path)
    for ref, fragment in (("no_such_module:Thing", "cannot import"), ("aerobat_test_plugin:Nope", "no callable"),
                          ("not a reference", "expected a maneuver file")):
        code, _, err = call(["design", "--maneuver", ref])
        assert code == 2 and fragment in err and len(err.strip().splitlines()) == 1, err


def test_a_staged_maneuver_rebuilds_from_its_spec():
    maneuver = load_maneuver_file(EXAMPLES / "flip_sideways.toml", CONFIG.vehicle)
    again = from_spec(json.loads(json.dumps(maneuver.spec())))
    assert isinstance(again, StagedManeuver) and again.spec() == maneuver.spec()
    assert math.isclose(again.duration_s(again.guess()), maneuver.duration_s(maneuver.guess()))


# ------------------------------------------------------------------ issue 25 item 6: Python maneuvers


def _aerobat_script(argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """The installed ``aerobat`` command (its sys.path has no working directory, as for a user)."""
    script = Path(sys.executable).parent / "aerobat"
    return subprocess.run([str(script), *argv], capture_output=True, text=True, cwd=cwd, timeout=600,
                          env={**os.environ, "PYTHONPATH": str(ROOT / "src")})


@pytest.fixture()
def user_folder(tmp_path):
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    yield tmp_path
    sys.modules.pop("custom_maneuver", None)


def test_a_python_file_with_a_class_name_is_a_maneuver(user_folder):
    result = _aerobat_script(["design", "--maneuver", "examples/custom_maneuver.py:VerticalHop", "--json"],
                             user_folder)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["converged"] is True


@pytest.mark.parametrize(("spelling", "fragment"), [
    ("examples/custom_maneuver.py", "a Python file; name the maneuver in it as examples/custom_maneuver.py:Name "
                                    "(maneuvers in it: VerticalHop)"),
    ("examples.custom_maneuver:VerticalHop", "examples/custom_maneuver.py is a file here: name it as "
                                             "examples/custom_maneuver.py:VerticalHop (or "
                                             "aerobat.examples.custom_maneuver:VerticalHop"),
    ("examples/custom_maneuver.py:Nope", "custom_maneuver has no callable Nope"),
    ("examples/nothing.py:X", "examples/nothing.py is not a file"),
])
def test_python_maneuver_spellings_that_do_not_work_say_the_one_that_does(user_folder, spelling, fragment):
    """Was "invalid TOML" for a .py file and "No module named 'examples'" for the dotted name."""
    result = _aerobat_script(["design", "--maneuver", spelling], user_folder)
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and fragment in result.stderr, result.stderr
    assert "invalid TOML" not in result.stderr


def test_load_maneuver_is_one_call_for_every_spelling(user_folder, monkeypatch):
    from aerobat import load_maneuver

    monkeypatch.chdir(user_folder)
    step = load_maneuver("examples/maneuvers/sideways_step.toml")
    assert isinstance(step, StagedManeuver) and step.vehicle == CONFIG.vehicle
    assert load_maneuver(Path("examples/maneuvers/sideways_step.toml"), CONFIG).spec() == step.spec()
    hop = load_maneuver("examples/custom_maneuver.py:VerticalHop", CONFIG.vehicle)
    assert hop.name == "vertical hop" and hop.guess().tolist() == [0.3, 0.3]
    with pytest.raises(ConfigError, match="expected a maneuver file"):
        load_maneuver("not a reference")


def _wrong_sign(path: Path, tmp_path: Path) -> Path:
    """The sideways step with the roll rates' signs flipped: it steps to −y instead of +y."""
    text = path.read_text()
    text = text.replace('rate_p_rad_s = "-w"', 'rate_p_rad_s = "MINUS"').replace('rate_p_rad_s = "w"',
                                                                               'rate_p_rad_s = "-w"')
    target = tmp_path / "wrong_sign.toml"
    target.write_text(text.replace('"MINUS"', '"w"'))
    return target


def test_a_rate_of_the_wrong_sign_gets_a_hint(tmp_path):
    wrong = _wrong_sign(EXAMPLES / "sideways_step.toml", tmp_path)
    maneuver = load_maneuver_file(wrong, CONFIG.vehicle)
    result = design(maneuver, NominalModel(CONFIG))
    assert not result.converged
    assert "hint: at the guess y ends at -1.48 m, the opposite sign of its target +1.5: a rate or acceleration " \
           "of the wrong sign?" in result.message
    code, _, err = call(["design", "--maneuver", str(wrong)])
    assert code == 1 and "wrong sign" in err
    # a design that fails for another reason gets no such hint
    far = read_toml(EXAMPLES / "climb_pitch_flip.toml")
    far["errors"][2]["target"] = 3.0
    failed = design(StagedManeuver(vehicle=CONFIG.vehicle, table=far, source="far.toml"), NominalModel(CONFIG))
    assert not failed.converged and "hint" not in failed.message
