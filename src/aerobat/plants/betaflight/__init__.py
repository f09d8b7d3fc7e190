"""``--plant betaflight``: Betaflight 4.6 firmware in the loop, a lockstep SITL driven by aerobat's physics.

The firmware itself (its protocols, settings, tunes, the SITL's build, process and exchange) is the
library :mod:`aerobat.firmware.betaflight`, which the flight controller on the wall clock
(:mod:`aerobat.plants.fc`) uses as well. This package is the plant around it:

* :mod:`.plant` — :class:`~.plant.BetaflightPlant`: one iteration of Fig. 8 flown through the firmware.
* :mod:`.flight` — one flight: a firmware process, the physical world, the radio and motion capture.
* :mod:`.physics` — the world around the firmware: one compiled step of rigid body and rotors.
* :mod:`.lockstep` — the lockstep exchange and the physics in one compiled loop (many steps per call),
  over shared memory or UDP (``firmware.exchange``).
* :mod:`.cores` — a core each for the driver and the firmware (``firmware.pin_cores``).
* :mod:`.frame_loop`, :mod:`.frame_noise` — the compiled loop that flies the radio's frames, the sensors' noise.
* :mod:`.replay` — a recorded flight's sticks replayed into the SITL (``aerobat log replay``).
* :mod:`.model_check` — the firmware design model checked against a noiseless trial.

The settings, the pilot, its frames and phases and the firmware design model are shared with
:mod:`aerobat.plants.fc` and live in :mod:`aerobat.plants.fpv`.

* :mod:`.spec` — the plant's entry in the registry (:data:`SPEC`).

``from aerobat.plants.betaflight.plant import BetaflightPlant``; only the spec is imported here, so that
listing plants starts no firmware and compiles nothing.
"""

from aerobat.plants.betaflight.spec import SPEC

__all__ = ["SPEC"]
