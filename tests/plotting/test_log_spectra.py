"""The log figures' power spectra: NumPy's Welch is scipy.signal.welch's (log plot no longer imports scipy.signal)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal as sps

from aerobat.plotting.flightlog import welch


@pytest.mark.parametrize("n", [2, 3, 100, 1023, 1024, 1025, 5000, 66_641])
@pytest.mark.parametrize("nperseg", [7, 8, 1024])
def test_welch_is_scipys(n, nperseg):
    x = np.random.default_rng(n).normal(size=n).cumsum()
    f, p = sps.welch(x, fs=500.0, nperseg=min(nperseg, n))
    mine_f, mine_p = welch(x, 500.0, nperseg)
    assert np.allclose(mine_f, f) and np.allclose(mine_p, p, rtol=1e-10, atol=0.0)


def test_welch_of_one_sample_is_empty():
    f, p = welch(np.ones(1), 500.0)
    assert f.size == 0 and p.size == 0
