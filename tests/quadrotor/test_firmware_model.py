"""The firmware design model (aerobat.quadrotor.firmware) on its own: equilibria, its pieces, smoothness, the design.

The model against the firmware itself is tests/plants/betaflight/test_firmware_model_sitl.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from aerobat.core.design import DesignStatus, design
from aerobat.errors import ConfigError
from aerobat.firmware.betaflight.settings import load_settings
from aerobat.plants.fpv.design_model import firmware_config, firmware_design_model
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.quadrotor.firmware import FirmwareConfig
from aerobat.quadrotor.firmware import filters as f
from aerobat.quadrotor.firmware.layout import rates_curve
from aerobat.quadrotor.firmware.sticks import frames_of
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.program import Program, Switch
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import fpv5


@pytest.fixture(scope="module")
def config():
    return fpv5()


@pytest.fixture(scope="module")
def model(config):
    return firmware_design_model(config, BetaflightParams())


def _hover(seconds: float) -> Program:
    return Program(switches=(Switch(time_s=0.0, channel="collective", value=9.81),), duration_s=seconds,
                   hover_collective_m_s2=9.81)


@pytest.mark.parametrize("fidelity", ["design", "exact"])
def test_hover_is_an_equilibrium_of_the_loop(config, fidelity):
    """A second of hover commands from hover: the firmware's loop stays at rest, level, and the height moves
    only by the throttle path's resolution (the pilot's pulse, the firmware's integer throttle map and motor
    microseconds: ~0.1 % of thrust, a centimetre or two in a second)."""
    model = firmware_design_model(config, BetaflightParams(), fidelity=fidelity)
    x = model.final_states([_hover(1.0)])[0]
    assert np.linalg.norm(x[0:2]) < 1e-12
    assert abs(x[2]) < 0.03
    assert np.linalg.norm(x[10:13]) < 1e-9
    assert abs(x[6] - 1.0) < 1e-12


def test_hover_is_an_equilibrium_with_a_sagging_battery(config):
    """The hover command solves f(u) × battery factor = m g / 4 (here the pack at hover load is above the
    reference voltage, so the command is lower than without the battery), and hover is still at rest."""
    sagging = BetaflightParams().replace(airframe__battery_reference_v=15.6, airframe__battery_rest_v=16.3,
                                         airframe__battery_sag_v=3.0)
    model = firmware_design_model(config, sagging)
    steady = firmware_design_model(config, BetaflightParams())
    airframe = sagging.airframe
    u = float(model.hover_packet[0])
    assert airframe.battery_factor((u,) * 4) > 1.0 and u < float(steady.hover_packet[0])
    assert airframe.thrust_n(u) * airframe.battery_factor((u,) * 4) == pytest.approx(model.hover_thrust_n, rel=1e-12)
    x = model.final_states([_hover(1.0)])[0]
    assert np.linalg.norm(x[0:2]) < 1e-12 and abs(x[2]) < 0.03 and np.linalg.norm(x[10:13]) < 1e-9


def test_the_battery_factor_is_the_packs_voltage_squared():
    """(V/V_ref)² with V = rest − sag · mean(u²), commands clipped to [0, 1]; 1 without a battery model."""
    from aerobat.quadrotor.xframe import Airframe

    airframe = Airframe(battery_reference_v=15.6, battery_rest_v=16.3, battery_sag_v=3.0)
    assert airframe.battery_factor((0.0,) * 4) == pytest.approx((16.3 / 15.6) ** 2, rel=1e-14)
    assert airframe.battery_factor((1.0, 1.0, 0.0, 0.0)) == pytest.approx(((16.3 - 1.5) / 15.6) ** 2, rel=1e-14)
    assert airframe.battery_factor((2.0, -1.0, 1.0, 0.0)) == airframe.battery_factor((1.0, 0.0, 1.0, 0.0))
    assert Airframe(battery_rest_v=16.3, battery_sag_v=3.0).battery_factor((1.0,) * 4) == 1.0  # no reference: off
    with pytest.raises(ConfigError, match="battery_sag_v"):
        Airframe(battery_reference_v=15.6, battery_rest_v=16.3, battery_sag_v=16.3)


def test_a_roll_command_is_tracked_within_the_rate_loops_lag(model):
    """Half a second at 400 deg/s of roll stick: the body turns 200 degrees, less the loop's lag of some ms."""
    program = Program(switches=(Switch(time_s=0.0, channel="rate_p", value=math.radians(400.0)),
                                Switch(time_s=0.0, channel="collective", value=9.81),
                                Switch(time_s=0.5, channel="rate_p", value=0.0)),
                      duration_s=0.7, hover_collective_m_s2=9.81)
    flight = model.trajectory(program)
    turned = math.degrees(flight.states[-1, 17])
    assert 180.0 < turned < 200.0
    mid = np.searchsorted(flight.times_s, 0.3)
    assert abs(math.degrees(flight.states[mid, 10]) - 400.0) < 8.0  # tracked: the PID's steady error is small
    assert abs(flight.setpoint_deg_s[mid, 0] - 400.0) < 1e-6  # the firmware's set point is the stick's rate


