"""``--plant betaflight``: the arena's physical world with Betaflight 4.6 as the onboard loop.

One :meth:`BetaflightPlant.fly` is one iteration of the paper's Fig. 8, flown the way an FPV
pilot flies (``docs/plants.md``, Betaflight):

1. **Power on** on the floor below the start: a fresh SITL process (lockstep, its own ports)
   boots from the configured eeprom; ARM off, ANGLE on, throttle low while Betaflight
   calibrates its gyro.
2. **Arm** through AUX1; the firmware answers with idle motor commands.
3. **Take off, settle, hover** in ANGLE mode: the offboard position loop on motion capture sends
   angle sticks and throttle over the radio (250 Hz, lossy) until the vehicle has stayed at the
   start for the hold time and then hovered for ``hover_s``.
4. **Trigger**: AUX2 switches to ACRO (air mode is on whenever armed) and the program streams
   as stick positions (body rates through the linear rate curve, collective through the inverted
   throttle→thrust model), one frame per radio period.
5. **Measure**: after the program (and 15 ms of its hover command) ANGLE mode and the position
   loop take over and fly back; the final state at the maneuver's end is estimated from
   motion-capture samples alone (:mod:`aerobat.plants.mocap`).
6. **Land and disarm** on the floor; the firmware process ends with the trial.

Every trial starts a fresh firmware: the plant's state between trials is its random generator,
the trial count and the battery (drift), so a saved state repeats the next trial bit for bit.
A firmware that dies or stops answering loses the trial (``TrialStatus.LOST``, with the reason);
the next trial starts a new one, and learning flies the lost parameters again.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.core.plant import Trial, TrialStatus
from aerobat.firmware.betaflight.errors import FirmwareNotResponding
from aerobat.firmware.betaflight.settings import BetaflightSettings
from aerobat.plants.betaflight.flight import Flight, NonFinite
from aerobat.plants.betaflight.physics import airframe_plant
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.plants.fpv.phases import failed_trial
from aerobat.plants.fpv.radio_plant import RadioPlant
from aerobat.plants.plant_state import StateLayout
from aerobat.quadrotor.feedback import (
    Feedback,
    FeedbackScheme,
)
from aerobat.quadrotor.program import CompiledProgram, Program
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["BetaflightPlant"]

_LAYOUT = StateLayout("betaflight", counters=("trials_flown",), fractions=("capacity",))


class BetaflightPlant(RadioPlant):
    """The 5-inch racer in a motion-capture arena, flown by Betaflight 4.6 (SITL, lockstep).

    Parameters
    ----------
    config : the *nominal* vehicle (the design model), used for g; the true vehicle is
        ``params.airframe``, whose published mass and thrust curve the pilot's collective →
        throttle model inverts (``params.pilot.vehicle_mass_kg``).
    params : the plant's settings (:class:`~aerobat.plants.fpv.params.BetaflightParams`).
    seed : seeds the plant's generator (noise, wind, radio losses, motor spread per trial).
    binary, eeprom : the SITL binary and configured eeprom (default: built and configured on
        first use, cached: :func:`aerobat.firmware.betaflight.build.ensure_sitl`,
        :func:`aerobat.firmware.betaflight.configure.ensure_eeprom`).
    settings : the firmware's settings (default: the packaged ``settings.toml``).
    feedback : what the offboard pilot mixes into the program's sticks (:mod:`aerobat.quadrotor.feedback`;
        default the best scheme measured, ``tracking``; ``"none"`` streams the program as it is).
        Betaflight runs no program, so the law runs in the pilot, at the radio's rate, on motion capture: the
        attitude is the latest motion-capture sample carried forward by the commanded rates over its age and the
        radio's latency (the pilot sees no gyro).
    design_model : the vehicle the programs were designed on, if not ``config`` (a vehicle identified from
        this plant): the feedback tracks that vehicle's flight of each program.
    """

    name = "betaflight"

    def __init__(self, config: VehicleConfig, params: BetaflightParams | None = None, *, seed: int = 0,
                 binary: Path | None = None, eeprom: Path | None = None,
                 settings: BetaflightSettings | None = None,
                 feedback: Feedback | FeedbackScheme | str | None = None,
                 design_model: VehicleConfig | None = None) -> None:
        from aerobat.firmware.betaflight.build import ensure_sitl
        from aerobat.firmware.betaflight.configure import ensure_eeprom

        super().__init__(config, params, seed=seed, settings=settings, feedback=feedback, design_model=design_model)
        self.binary = Path(binary) if binary is not None else ensure_sitl()
        self.eeprom = Path(eeprom) if eeprom is not None else ensure_eeprom(self.binary, settings=self.settings)
        self.flight: Flight | None = None  # the flight in progress (for fault injection and diagnosis)

    # ---------------------------------------------------------------- trial
    def _trial_plant(self, rng: np.random.Generator) -> np.ndarray:
        """The true vehicle for one trial: motor spread, battery, per-trial jitter, wind and gust."""
        p = self.params
        gains = np.array(p.airframe.thrust_gains, dtype=float) * self.capacity
        extra: dict[str, Any] = {}
        d = p.disturbances
        if d.enabled:
            gains = gains * (1.0 + d.thrust_gain_jitter * rng.standard_normal()
                             + d.motor_gain_jitter * rng.standard_normal(4))
            extra = {"wind_m_s": tuple(float(v) for v in d.wind_std_m_s * rng.standard_normal(3)),
                     "gust_amplitude_m_s": tuple(float(v) for v in d.gust_amplitude_std_m_s * rng.standard_normal(3)),
                     "gust_frequency_hz": d.gust_frequency_hz,
                     "gust_phase_rad": float(rng.uniform(0.0, 2.0 * math.pi))}
        return airframe_plant(p, thrust_gains=(float(gains[0]), float(gains[1]), float(gains[2]), float(gains[3])),
                              **extra)

    def fly(self, program: Program | CompiledProgram) -> Trial:
        """One supervised trial (Fig. 8) through the firmware; a failure is a trial status, never an exception."""
        wall = time.perf_counter()
        compiled = program.compile() if isinstance(program, Program) else program
        rng = np.random.default_rng(self.rng.integers(2**63))  # one child stream per trial, whatever happens
        plant = self._trial_plant(rng)
        self.trials_flown += 1
        info: dict[str, Any] = {"firmware": f"Betaflight 4.6.0 SITL lockstep, settings revision "
                                            f"{self.settings.revision} ({self.settings.sha256[:12]})"
                                            + (f", tune {self.params.tune.source}" if self.params.tune else "")}
        flight = None
        try:
            flight = self.open_flight(rng, plant)
            self.flight = flight
            return self._fly(flight, compiled, info, wall)
        except FirmwareNotResponding as error:
            info.update(self._timing(flight, wall))
            reason = str(error).splitlines()[0]
            return failed_trial(TrialStatus.LOST, f"firmware lost: {reason}; the next trial starts a new one", info)
        except NonFinite as error:
            info.update(self._timing(flight, wall))
            return failed_trial(TrialStatus.ABORTED, str(error), info)
        finally:
            self.flight = None
            if flight is not None:
                flight.close()
            if self.params.drift.enabled:
                self.capacity *= 1.0 - self.params.drift.thrust_loss_per_trial

    def open_flight(self, rng: np.random.Generator | None = None, plant: np.ndarray | None = None) -> Flight:
        """A fresh firmware and the vehicle on the floor below the start, powered on (not a trial).

        ``rng`` defaults to a child of the plant's generator, ``plant`` to this trial's true vehicle.
        The caller closes it (a context manager). :meth:`fly` runs the phases below on one.
        """
        rng = rng if rng is not None else np.random.default_rng(self.rng.integers(2**63))
        plant = plant if plant is not None else self._trial_plant(rng)
        return Flight(self.binary, self.eeprom, self.params, plant, self.start_m, rng, self.gravity)

    def _timing(self, flight: Flight | None, wall: float) -> dict[str, Any]:
        elapsed = time.perf_counter() - wall
        simulated = flight.time_s if flight is not None else 0.0
        cpu = flight.firmware_cpu_time_s() if flight is not None else None
        spun, driver_spun = flight.spun_s() if flight is not None else (0.0, 0.0)
        choices = flight.spin_choices() if flight is not None else None
        # the driver's measured spin policy (shm_exchange.c, choose_spin): the waits that slept at once
        policy = {} if choices is None else {"driver_sleeping_share": choices.sleeping_share,
                                             "driver_spin_switches": choices.switches,
                                             "driver_spin_probes": choices.probes}
        return {"wall_s": elapsed, "simulated_s": simulated,
                "steps": flight.tick if flight is not None else 0,
                "real_time_factor": simulated / elapsed if elapsed > 0 else math.nan,
                # the driver's overhead: wall time per second of the firmware's own CPU time
                "firmware_cpu_s": cpu if cpu is not None else math.nan,
                "wall_per_firmware_cpu": elapsed / cpu if cpu else math.nan,
                # over shared memory the waits spin first: CPU time spent waiting, not working (wall
                # time spinning: under load it includes preemption)
                "firmware_spin_s": spun, "driver_spin_s": driver_spun,
                # Python's turns: calls into the compiled frame loop (the firmware may nap in each)
                "compiled_calls": flight.compiled_calls - 1 if flight is not None else 0, **policy}

    def _ok_message(self, info: dict[str, Any]) -> str:
        return (f"maneuver flown through Betaflight ({info['steps']} lockstep steps, "
                f"{info['frames_dropped']}/{info['frames_sent']} radio frames lost)")

