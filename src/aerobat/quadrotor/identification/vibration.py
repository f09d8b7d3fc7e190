"""The rotors' speed, from the frame's vibration in a log's unfiltered gyro seen through the log's sampling (issue 42).

A rotor shakes the frame once per turn (no propeller is perfectly balanced), so the gyro before the firmware's filters
carries a line at each rotor's rotation frequency, which rises with the rotor's thrust. A blackbox log samples that
gyro far slower than the firmware reads it: the ROMA F5's logs at 250 Hz (Nyquist 125 Hz), while its rotors turn at
roughly 130–250 Hz in flight. The line is therefore folded into the log's band, to |f − n·fs| for the nearest whole n,
and it moves *down* as the throttle rises (``scripts/results_vibration.py`` shows it). The fold is a property of the
sampling, known exactly, so the rotors' speed can be identified through it:

* the thrust curve identified from the same log gives each rotor's thrust T(u) at its command u;
* a thrust coefficient k (T = k Ω²) gives its rotation frequency f = √(T / k) / 2π;
* the fold gives where that line must appear in the log.

:func:`fit_vibration` takes the k whose folded lines carry the most unfiltered-gyro power over the flight's steady
windows (256 samples each, every motor's command steady), each window's spectrum divided by its own median level so
that no loud window decides alone: a grid of ¼ to 4 times the prior's k in steps of 0.7 %. At that k it measures the
lines' rms per axis: the power within ±2 Hz of the four folded lines above the window's median level.

What such a log cannot tell: which multiple of the rotation the line is (the fit assumes once per turn, the balance
line; a line at twice the rotation would give k / 4), and anything about a line the fold puts below 30 Hz, where the
flight's own motion lies (those rotors are left out of the window's score). Only numpy here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["VibrationFit", "fit_vibration", "folded_hz"]

WINDOW = 256
"""Samples per spectrum (about 1 s at 250 Hz); windows overlap by half."""
LOW_HZ = 30.0
"""Folded lines below this are not scored: the flight's own motion lies there."""
BAND_HZ = 2.0
"""Half-width of the band about a folded line whose power is the line's."""
STEADY_COMMAND = 0.03
"""A window is steady when no motor's command moves more than this (its standard deviation)."""
_GRID = np.exp(np.linspace(math.log(0.25), math.log(4.0), 401))  # k / prior k


def folded_hz(f_hz: np.ndarray | float, rate_hz: float) -> np.ndarray:
    """Where a line at ``f_hz`` appears in a series sampled at ``rate_hz``: |f − n · rate| for the nearest whole n."""
    f = np.asarray(f_hz, dtype=float)
    return np.abs(f - rate_hz * np.round(f / rate_hz))


@dataclass(frozen=True)
class VibrationFit:
    """The rotors' speed through the log's folded vibration lines, and how strong the lines are.

    Attributes
    ----------
    thrust_coefficient_n_s2 : k in T = k Ω² [N/(rad/s)²] whose folded lines carry the most power.
    prior_thrust_coefficient_n_s2 : the prior's k, the grid's centre.
    log_rate_hz : the log's sample rate [Hz]; its Nyquist frequency is half of it.
    rotor_hz : a rotor's rotation frequency at the flights' median command, with that k [Hz].
    reference_thrust_n : a rotor's thrust at that command [N]: the lines' rms holds there (an airframe's
        ``vibration_thrust_n``).
    line_rms_rad_s : per body axis (roll, pitch, yaw), the rms of the gyro within the folded lines' bands above the
        window's median level, the median over the windows [rad/s].
    windows : steady windows scored.
    matched_share : the windows whose strongest bin above :data:`LOW_HZ` lies within 3 Hz of a folded line at k.
    matched_share_prior : the same at the prior's k.
    contrast : the score at k over the median score across the grid (1: no line found).
    runner_up : the best score outside ±10 % of k, over the score at k (near 1: two speeds explain the log alike).
    """

    thrust_coefficient_n_s2: float
    prior_thrust_coefficient_n_s2: float
    log_rate_hz: float
    rotor_hz: float
    reference_thrust_n: float
    line_rms_rad_s: tuple[float, float, float]
    windows: int
    matched_share: float
    matched_share_prior: float
    contrast: float
    runner_up: float

    def describe(self) -> str:
        """One line a person reads."""
        rms = ", ".join(f"{math.degrees(v):.2f}" for v in self.line_rms_rad_s)
        return (f"vibration: rotors at {self.rotor_hz:.0f} Hz at the median command, seen folded below the log's "
                f"{self.log_rate_hz / 2:.0f} Hz Nyquist; thrust coefficient {self.thrust_coefficient_n_s2:.3g} "
                f"N/(rad/s)² ({self.thrust_coefficient_n_s2 / self.prior_thrust_coefficient_n_s2:.2f}× the prior's); "
                f"the strongest line of {self.matched_share:.0%} of {self.windows} steady windows lies on a folded "
                f"rotor line ({self.matched_share_prior:.0%} at the prior's k); lines' rms {rms} °/s (roll, pitch, "
                f"yaw)")

    def airframe_fields(self) -> dict[str, object]:
        """The Betaflight airframe's fields that fly this vibration (:class:`~aerobat.quadrotor.xframe.Airframe`)."""
        return {"thrust_coefficient_n_s2": self.thrust_coefficient_n_s2,
                "vibration_rms_rad_s": list(self.line_rms_rad_s), "vibration_thrust_n": self.reference_thrust_n}


