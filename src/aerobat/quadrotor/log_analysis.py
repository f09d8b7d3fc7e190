"""What a pilot reads from a flight log: where it crashed, how the rate loop answers a step, and how the
gyro's noise moves with throttle. NumPy only; :mod:`aerobat.plotting.flightlog` draws them.

* **Crash**: the first sample in the log's last :data:`CRASH_SEARCH_S` seconds where the gyro reaches
  :data:`GYRO_SATURATION_DEG_S` (95 % of Betaflight's 2000 °/s range) or the accelerometer
  :data:`CRASH_SPECIFIC_FORCE_G`, moved back to the last sample before it that was still calm (gyro
  below a quarter of saturation, specific force below :data:`CALM_SPECIFIC_FORCE_G`); from there to the
  end is the crash. Saturated samples anywhere are
  left out of a plot's limits, so the crash no longer flattens the flight.
* **Step response** (what PID-Analyzer and PIDtoolbox draw; estimated here by least squares): the log
  is cut into overlapping segments; in each, the impulse response from set point to gyro over
  :data:`RESPONSE_S` is the least-squares FIR fit, and its running sum is the step response. Segments
  where the set point moves less than ``min_input_deg_s`` say nothing about the loop and are left out;
  the rest are averaged. (A regularised Wiener deconvolution, PID-Analyzer's way, was tried: on these
  logs its regularisation biased the steady state to 0.6–0.9 of the step, where least squares gives 1.)
* **Spectrogram against throttle**: the gyro cut into short segments, each one's power spectrum
  filed under its mean throttle, averaged per throttle bin: motor-harmonic noise shows as a line
  that moves with throttle, frame resonance as one that does not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["BAND_HZ", "CALM_SPECIFIC_FORCE_G", "CRASH_SEARCH_S", "CRASH_SPECIFIC_FORCE_G", "GYRO_SATURATION_DEG_S",
           "RESPONSE_S", "Crash", "StepResponse", "ThrottleSpectrogram", "estimate_step_response", "band_pass",
           "find_crash", "plot_limits", "throttle_spectrogram", "welch"]

GYRO_SATURATION_DEG_S = 1900.0
"""A gyro sample at or above this [°/s] is saturated (95 % of Betaflight's 2000 °/s full scale)."""
CRASH_SPECIFIC_FORCE_G = 10.0
"""Specific force [g] that no flight reaches and an impact does."""
CRASH_SEARCH_S = 3.0
"""A crash is looked for in the log's last seconds only [s]: a log ends at the crash or soon after."""
CALM_SPECIFIC_FORCE_G = 4.0
"""Specific force [g] below which a sample before an impact still belongs to the flight."""
BAND_HZ = (1.0, 20.0)
"""The band a pilot reads a tracking error in [Hz]: above the trims and drifts, below frame vibration."""
RESPONSE_S = 0.5
"""The step response's length [s]."""
_G = 9.80665


@dataclass(frozen=True)
class Crash:
    """Where a log's crash starts, and what gave it away."""

    time_s: float
    reason: str


def find_crash(time_s: np.ndarray, gyro_deg_s: np.ndarray, specific_force_m_s2: np.ndarray | None = None,
               force_time_s: np.ndarray | None = None) -> Crash | None:
    """The crash at the end of a log, or None (see the module's docstring for the rule).

    ``gyro_deg_s`` is (n, 3) on ``time_s``; ``specific_force_m_s2`` (m, 3) on ``force_time_s``.
    """
    t = np.asarray(time_s, dtype=float)
    if t.size == 0:
        return None
    found: list[Crash] = []
    start = t[-1] - CRASH_SEARCH_S
    g = np.abs(np.asarray(gyro_deg_s, dtype=float)).max(axis=1)
    hit = np.flatnonzero((t >= start) & np.isfinite(g) & (g >= GYRO_SATURATION_DEG_S))  # a broken sample is no crash
    if hit.size:
        found.append(Crash(_onset(t, g, int(hit[0]), 0.25 * GYRO_SATURATION_DEG_S),
                           f"gyro at {g[hit[0]]:.0f} °/s (saturated)"))
    if specific_force_m_s2 is not None and force_time_s is not None and len(force_time_s):
        ft = np.asarray(force_time_s, dtype=float)
        a = np.linalg.norm(np.asarray(specific_force_m_s2, dtype=float), axis=1) / _G
        hit = np.flatnonzero((ft >= start) & np.isfinite(a) & (a >= CRASH_SPECIFIC_FORCE_G))
        if hit.size:
            found.append(Crash(_onset(ft, a, int(hit[0]), CALM_SPECIFIC_FORCE_G),
                               f"specific force {a[hit[0]]:.1f} g"))
    return min(found, key=lambda c: c.time_s) if found else None


def welch(x: np.ndarray, fs: float, nperseg: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """One-sided power spectral density of ``x`` by Welch's method: ``scipy.signal.welch``'s defaults (periodic
    Hann window, half overlap, each segment's mean removed, density scaling), in NumPy.

    Here so that ``aerobat log plot`` and the replay's vibration bands do not import ``scipy.signal`` (about 45 MB
    of the process's memory) for it; segment by segment, without a table of them all.
    """
    n = min(nperseg, len(x))
    if n < 2:
        return np.zeros(0), np.zeros(0)
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)
    step = n - n // 2
    total = np.zeros(n // 2 + 1)
    starts = range(0, len(x) - n + 1, step)
    for start in starts:
        segment = x[start: start + n]
        total += np.abs(np.fft.rfft((segment - segment.mean()) * window)) ** 2
    p = total / (len(starts) * fs * float(np.sum(window ** 2)))
    p[1: n // 2 + (n % 2)] *= 2.0  # one-sided: every bin but 0 and (n even) the Nyquist one counts twice
    return np.fft.rfftfreq(n, 1.0 / fs), p


def band_pass(x: np.ndarray, dt_s: float, band_hz: tuple[float, float] = BAND_HZ) -> np.ndarray:
    """``x`` (evenly spaced by ``dt_s``) with only its content in ``band_hz`` kept (FFT, mean removed)."""
    spectrum = np.fft.rfft(x - x.mean())
    f = np.fft.rfftfreq(x.size, dt_s)
    spectrum[(f < band_hz[0]) | (f > band_hz[1])] = 0.0
    return np.fft.irfft(spectrum, x.size)


def _onset(t: np.ndarray, magnitude: np.ndarray, hit: int, calm: float) -> float:
    """The time of the last sample at or before ``hit`` whose ``magnitude`` is below ``calm`` (the first sample
    if none is)."""
    calm_before = np.flatnonzero(magnitude[: hit + 1] < calm)
    return float(t[calm_before[-1]]) if calm_before.size else float(t[0])


def plot_limits(*series: np.ndarray, saturation: float | None = None, margin: float = 0.08
                ) -> tuple[float, float] | None:
    """(low, high) that hold every finite sample of ``series`` below ``saturation`` in magnitude, with a margin.

    None when nothing is left. A pilot's limits: a crash's saturated samples are not the flight.
    """
    kept = []
    for s in series:
        v = np.asarray(s, dtype=float).ravel()
        v = v[np.isfinite(v)]
        if saturation is not None:
            v = v[np.abs(v) < saturation]
        kept.append(v)
    values = np.concatenate(kept) if kept else np.zeros(0)
    if values.size == 0:
        return None
    lo, hi = float(values.min()), float(values.max())
    pad = margin * ((hi - lo) if hi > lo else max(abs(hi), 1.0))
    return lo - pad, hi + pad


@dataclass(frozen=True)
class StepResponse:
    """The rate loop's step response estimated from a log, one axis.

    Attributes
    ----------
    time_s : (k,) from the step [s].
    mean : (k,) the averaged response to a unit set-point step (1 = the set point).
    spread : (k,) the standard deviation over the segments.
    segments : segments averaged (those with enough input).
    rise_s : 10 → 90 % of the mean response [s] (nan if it never reaches 90 %).
    overshoot : peak above 1, as a fraction (0 if none).
    delay_s : time to 50 % [s] (nan if never).
    """

    time_s: np.ndarray
    mean: np.ndarray
    spread: np.ndarray
    segments: int
    rise_s: float
    overshoot: float
    delay_s: float


def _first_crossing(t: np.ndarray, y: np.ndarray, level: float) -> float:
    hit = np.flatnonzero(y >= level)
    if not hit.size:
        return math.nan
    i = int(hit[0])
    if i == 0:
        return float(t[0])
    frac = (level - y[i - 1]) / (y[i] - y[i - 1])
    return float(t[i - 1] + frac * (t[i] - t[i - 1]))


def _fir(x: np.ndarray, y: np.ndarray, taps: int) -> np.ndarray:
    """The least-squares FIR ``h`` (``taps`` long) with y[k] ≈ Σ h[i]·x[k − i].

    The Wiener–Hopf normal equations from the auto- and cross-correlations (FFT), solved directly; means
    removed. A ridge of 1e-3 of x's power keeps the taps the input barely excites from swinging (on a
    first-order lag with delay it moves the step response by less than 0.05).
    """
    x = x - x.mean()
    y = y - y.mean()
    size = 1 << int(math.ceil(math.log2(2 * x.size)))
    xf, yf = np.fft.rfft(x, size), np.fft.rfft(y, size)
    rxx = np.fft.irfft(np.abs(xf) ** 2, size)[:taps]
    rxy = np.fft.irfft(yf * np.conj(xf), size)[:taps]
    lag = np.abs(np.arange(taps)[:, None] - np.arange(taps)[None, :])
    return np.linalg.solve(rxx[lag] + 1e-3 * rxx[0] * np.eye(taps), rxy)


def estimate_step_response(time_s: np.ndarray, setpoint_deg_s: np.ndarray, gyro_deg_s: np.ndarray, *,
                           segment_s: float = 10.0, min_input_deg_s: float = 20.0) -> StepResponse | None:
    """The step response from set point to gyro of one axis: the running sum of a least-squares impulse response.

    ``time_s`` must be evenly spaced (a log's main time base). In each half-overlapping segment of ``segment_s``
    (the whole series if shorter) whose set point spans at least ``min_input_deg_s``, the impulse response over
    :data:`RESPONSE_S` is fitted by least squares (the Wiener–Hopf equations); the step responses are averaged.
    A pilot in the loop correlates the set point with the gyro's past, which no open-loop estimate separates:
    read the curve as the loop's shape, as a blackbox tool's. None when no segment qualifies.
    """
    t = np.asarray(time_s, dtype=float)
    x = np.asarray(setpoint_deg_s, dtype=float)
    y = np.asarray(gyro_deg_s, dtype=float)
    if t.size < 4:
        return None
    dt = float(np.median(np.diff(t)))
    taps = int(round(RESPONSE_S / dt))
    n = min(int(round(segment_s / dt)), t.size)
    if n < 4 * taps:
        return None
    starts = range(0, t.size - n + 1, max(n // 2, 1))
    responses = []
    for start in starts:
        xs, ys = x[start: start + n], y[start: start + n]
        if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(ys))):
            continue
        if float(xs.max() - xs.min()) < min_input_deg_s:
            continue
        responses.append(np.cumsum(_fir(xs, ys, taps)))
    if not responses:
        return None
    stack = np.array(responses)
    mean = stack.mean(axis=0)
    times = np.arange(taps) * dt
    return StepResponse(time_s=times, mean=mean, spread=stack.std(axis=0), segments=len(responses),
                        rise_s=_first_crossing(times, mean, 0.9) - _first_crossing(times, mean, 0.1),
                        overshoot=max(float(mean.max()) - 1.0, 0.0), delay_s=_first_crossing(times, mean, 0.5))


@dataclass(frozen=True)
class ThrottleSpectrogram:
    """Power spectra of a signal per throttle bin.

    Attributes
    ----------
    frequency_hz : (f,) bin frequencies.
    throttle_edges : (b + 1,) the throttle bins' edges (fraction 0..1).
    power_db : (b, f) mean power spectral density per bin [dB re 1 unit²/Hz]; nan where no segment fell in.
    counts : (b,) segments per bin.
    segment_s : one segment's length [s].
    """

    frequency_hz: np.ndarray
    throttle_edges: np.ndarray
    power_db: np.ndarray
    counts: np.ndarray
    segment_s: float


def throttle_spectrogram(time_s: np.ndarray, values: np.ndarray, throttle: np.ndarray, *,
                         segment_samples: int = 128, bins: int = 20) -> ThrottleSpectrogram | None:
    """``values`` (n,) cut into half-overlapping segments of ``segment_samples``, each one's Hann-windowed
    power spectrum filed under its mean ``throttle`` (n,), fraction 0..1, in ``bins`` equal bins.

    None when the signal is shorter than one segment.
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(values, dtype=float)
    thr = np.asarray(throttle, dtype=float)
    n = segment_samples
    if t.size < n:
        return None
    dt = float(np.median(np.diff(t)))
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)
    scale = 1.0 / ((1.0 / dt) * float(np.sum(window ** 2)))
    edges = np.linspace(0.0, 1.0, bins + 1)
    total = np.zeros((bins, n // 2 + 1))
    counts = np.zeros(bins, dtype=int)
    for start in range(0, t.size - n + 1, n // 2):
        seg = v[start: start + n]
        level = float(np.mean(thr[start: start + n]))
        if not (np.all(np.isfinite(seg)) and math.isfinite(level)):
            continue
        p = np.abs(np.fft.rfft((seg - seg.mean()) * window)) ** 2 * scale
        p[1: n // 2 + (n % 2)] *= 2.0
        b = min(max(int(np.searchsorted(edges, level, side="right")) - 1, 0), bins - 1)
        total[b] += p
        counts[b] += 1
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = total / counts[:, None]
        power_db = np.where(counts[:, None] > 0, 10.0 * np.log10(np.maximum(mean, 1e-30)), np.nan)
    return ThrottleSpectrogram(frequency_hz=np.fft.rfftfreq(n, dt), throttle_edges=edges, power_db=power_db,
                               counts=counts, segment_s=n * dt)
