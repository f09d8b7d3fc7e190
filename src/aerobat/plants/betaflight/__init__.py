"""``--plant betaflight``: Betaflight 4.6 firmware in the loop, a lockstep SITL driven by aerobat's physics.

The firmware itself (its protocols, settings, tunes, the SITL's build, process and exchange) is the
library :mod:`aerobat.firmware.betaflight`, which the flight controller on the wall clock
(:mod:`aerobat.plants.fc`) uses as well. This package is the plant around it:

* :mod:`.plant` — :class:`~.plant.BetaflightPlant`: one iteration of Fig. 8 flown through the firmware.
* :mod:`.params` — the plant's own settings (``--betaflight FILE.toml``): vehicle, airframe, arena.
* :mod:`.flight` — one flight: a firmware process, the physical world, the radio and motion capture.
* :mod:`.physics` — the world around the firmware: one compiled step of rigid body and rotors.
* :mod:`.lockstep` — the lockstep exchange and the physics in one compiled loop (many steps per call).
* :mod:`.lockstep_shm` — the same loop over the shared-memory exchange (``firmware.exchange = "shm"``).
* :mod:`.cores` — a core each for the driver and the firmware (``firmware.pin_cores``).
* :mod:`.frames`, :mod:`.frame_loop`, :mod:`.frame_by_frame`, :mod:`.frame_noise` — the radio's frames:
  what a frame asks, the compiled loop that flies them, the same in Python, the sensors' noise.
* :mod:`.pilot` — the sticks a pilot gives: ANGLE-mode position hold, ACRO rates for a maneuver.
* :mod:`.replay` — a recorded flight's sticks replayed into the SITL (``aerobat log replay``).
* :mod:`.design_model`, :mod:`.model_check` — the firmware design model this plant's settings give,
  and its check against a noiseless trial.

* :mod:`.spec` — the plant's entry in the registry (:data:`SPEC`).

``from aerobat.plants.betaflight.plant import BetaflightPlant``; only the spec is imported here, so that
listing plants starts no firmware and compiles nothing.
"""

from aerobat.plants.betaflight.spec import SPEC

__all__ = ["SPEC"]