def _steady_windows(commands: np.ndarray, flying_command: float) -> list[int]:
    starts = []
    for s in range(0, commands.shape[0] - WINDOW + 1, WINDOW // 2):
        u = commands[s:s + WINDOW]
        if u.mean() > flying_command and float(u.std(axis=0).max()) < STEADY_COMMAND:
            starts.append(s)
    return starts


def fit_vibration(series: list[tuple[np.ndarray, np.ndarray, np.ndarray]], thrust_n: Callable[[np.ndarray], np.ndarray],
                  prior_thrust_coefficient_n_s2: float, *, flying_command: float = 0.1) -> VibrationFit | None:
    """The thrust coefficient whose folded rotor lines the logs' unfiltered gyro carries (module docstring).

    ``series``: per log, (time [s], unfiltered gyro (n, 3) [rad/s], motor commands (n, 4) in [0, 1]) on the same
    samples. ``thrust_n``: a rotor's thrust [N] at commands (the identified thrust curve). None when no log has a
    steady window.
    """
    spectra, freqs_list, lines_u, rates = [], [], [], []
    for t, gyro, commands in series:
        if len(t) < WINDOW:
            continue
        rate = 1.0 / float(np.median(np.diff(t)))
        taper = np.hanning(WINDOW)
        norm = rate * float(np.sum(taper ** 2))
        freqs = np.fft.rfftfreq(WINDOW, 1.0 / rate)
        for s in _steady_windows(commands, flying_command):
            g = gyro[s:s + WINDOW]
            spectrum = np.abs(np.fft.rfft((g - g.mean(axis=0)) * taper[:, None], axis=0)) ** 2 * (2.0 / norm)
            spectra.append(spectrum.T)  # (3, bins): one-sided power density [(rad/s)²/Hz]
            freqs_list.append(freqs)
            lines_u.append(commands[s:s + WINDOW].mean(axis=0))
            rates.append(rate)
    if not spectra:
        return None
    rate = float(np.median(rates))
    freqs = freqs_list[int(np.argmin([abs(r - rate) for r in rates]))]
    same = [i for i, r in enumerate(rates) if abs(r - rate) < 1e-6 * rate]  # windows of logs at the common rate
    power = np.array([spectra[i] for i in same])  # (w, 3, bins)
    commands = np.array([lines_u[i] for i in same])  # (w, 4)
    total = power.sum(axis=1)  # (w, bins)
    scored = freqs >= LOW_HZ
    level = np.median(total[:, scored], axis=1)  # (w,)
    relative = total / level[:, None]
    thrust = np.maximum(thrust_n(commands), 0.0)  # (w, 4)
    df = freqs[1] - freqs[0]

    def lines_hz(k: float) -> np.ndarray:
        return folded_hz(np.sqrt(thrust / k) / (2.0 * math.pi), rate)  # (w, 4)

    def score(k: float) -> float:
        at = lines_hz(k)
        bins = np.clip(np.round(at / df).astype(int), 0, len(freqs) - 1)
        values = np.take_along_axis(relative, bins, axis=1)
        values = np.where(at >= LOW_HZ, values, np.nan)
        return float(np.nanmean(values)) if np.isfinite(values).any() else 0.0

    grid = prior_thrust_coefficient_n_s2 * _GRID
    scores = np.array([score(k) for k in grid])
    best = int(np.argmax(scores))
    k = float(grid[best])
    far = np.abs(np.log(grid / k)) > math.log(1.1)
    runner_up = float(scores[far].max() / scores[best]) if far.any() and scores[best] > 0 else 1.0

    def matched(k_try: float) -> float:
        peak = freqs[scored][np.argmax(total[:, scored], axis=1)]  # (w,)
        return float(np.mean(np.min(np.abs(lines_hz(k_try) - peak[:, None]), axis=1) <= 3.0))

    at = lines_hz(k)
    in_band = np.abs(freqs[None, None, :] - at[:, :, None]) <= BAND_HZ  # (w, 4, bins)
    band = in_band.any(axis=1) & (freqs[None, :] >= LOW_HZ)  # (w, bins)
    rms = []
    for axis in range(3):
        p = power[:, axis, :]
        floor = np.median(p[:, scored], axis=1)
        excess = np.where(band, np.maximum(p - floor[:, None], 0.0), 0.0).sum(axis=1) * df
        rms.append(float(np.median(np.sqrt(excess))))
    median_thrust = float(np.median(thrust))
    return VibrationFit(
        thrust_coefficient_n_s2=k, prior_thrust_coefficient_n_s2=float(prior_thrust_coefficient_n_s2),
        log_rate_hz=rate, rotor_hz=math.sqrt(median_thrust / k) / (2.0 * math.pi), reference_thrust_n=median_thrust,
        line_rms_rad_s=(rms[0], rms[1], rms[2]), windows=len(same), matched_share=matched(k),
        matched_share_prior=matched(float(prior_thrust_coefficient_n_s2)),
        contrast=float(scores[best] / np.median(scores)) if np.median(scores) > 0 else math.inf,
        runner_up=runner_up)
