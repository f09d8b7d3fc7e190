"""A frame's noise drawn in pieces (as the shared-memory loop takes it) is the noise drawn at once."""

from __future__ import annotations

import numpy as np
import pytest

from aerobat.plants.betaflight.frame_noise import ALL, begin_draws, draw_noise, sensor_draws_through
from aerobat.plants.fpv import frames as fr


def _config(sensor: bool, position: float, attitude: float) -> tuple[np.ndarray, np.ndarray]:
    cfg = np.zeros(fr.N_CFG, dtype=np.int64)
    cfg[fr.K_EVERY] = 40
    cfg[fr.K_SENSOR_NOISE] = int(sensor)
    fcfg = np.zeros(fr.N_FCFG)
    fcfg[fr.Q_POSITION_NOISE_M] = position
    fcfg[fr.Q_ATTITUDE_NOISE_RAD] = attitude
    return cfg, fcfg


def _at_once(n: int, seed: int, sensor: bool, position: float, attitude: float) -> tuple[np.ndarray, np.ndarray, float]:
    """What the frame drew before its steps did: sensor rows, then position rows, then attitude rows."""
    rng = np.random.default_rng(seed)
    noise = np.full((n, 6), 7.0)
    rows = n // 40 + 2
    mocap = np.zeros((rows, 6))
    if sensor:
        noise[:] = rng.standard_normal((n, 6))
    if position:
        for r in range(rows):
            for c in range(3):
                mocap[r, c] = position * rng.standard_normal()
    if attitude:
        for r in range(rows):
            for c in range(3):
                mocap[r, 3 + c] = attitude * rng.standard_normal()
    return noise, mocap, float(rng.random())


@pytest.mark.parametrize(("sensor", "position", "attitude"),
                         [(True, 1e-3, 2e-3), (False, 1e-3, 0.0), (True, 0.0, 0.0), (False, 0.0, 3e-3)])
def test_draws_in_pieces_are_the_draws_at_once(sensor: bool, position: float, attitude: float) -> None:
    n = 32
    cfg, fcfg = _config(sensor, position, attitude)
    expected_noise, expected_mocap, next_draw = _at_once(n, 5, sensor, position, attitude)
    for pieces in ([1, 6, 6, 200, 3], [ALL], [sensor_draws_through(i) for i in range(n)] + [ALL]):
        rng = np.random.default_rng(5)
        noise = np.full((n, 6), 7.0)
        mocap = np.ones((n // 40 + 2, 6))  # the frame's rows are zeroed when it begins
        st = np.zeros(fr.N_ST, dtype=np.int64)
        begin_draws(n, cfg, fcfg, st, mocap)
        assert st[fr.S_DRAWN] == 0
        for upto in pieces:
            draw_noise(min(ALL, st[fr.S_DRAWN] + upto) if upto != ALL else ALL, rng, cfg, fcfg, st, noise, mocap)
        assert st[fr.S_DRAWN] == st[fr.S_DRAW_TOTAL] == 6 * n * sensor + 6 * (position != 0) + 6 * (attitude != 0)
        assert np.array_equal(noise, expected_noise) and np.array_equal(mocap, expected_mocap)
        assert rng.random() == next_draw  # the generator is where the frame at once left it


def test_a_step_has_its_sensor_row_before_its_physics() -> None:
    cfg, fcfg = _config(True, 1e-3, 1e-3)
    rng = np.random.default_rng(1)
    noise, mocap, st = np.zeros((32, 6)), np.zeros((2, 6)), np.zeros(fr.N_ST, dtype=np.int64)
    begin_draws(32, cfg, fcfg, st, mocap)
    draw_noise(sensor_draws_through(3), rng, cfg, fcfg, st, noise, mocap)
    assert st[fr.S_DRAWN] == 24 and np.all(noise[:4] != 0.0) and np.all(noise[4:] == 0.0)
    draw_noise(sensor_draws_through(2), rng, cfg, fcfg, st, noise, mocap)  # nothing drawn twice
    assert st[fr.S_DRAWN] == 24


def test_polling_for_the_answer_takes_it_only_once_it_came() -> None:
    from aerobat.firmware.betaflight.errors import FirmwareUnavailable
    from aerobat.firmware.betaflight.shm import ShmRegion, library

    try:
        lib = library()
    except FirmwareUnavailable as error:
        pytest.skip(f"the shared-memory helper cannot be built here: {error}")
    region = ShmRegion(spin_s=0.0)
    try:
        state, motor, out = np.zeros(18), np.arange(19, dtype=np.float32), np.zeros(19, dtype=np.float32)
        region.publish_state(state)
        seq = lib.aerobat_shm_wait_state(region.address, state.ctypes.data, state.nbytes, 0, 0, 10**8)
        assert seq == 1
        assert lib.aerobat_shm_poll_motor(region.address, out.ctypes.data, out.nbytes) == 0  # not answered yet
        lib.aerobat_shm_publish_motor(region.address, motor.ctypes.data, motor.nbytes, seq)
        assert lib.aerobat_shm_poll_motor(region.address, out.ctypes.data, out.nbytes) == out.nbytes
        assert np.array_equal(out, motor)
        assert lib.aerobat_shm_poll_motor(region.address, out.ctypes.data, 10**6) == -1  # larger than the slot
    finally:
        region.close()
