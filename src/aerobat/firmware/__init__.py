"""Flight-controller firmware as a library: what aerobat knows of a firmware, apart from any plant.

* :mod:`aerobat.firmware.betaflight` — Betaflight 4.6: its MSP and CLI protocols, RC channels, the
  versioned settings and real quads' tunes, and the patched SITL (build, process, lockstep exchange).

Both plants that fly Betaflight use it: the lockstep plant (:mod:`aerobat.plants.betaflight`) and the
flight controller on the wall clock (:mod:`aerobat.plants.fc`). It imports no plant (``make lint``).
"""
