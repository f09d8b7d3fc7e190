"""Command programs: validation, TOML io and the compiled piecewise-polynomial commands."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from aerobat.config import ConfigError
from aerobat.quadrotor.program import CHANNELS, Program, RampDown, Switch, load_program, save_program

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
G = 9.81


def sw(t: float, channel: str, value: float) -> Switch:
    return Switch(time_s=t, channel=channel, value=value)


# ------------------------------------------------------------ validation


@pytest.mark.parametrize(
    ("switches", "duration", "pattern"),
    [
        (
            (sw(-0.1, "collective", 10.0),),
            1.0,
            r"^switch 0 \(collective\): time_s = -0.1 is negative",
        ),
        (
            (sw(0.1, "rate_p", 1.0), sw(0.2, "rate_q", math.nan)),
            1.0,
            r"^switch 1 \(rate_q\): value = nan is not finite",
        ),
        ((sw(math.inf, "rate_p", 1.0),), 1.0, r"^switch 0 \(rate_p\): time_s = inf is not finite"),
        (
            (sw(0.1, "roll", 1.0),),
            1.0,
            r"^switch 0: unknown channel 'roll'; allowed: collective, rate_p",
        ),
        (
            (sw(0.1, "rate_p", 1.0), sw(0.2, "rate_p", 0.0), sw(0.1, "rate_p", 2.0)),
            1.0,
            r"^switch 2 \(rate_p\): overlaps switch 0 .* time_s = 0.1",
        ),
        (
            (sw(1.0, "rate_p", 1.0),),
            1.0,
            r"^switch 0 \(rate_p\): time_s = 1 is at or after the program end",
        ),
        (
            (sw(0.0, "rate_p", 1.0), sw(2.0, "rate_p", 1.0)),
            1.0,
            r"^switch 1 \(rate_p\): time_s = 2 is at or after",
        ),
        ((sw(0.1, "rate_p", "1.0"),), 1.0, r"^switch 0: value must be a number, got '1.0'"),
        ((sw(0.1, "rate_p", True),), 1.0, r"^switch 0: value must be a number, got True"),
        (
            (sw(0.1, "collective", 500.0),),
            1.0,
            r"^switch 0 \(collective\): value = 500 is out of range: allowed \[0, 200\]",
        ),
        (
            (sw(0.1, "accel_q", -2e4),),
            1.0,
            r"^switch 0 \(accel_q\): value = -20000 is out of range",
        ),
        ((), 0.0, r"^duration_s = 0 is out of range: allowed \(0, 600\] \(s\)$"),
        ((), -1.0, r"^duration_s = -1 is out of range"),
        ((), math.nan, r"^duration_s = nan must be finite \(s\)$"),
        ((), 601.0, r"^duration_s = 601 is out of range"),
        ((), "1.0", r"^duration_s must be a number, got str '1.0'"),
    ],
)
def test_invalid_program_names_switch_and_field(switches, duration, pattern):
    with pytest.raises(ValueError, match=pattern):
        Program(switches=switches, duration_s=duration)


def test_same_time_on_different_channels_is_allowed():
    p = Program(
        switches=(sw(0.1, "rate_p", 1.0), sw(0.1, "rate_q", 1.0), sw(0.1, "collective", 12.0)),
        duration_s=1.0,
    )
    assert len(p.switches) == 3


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"collective_s": -0.1}, r"^collective_s = -0.1 is out of range: allowed >= 0 \(s\)$"),
        ({"rates_s": math.inf}, r"^rates_s = inf must be finite \(s\)$"),
    ],
)
def test_invalid_ramp_down(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        RampDown(**kwargs)


def test_invalid_hover_collective():
    with pytest.raises(ValueError, match=r"^hover_collective_m_s2 = -9.81 is out of range: allowed > 0 \(m/s²\)$"):
        Program(switches=(), duration_s=1.0, hover_collective_m_s2=-9.81)


HEADER = "[program]\nduration_s = 1.0\n"


def _switch(t: str, channel: str, value: str) -> str:
    return f'[[switch]]\ntime_s = {t}\nchannel = "{channel}"\nvalue = {value}\n'


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        # negative switch time
        (
            HEADER + _switch("0.0", "collective", "12.0") + _switch("-0.1", "rate_p", "1.0"),
            ["switch 1 (rate_p)", "time_s = -0.1", "negative"],
        ),
        # non-finite values (TOML spells them nan / inf)
        (
            HEADER + _switch("0.1", "collective", "nan"),
            ["switch 0 (collective)", "value = nan", "not finite"],
        ),
        (
            HEADER + _switch("0.1", "collective", "-inf"),
            ["switch 0 (collective)", "value = -inf", "not finite"],
        ),
        (
            HEADER + _switch("inf", "collective", "10.0"),
            ["switch 0 (collective)", "time_s = inf", "not finite"],
        ),
        ("[program]\nduration_s = nan\n", ["duration_s = nan", "must be finite"]),
        (
            "[program]\nduration_s = 1.0\nhover_collective_m_s2 = inf\n",
            ["hover_collective_m_s2 = inf"],
        ),
        # unknown channel
        (HEADER + _switch("0.1", "rate_x", "1.0"), ["switch 0", "unknown channel 'rate_x'"]),
        # overlapping switches: same channel, same time
        (
            HEADER
            + _switch("0.1", "accel_p", "1.0")
            + _switch("0.2", "accel_p", "0.0")
            + _switch("0.1", "accel_p", "3"),
            ["switch 2 (accel_p)", "overlaps switch 0", "time_s = 0.1"],
        ),
        # at / after the end
        (
            HEADER + _switch("1.0", "rate_p", "1.0"),
            ["switch 0 (rate_p)", "time_s = 1", "at or after", "duration_s = 1"],
        ),
        (
            HEADER + _switch("1.5", "rate_p", "1.0"),
            ["switch 0 (rate_p)", "time_s = 1.5", "at or after"],
        ),
        # missing duration
        ('[program]\nname = "no end"\n', ["[program]", "missing required field duration_s"]),
        (_switch("0.1", "rate_p", "1.0"), ["missing required table [program]"]),
        # wrong types
        (
            HEADER + _switch("0.1", "rate_p", '"1.0"'),
            ["switch 0", "value must be a number", "'1.0'"],
        ),
        (HEADER + _switch('"0.1"', "rate_p", "1.0"), ["switch 0", "time_s must be a number"]),
        (HEADER + _switch("0.1", "rate_p", "true"), ["switch 0", "value must be a number", "True"]),
        (
            HEADER + "[[switch]]\ntime_s = 0.1\nchannel = 3\nvalue = 1.0\n",
            ["switch 0", "channel must be a string"],
        ),
        ('[program]\nduration_s = "1.0"\n', ["[program] duration_s must be a number"]),
        ("[program]\nduration_s = 1.0\nname = 3\n", ["[program] name must be a string"]),
        (
            "[program]\nduration_s = 1.0\n[program.ramp_down]\ncollective_s = -0.2\n",
            ["ramp_down.collective_s = -0.2"],
        ),
        # structural problems
        (
            HEADER + '[[switch]]\ntime_s = 0.1\nchannel = "rate_p"\n',
            ["switch 0", "missing required field(s) value"],
        ),
        (
            HEADER
            + _switch("0.1", "rate_p", "1.0").replace("value = 1.0", 'value = 1.0\nunit = "deg"'),
            ["switch 0", "unknown field(s) unit"],
        ),
        (HEADER + "duration = 2.0\n", ["[program] unknown field(s) duration"]),
        (
            HEADER + "[program.ramp_down]\nthrust_s = 0.1\n",
            ["[program.ramp_down] unknown field(s) thrust_s"],
        ),
        (HEADER + "[extra]\n", ["unknown table(s) extra"]),
        ("switch = 3\n" + HEADER, ["'switch' must be an array of tables"]),
        ("[program]\nduration_s = 1.0\n[[switch]\n", ["invalid TOML"]),
    ],
)
def test_invalid_program_file_names_file_and_field(tmp_path, text, fragments):
    path = tmp_path / "bad program.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_program(path)
    message = str(info.value)
    assert message.startswith(f"{path}: "), message
    for fragment in fragments:
        assert fragment in message, message


def test_missing_program_file(tmp_path):
    with pytest.raises(ConfigError, match=r"nope.toml: file not found"):
        load_program(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match="is a directory"):
        load_program(tmp_path)


# ---------------------------------------------------------------- TOML io


def test_examples_load():
    hover = load_program(EXAMPLES / "hover.toml")
    assert hover.switches == () and hover.duration_s == 5.0
    single = load_program(EXAMPLES / "single_flip.toml")
    assert len(single.switches) == 10
    assert single.ramp_down == RampDown(collective_s=0.1, rates_s=0.0)
    triple = load_program(EXAMPLES / "triple_flip_1800.toml")
    assert triple.ramp_down == RampDown()
    assert all(s.channel in CHANNELS for s in triple.switches)


@pytest.mark.parametrize("name", ["hover.toml", "single_flip.toml", "triple_flip_1800.toml"])
def test_example_round_trip(tmp_path, name):
    program = load_program(EXAMPLES / name)
    save_program(program, tmp_path / name)
    again = load_program(tmp_path / name)
    assert again == program
    np.testing.assert_array_equal(again.compile().coefficients, program.compile().coefficients)


def test_round_trip_preserves_every_bit(tmp_path):
    program = Program(
        switches=(
            sw(0.1 + 0.2, "collective", 1 / 3),
            sw(0.0, "accel_p", -152.72060869565215),
            sw(1e-9, "rate_r", -math.pi),
            sw(0.7, "accel_r", 5e-324),  # subnormal survives
            sw(0.5, "rate_q", 0.0),
        ),
        duration_s=0.9390230897223883,
        ramp_down=RampDown(collective_s=0.123456789, rates_s=0.05),
        hover_collective_m_s2=9.80665,
        name='flip "π" – ünïcode',
    )
    path = tmp_path / "p.toml"
    save_program(program, path)
    again = load_program(path)
    assert again == program
    assert [s.time_s for s in again.switches] == [s.time_s for s in program.switches]


def test_integer_values_in_toml_become_floats(tmp_path):
    path = tmp_path / "ints.toml"
    path.write_text("[program]\nduration_s = 2\n" + _switch("0", "collective", "12"))
    p = load_program(path)
    assert p.duration_s == 2.0 and isinstance(p.duration_s, float)
    assert p.switches[0] == Switch(time_s=0.0, channel="collective", value=12.0)
    assert isinstance(p.switches[0].value, float)


# --------------------------------------------------------------- compile


def test_no_switches_is_hover_everywhere():
    p = Program(switches=(), duration_s=5.0)
    c = p.compile()
    np.testing.assert_array_equal(c.breakpoints_s, [0.0, 5.0])
    cmds = p.commands_at(np.linspace(0.0, 6.0, 61))
    np.testing.assert_array_equal(cmds, np.tile([G, 0.0, 0.0, 0.0], (61, 1)))


def test_zero_order_hold_and_hover_before_first_switch():
    p = Program(
        switches=(sw(0.2, "collective", 15.0), sw(0.5, "collective", 5.0), sw(0.3, "rate_q", -2.0)),
        duration_s=1.0,
    )
    t = np.array([0.0, 0.1999, 0.2, 0.25, 0.3, 0.4999, 0.5, 0.9999, 1.0, 1.5])
    cmds = p.commands_at(t)
    np.testing.assert_array_equal(cmds[:, 0], [G, G, 15, 15, 15, 15, 5, 5, G, G])
    np.testing.assert_array_equal(cmds[:, 2], [0, 0, 0, 0, -2, -2, -2, -2, 0, 0])
    np.testing.assert_array_equal(cmds[:, [1, 3]], 0.0)
    np.testing.assert_array_equal(p.compile().breakpoints_s, [0.0, 0.2, 0.3, 0.5, 1.0])


def test_switch_order_does_not_matter():
    switches = (
        sw(0.4, "accel_p", 0.0),
        sw(0.0, "collective", 20.0),
        sw(0.1, "accel_p", 30.0),
        sw(0.1, "collective", 12.0),
        sw(0.6, "rate_p", 1.0),
    )
    a = Program(
        switches=switches, duration_s=1.0, ramp_down=RampDown(collective_s=0.2, rates_s=0.3)
    ).compile()
    b = Program(
        switches=switches[::-1], duration_s=1.0, ramp_down=RampDown(collective_s=0.2, rates_s=0.3)
    ).compile()
    np.testing.assert_array_equal(a.breakpoints_s, b.breakpoints_s)
    np.testing.assert_array_equal(a.coefficients, b.coefficients)


def test_accelerations_integrate_into_rates():
    # accel_p 10 rad/s² over [0.1, 0.3) → p̂ ramps 0 → 2 rad/s; rate_p offset 0.5 added at 0.4.
    p = Program(
        switches=(
            sw(0.1, "accel_p", 10.0),
            sw(0.3, "accel_p", 0.0),
            sw(0.4, "rate_p", 0.5),
            sw(0.5, "accel_p", -4.0),
        ),
        duration_s=1.0,
    )
    t = np.array([0.05, 0.1, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.75, 0.99])
    expected = [0.0, 0.0, 1.0, 1.5, 2.0, 2.0, 2.5, 2.5, 2.5, 2.5 - 4 * 0.25, 2.5 - 4 * 0.49]
    np.testing.assert_allclose(p.commands_at(t)[:, 1], expected, rtol=0, atol=1e-13)


def test_ramp_down_envelope_reaches_hover_at_the_end():
    T, ramp_c, ramp_r = 1.0, 0.2, 0.4
    p = Program(
        switches=(sw(0.0, "collective", 15.0), sw(0.0, "accel_q", 3.0)),
        duration_s=T,
        ramp_down=RampDown(collective_s=ramp_c, rates_s=ramp_r),
    )
    bp = p.compile().breakpoints_s
    np.testing.assert_allclose(bp, [0.0, 0.6, 0.8, 1.0], rtol=0, atol=1e-15)
    t = np.array([0.3, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95, 1.0 - 1e-9])
    w_c = np.minimum(1.0, (T - t) / ramp_c)
    w_r = np.minimum(1.0, (T - t) / ramp_r)
    cmds = p.commands_at(t)
    np.testing.assert_allclose(cmds[:, 0], G + w_c * (15.0 - G), rtol=0, atol=1e-12)
    # the raw rate is the integral 3 t; the envelope multiplies it (a quadratic in t on the ramp)
    np.testing.assert_allclose(cmds[:, 2], w_r * 3.0 * t, rtol=0, atol=1e-12)
    assert abs(cmds[-1, 0] - G) < 1e-7 and abs(cmds[-1, 2]) < 1e-7  # continuous at T
    np.testing.assert_array_equal(p.commands_at(np.array([T, T + 1]))[:, 0], [G, G])


def test_ramp_longer_than_program():
    p = Program(
        switches=(sw(0.0, "collective", 15.0),),
        duration_s=0.5,
        ramp_down=RampDown(collective_s=1.0),
    )
    t = np.array([0.0, 0.25, 0.49])
    np.testing.assert_allclose(
        p.commands_at(t)[:, 0], G + (0.5 - t) / 1.0 * (15.0 - G), rtol=0, atol=1e-12
    )


def test_custom_hover_collective():
    p = Program(
        switches=(sw(0.5, "collective", 12.0),),
        duration_s=1.0,
        hover_collective_m_s2=9.0,
        ramp_down=RampDown(collective_s=0.2),
    )
    np.testing.assert_allclose(
        p.commands_at(np.array([0.0, 0.7, 0.9, 2.0]))[:, 0],
        [9.0, 12.0, 10.5, 9.0],
        rtol=0,
        atol=1e-12,
    )
    np.testing.assert_array_equal(p.compile().hover, [9.0, 0.0, 0.0, 0.0])


def test_single_flip_commands_reach_eq_27_peak_rate():
    """The single flip's p̂ ramps up with 152.72 rad/s², coasts, and comes back to ≈0 at the end."""
    p = load_program(EXAMPLES / "single_flip.toml")
    t = np.linspace(0.0, p.duration_s, 2001)
    rates = p.commands_at(t)[:, 1]
    s = {(x.channel, x.value): x.time_s for x in p.switches}
    t_up, t_coast = s[("accel_p", 152.72060869565215)], s[("accel_p", 0.0)]
    peak = -13.598832339218125 * t_up + 152.72060869565215 * (t_coast - t_up)
    assert rates.max() == pytest.approx(peak, rel=1e-9)
    assert peak == pytest.approx(math.radians(800.0), rel=0.05)
    # total commanded rotation ∫p̂ dt ≈ 2π (one flip); Simpson on a fine grid
    from scipy.integrate import simpson

    assert simpson(rates, x=t) == pytest.approx(2 * math.pi, rel=0.02)


def test_hover_collective_of_wrong_type_names_the_field():
    with pytest.raises(ValueError, match="hover_collective_m_s2"):
        Program(switches=(), duration_s=1.0, hover_collective_m_s2="9.81")  # type: ignore[arg-type]
