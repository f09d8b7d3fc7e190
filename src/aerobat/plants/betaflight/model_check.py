"""The firmware design model held against the firmware itself: one program, the same vehicle, no noise.

:func:`noiseless` is the Betaflight plant's world reduced to what the firmware design model
describes: the model's airframe (no centre-of-mass offset, equal motors), no aerodynamics beyond
the model's, exact sensors, no wind, gusts, drift or jitter, a lossless radio, exact motion
capture. :func:`sitl_flight` flies a program there as a trial does (power on, calibrate, arm,
take off, settle, hover in ANGLE, the program in ACRO as the plant streams it) and records every
gyro period of the maneuver: the true state, the firmware's motor packet, its set point and its
P, I, D, F terms. :class:`~aerobat.quadrotor.firmware.FirmwareModel` ``.trajectory`` gives the
same rows for the model, so the two compare sample for sample (docs/plants.md, "The firmware
design model"; ``tests/plants/betaflight/test_firmware_model.py``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from aerobat.plants.fpv.frames import Mode, Radio
from aerobat.plants.fpv.params import BetaflightParams, Sensors
from aerobat.plants.fpv.pilot import program_sticks
from aerobat.plants.world_params import Aerodynamics, Disturbances, Drift
from aerobat.quadrotor.firmware import FirmwareModel, FirmwareTrajectory
from aerobat.quadrotor.firmware.sticks import frames_of
from aerobat.quadrotor.program import CompiledProgram, Program

__all__ = ["noiseless", "sitl_flight"]


def noiseless(params: BetaflightParams, model: FirmwareModel) -> BetaflightParams:
    """``params`` with the world reduced to ``model``'s: its airframe and drag, exact sensors, no disturbances,
    a lossless radio."""
    exact = Sensors(gyro_noise_rad_s=0.0, gyro_scale_error=(0.0, 0.0, 0.0), gyro_bias_rad_s=(0.0, 0.0, 0.0),
                    accel_noise_m_s2=0.0, attitude_error_rad=(0.0, 0.0))
    mocap = dataclasses.replace(params.motion_capture, position_noise_m=0.0, attitude_noise_rad=0.0)
    drag = model.aerodynamics
    unmatched = set(drag) - {"body_drag_n_s2_m2", "rotor_drag_s_m", "rotational_damping_n_m_s"}
    if any(drag[name] for name in unmatched):
        raise ValueError(f"the plant has no {', '.join(sorted(unmatched))}: it cannot fly the model's drag")
    aero = (Aerodynamics(body_drag_n_s2_m2=float(drag.get("body_drag_n_s2_m2", 0.0)),
                         rotor_drag_s_m=float(drag.get("rotor_drag_s_m", 0.0)),
                         rotational_damping_n_m_s=tuple(drag.get("rotational_damping_n_m_s", (0.0, 0.0, 0.0))))
            if drag else Aerodynamics(enabled=False))
    return params.replace(airframe=model.airframe, sensors=exact, aerodynamics=aero,
                          disturbances=Disturbances(enabled=False), drift=Drift(enabled=False),
                          motion_capture=mocap, radio=dataclasses.replace(params.radio, drop_probability=0.0))


def sitl_flight(plant: object, program: Program | CompiledProgram) -> FirmwareTrajectory:
    """Fly ``program`` through ``plant``'s firmware (a Betaflight plant) and record every gyro period of it.

    Rows start when the program's first frame reaches the receiver (the model's time 0) and end at
    the program's end; columns as :class:`~aerobat.quadrotor.firmware.FirmwareTrajectory`'s.
    """
    from aerobat.plants.betaflight.plant import BetaflightPlant

    if not isinstance(plant, BetaflightPlant):
        raise TypeError("sitl_flight needs a BetaflightPlant")
    compiled = program.compile() if isinstance(program, Program) else program
    flight = plant.open_flight()
    with flight:
        plant.pilot.power_on_and_arm(flight)
        plant.pilot.settle(flight)
        plant.pilot.hover(flight, plant.params.pilot.hover_s)
        period = flight.frame_steps * flight.step_s
        frames = flight.frames_for(compiled.duration_s) + 1
        commands = frames_of(compiled, period, frames)
        latency = flight.latency_steps
        total = latency + int(np.floor(compiled.duration_s / flight.step_s + 1e-9)) + 1
        rows = np.full((total + 1, 40), np.nan)
        sticks = np.zeros(4)
        start = flight.tick
        for i in range(total + 1):
            tick = flight.tick - start
            if tick % flight.frame_steps == 0 and tick // flight.frame_steps < frames:
                program_sticks(commands[tick // flight.frame_steps], plant.pilot.limits, sticks)
                channels = np.array([plant.pilot.channels(sticks, arm=True, angle=False)], dtype=np.int64)
                flight.run_frames(Mode.STREAM, 1, steps=1, channels_us=channels, radio=Radio.LOSSLESS)
            else:
                flight.run_frames(Mode.STEPS, 1, steps=1, radio=Radio.NONE)
            rows[i, 0] = (flight.tick - start - latency) * flight.step_s
            rows[i, 1:21] = flight.x
            packet = np.asarray(flight.motors, dtype=float)
            rows[i, 21:25] = packet[0:4]
            rows[i, 25:28] = packet[4:7]
            rows[i, 28:40] = packet[7:19].reshape(3, 4).T.reshape(12)
    kept = rows[rows[:, 0] >= -1e-12]
    return FirmwareTrajectory(times_s=kept[:, 0], states=kept[:, 1:21], motors=kept[:, 21:25],
                              setpoint_deg_s=kept[:, 25:28], pid=kept[:, 28:40].reshape(-1, 4, 3))
