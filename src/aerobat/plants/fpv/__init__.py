"""What the two plants that fly Betaflight by radio share: the pilot, its frames, the trial's phases, the world.

The lockstep plant (:mod:`aerobat.plants.betaflight`, the SITL in lockstep with aerobat's physics) and
the flight controller on the wall clock (:mod:`aerobat.plants.fc`, a board over MSP, or the firmware
rehearsed in real time) are flown by the same offboard pilot; neither imports the other.

* :mod:`.params` — the settings of the vehicle, its world and its pilot (``--betaflight FILE.toml``).
* :mod:`.pilot` — the sticks a pilot gives: ANGLE-mode position hold, ACRO rates for a maneuver.
* :mod:`.frames`, :mod:`.frame_by_frame` — the radio's frames: what a frame asks, and the loop that flies
  them one at a time in Python (the lockstep plant's compiled loop is its own).
* :mod:`.phases` — the pilot's phases of a supervised trial (arm, take off, hover, stream the program,
  return, land) on any flight that takes frames (:class:`~.phases.RadioPilot`).
* :mod:`.design_model` — the firmware design model the settings give.
* :mod:`.rehearsal` — what a rehearsal's world process and its ground station say to each other.
"""
