"""Body rates estimated from the attitude alone agree with the simulated ones (what the MCAP export sends)."""

from __future__ import annotations

import numpy as np
import pytest

from aerobat import hummingbird
from aerobat.errors import ConfigError
from aerobat.quadrotor.attitude_rates import body_rates_from_attitude
from aerobat.quadrotor.dynamics import quaternion_from_rotation_vector, quaternion_multiply
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import simulate

CONFIG = hummingbird()
P0_3D = np.array([21.147414905322183, 0.2489405172107463, 0.40965469406191607, 21.281144061832844,
                  0.2944397583640787, 8.21327673052149e-05, 0.005610005735469527, -0.0021228918136138486,
                  -0.009274212359579277])


def test_a_constant_rate_is_recovered_exactly_whatever_the_turn_per_sample():
    rate = np.array([30.0, -4.0, 2.5])  # rad/s: 1,760 °/s about x
    t = np.arange(0.0, 0.5, 0.005)
    q = [np.array([1.0, 0.0, 0.0, 0.0])]
    for _ in t[1:]:
        q.append(quaternion_multiply(q[-1], quaternion_from_rotation_vector(rate * 0.005)))  # body-frame turns
    signs = np.where(np.arange(t.size) % 3 == 0, -1.0, 1.0)[:, None]  # −q is the same attitude
    estimated = body_rates_from_attitude(t, np.array(q) * signs)
    np.testing.assert_allclose(estimated, np.tile(rate, (t.size, 1)), atol=1e-9)


def test_the_triple_flip_at_motion_capture_rate_is_within_a_tenth_of_a_percent_of_its_peak_rate():
    trajectory = simulate(MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=3).program(P0_3D), CONFIG)
    every = np.arange(0, trajectory.times_s.size, 10)  # 0.5 ms steps → 200 Hz, the arena's motion capture
    true = trajectory.body_rates_rad_s[every]
    estimated = body_rates_from_attitude(trajectory.times_s[every], trajectory.quaternion[every])
    assert np.abs(true).max() > 30.0  # 1,800 °/s
    assert np.abs(estimated - true).max() < 0.001 * np.abs(true).max()


def test_too_few_samples_or_a_time_that_does_not_increase_give_nan_and_a_wrong_shape_is_refused():
    assert np.isnan(body_rates_from_attitude(np.array([0.0]), np.array([[1.0, 0, 0, 0]]))).all()
    estimated = body_rates_from_attitude(np.array([0.0, 0.0, 0.1]), np.tile([1.0, 0, 0, 0], (3, 1)))
    assert np.isnan(estimated[0]).all() and np.isfinite(estimated[2]).all()
    with pytest.raises(ConfigError, match="quaternions"):
        body_rates_from_attitude(np.array([0.0, 0.1]), np.ones((2, 3)))