def test_frames_carry_the_program_mean_and_constants_exactly():
    program = Program(switches=(Switch(time_s=0.0, channel="rate_p", value=1.0),
                                Switch(time_s=0.0101, channel="rate_p", value=3.0)),
                      duration_s=0.03, hover_collective_m_s2=9.81).compile()
    frames = frames_of(program, 0.004, 9)
    assert frames[0, 1] == 1.0 and frames[1, 1] == 1.0  # inside a constant stretch: the constant itself
    assert frames[2, 1] == pytest.approx((0.0021 * 1.0 + 0.0019 * 3.0) / 0.004, rel=1e-12)
    assert frames[3, 1] == 3.0
    assert frames[8, 1] == 0.0  # past the end: the hover command
    # the integral of the rate command survives the frames (up to the last frame's hover part)
    assert np.sum(frames[:8, 1]) * 0.004 == pytest.approx(0.0101 * 1.0 + (0.03 - 0.0101) * 3.0, rel=1e-12)


def test_filters_are_betaflights(model):
    """PT1 gain as filter.c computes it, PT3 −3 dB at its cutoff, and a notch that removes its centre."""
    dt = 125e-6
    assert f.pt_gain(100.0, dt, 1) == pytest.approx((2 * math.pi * 100 * dt) / (2 * math.pi * 100 * dt + 1))
    state = np.zeros(f.SIZE)
    f.set_lowpass(f.PT3, state, 0, 93.0, dt)
    t = np.arange(40000) * dt
    out = np.array([f.apply(f.PT3, state, 0, v) for v in np.sin(2 * math.pi * 93.0 * t)])
    k = f.pt_gain(93.0, dt, 3)  # three sections k / (1 − (1 − k) z⁻¹): the discrete response at 93 Hz
    section = abs(k / (1.0 - (1.0 - k) * np.exp(-2j * math.pi * 93.0 * dt)))
    assert np.max(np.abs(out[20000:])) == pytest.approx(section**3, abs=1e-3)
    assert section**3 == pytest.approx(10 ** (-3 / 20), abs=0.04)  # −3 dB at the cutoff, up to discretisation
    f.set_notch(state, 0, 200.0, 160.0, dt)
    f.reset(state, 0, 0.0, f.NOTCH)
    out = np.array([f.apply(f.NOTCH, state, 0, v) for v in np.sin(2 * math.pi * 200.0 * t)])
    assert np.max(np.abs(out[20000:])) < 0.01


@pytest.mark.parametrize("kind,name", [(0, "BETAFLIGHT"), (1, "RACEFLIGHT"), (2, "KISS"), (3, "ACTUAL"), (4, "QUICK")])
def test_rate_curves_agree_with_the_plants_stick_map(kind, name):
    """The model's rate curve and the pilot's (firmware_settings.rate_deg_s) are the same function of the stick."""
    settings = load_settings().with_values({"rates_type": name, "roll_rc_rate": "120", "roll_srate": "70",
                                            "roll_expo": "30"}, why="test")
    for x in np.linspace(-1.0, 1.0, 21):
        expected = settings.rate_deg_s("roll", float(x))
        got = min(max(rates_curve(kind, 120.0, 70.0, 30.0, float(x)), -1998.0), 1998.0)
        assert got == pytest.approx(expected, rel=1e-9, abs=1e-9), (name, x)


def test_a_setting_the_model_does_not_model_refuses_it_by_name():
    values = dict(firmware_config(load_settings(), gyro_rate_hz=8000).values)
    values["abs_control_gain"] = "10"
    with pytest.raises(ConfigError, match=r"abs_control_gain = 10: absolute control is not modelled.*--design-model "
                                          r"paper"):
        FirmwareConfig.from_mapping(values, source="test")
    del values["p_roll"]
    with pytest.raises(ConfigError, match="no value for p_roll"):
        FirmwareConfig.from_mapping(values, source="test")


def test_the_design_model_is_smooth_where_the_exact_one_jumps(config):
    """A switch time swept across radio frames: the design fidelity moves smoothly, the exact one jumps by centimetres.

    What the exact model keeps and the design model leaves out (docs/plants.md): feedforward's treatment of a
    repeated frame and the 1 µs steps change the final state in steps as a switch crosses a frame's boundary.
    """
    flip = MultiFlip(vehicle=config.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
    p = design(flip, NominalModel(config)).p_nominal
    sweep = p[1] + np.linspace(-0.004, 0.004, 81)  # the accelerate stage's length, two frames either way
    params = np.tile(p, (sweep.size, 1))
    params[:, 1] = sweep
    programs = [flip.program(q) for q in params]
    jumps = {}
    for fidelity in ("design", "exact"):
        finals = firmware_design_model(config, BetaflightParams(), fidelity=fidelity).final_states(programs)
        y = finals[:, 1]
        second = np.abs(np.diff(y, 2))  # curvature of a smooth curve at this spacing is tiny
        jumps[fidelity] = float(np.max(second))
    assert jumps["design"] < 2e-3
    assert jumps["exact"] > 5 * jumps["design"]


def test_the_triple_flip_designs_on_the_firmware_model_from_the_papers_p0(config, model):
    flip = MultiFlip(vehicle=config.vehicle, flips=3, max_rate_rad_s=math.radians(1800), dims=3)
    paper = design(flip, NominalModel(config))
    result = design(flip, model, p_guess=paper.p_nominal)
    assert result.status is DesignStatus.CONVERGED
    assert result.residual_norm < 1e-6
    assert result.rank == len(flip.errors)
    # the firmware flies the paper's p⁰ far from the target: the models differ where it matters
    miss = flip.error(model.final_states([flip.program(paper.p_nominal)])[0])
    assert np.linalg.norm(miss[[0, 2, 5]]) > 0.2
