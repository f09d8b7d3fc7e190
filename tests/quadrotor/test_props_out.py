"""Props out (issue 42): the physics' spins and the firmware's yaw mixer turn together.

A quad whose propellers turn the other way round flies a yaw command exactly as one with props in:
its rotors' drag torques reverse, and the mixer (``yaw_motors_reversed = ON``) raises the other diagonal.
Either half alone would turn a yaw command into its opposite; the tests fly both halves.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from aerobat.errors import ConfigError
from aerobat.plants.fpv.design_model import firmware_design_model, plant_settings
from aerobat.plants.fpv.params import BetaflightParams, params_to_table
from aerobat.quadrotor.dynamics import P_KYAW
from aerobat.quadrotor.program import Program, Switch
from aerobat.quadrotor.vehicle import fpv5
from aerobat.quadrotor.xframe import MOTOR_SPIN_CCW, Airframe, xframe_plant


def _out(params: BetaflightParams) -> BetaflightParams:
    return dataclasses.replace(params, airframe=dataclasses.replace(params.airframe, props_out=True))


def test_props_out_reverses_every_spin_and_drag_torque():
    inside, outside = Airframe(), Airframe(props_out=True)
    assert inside.spins_ccw == MOTOR_SPIN_CCW and outside.spins_ccw == tuple(not s for s in MOTOR_SPIN_CCW)
    assert np.array_equal(xframe_plant(outside)[P_KYAW:P_KYAW + 4], -xframe_plant(inside)[P_KYAW:P_KYAW + 4])
    with pytest.raises(ConfigError, match="props_out"):
        Airframe(props_out="yes")  # type: ignore[arg-type]


def test_the_firmware_reverses_its_yaw_mix_with_the_airframe_and_only_then():
    params = BetaflightParams()
    assert plant_settings(params).value("yaw_motors_reversed") == "OFF"
    assert plant_settings(_out(params)).value("yaw_motors_reversed") == "ON"
    assert "props_out" not in params_to_table(params)["airframe"]  # stored forms before props_out are unchanged
    assert params_to_table(_out(params))["airframe"]["props_out"] is True


def test_a_yaw_command_flies_the_same_with_props_in_and_out():
    config = fpv5()
    program = Program(switches=(Switch(time_s=0.0, channel="rate_r", value=math.radians(300.0)),
                                Switch(time_s=0.0, channel="collective", value=9.81),
                                Switch(time_s=0.4, channel="rate_r", value=0.0)), duration_s=0.6)
    base = BetaflightParams()  # a symmetric frame: with uneven motors the two diagonals would differ on purpose
    params = dataclasses.replace(base, airframe=dataclasses.replace(base.airframe, thrust_gains=(1.0, 1.0, 1.0, 1.0),
                                                                    com_offset_m=(0.0, 0.0, 0.0)))
    inside = firmware_design_model(config, params).trajectory(program)
    outside = firmware_design_model(config, _out(params)).trajectory(program)
    assert math.degrees(np.max(inside.states[:, 12])) > 250.0  # it did yaw at about the command
    body = slice(0, 13)  # position, velocity, attitude, rates: the rotors' own states (13..16) swap diagonals
    assert np.allclose(outside.states[:, body], inside.states[:, body], rtol=0.0, atol=1e-9)
    yaw_mix = np.array([1.0 if ccw else -1.0 for ccw in MOTOR_SPIN_CCW])  # packet slots: the CCW ones minus the CW
    assert np.allclose(outside.motors @ yaw_mix, -(inside.motors @ yaw_mix), atol=1e-9)
    assert np.max(np.abs(inside.motors @ yaw_mix)) > 0.05
