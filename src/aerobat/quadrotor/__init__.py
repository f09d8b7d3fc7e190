"""The vehicle: a quadrocopter's model, input programs, maneuvers and the time-optimal benchmark.

Everything here is specific to quadrocopters (Sects. 6–9 of the paper) and
compiled where it is simulated (numba). The method in :mod:`aerobat.core` sees
these only through its protocols.
"""
