"""Figures of a flight log, as a pilot reads a blackbox viewer, and of a log identification."""

from __future__ import annotations

from typing import Any

import numpy as np

from aerobat.plotting.files import new_figure
from aerobat.quadrotor.flightlog import Channel, FlightLog

__all__ = ["plot_log_fit", "plot_log_spectra", "plot_log_traces", "welch"]

_AXES = ("roll", "pitch", "yaw")


def plot_log_traces(log: FlightLog, *, window_s: tuple[float, float] | None = None) -> Any:
    """Set point against gyro per axis, motors and throttle, over the log (or ``window_s``)."""
    fig = new_figure(figsize=(11, 9))
    axes = fig.subplots(5, 1, sharex=True)
    lo, hi = window_s if window_s else (-np.inf, np.inf)

    def cut(ch: Channel) -> tuple[np.ndarray, np.ndarray] | None:
        if not log.has(ch):
            return None
        s = log.signals[ch]
        keep = (s.time_s >= lo) & (s.time_s <= hi)
        return s.time_s[keep], s.values[keep]

    gyro, sp = cut(Channel.GYRO), cut(Channel.RATE_SETPOINT)
    for k, name in enumerate(_AXES):
        ax = axes[k]
        if sp is not None:
            ax.plot(sp[0], np.degrees(sp[1][:, k]), lw=0.8, color="tab:orange", label="set point")
        if gyro is not None:
            ax.plot(gyro[0], np.degrees(gyro[1][:, k]), lw=0.6, color="tab:blue", label="gyro")
        ax.set_ylabel(f"{name} [°/s]")
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    motors = cut(Channel.MOTOR_COMMAND)
    if motors is not None:
        names = log.signals[Channel.MOTOR_COMMAND].columns
        for j in range(motors[1].shape[1]):
            axes[3].plot(motors[0], motors[1][:, j], lw=0.6, label=names[j])
        axes[3].legend(loc="upper right", fontsize=8, ncol=4)
    axes[3].set_ylabel("motors [fraction]")
    axes[3].grid(alpha=0.3)
    throttle = cut(Channel.THROTTLE)
    if throttle is not None:
        axes[4].plot(throttle[0], throttle[1][:, 0], lw=0.8, color="k", label="throttle")
    acc = cut(Channel.SPECIFIC_FORCE)
    if acc is not None:
        twin = axes[4].twinx()
        twin.plot(acc[0], acc[1][:, 2] / 9.81, lw=0.5, color="tab:green", alpha=0.7)
        twin.set_ylabel("specific force z [g]", color="tab:green")
    axes[4].set_ylabel("throttle [fraction]")
    axes[4].set_xlabel("time [s]")
    axes[4].grid(alpha=0.3)
    meta = log.metadata
    fig.suptitle(f"{log.name}: {meta.firmware} {meta.firmware_version} {meta.board} {meta.craft_name}".strip())
    return fig


def welch(x: np.ndarray, fs: float, nperseg: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """One-sided power spectral density of ``x`` by Welch's method: ``scipy.signal.welch``'s defaults (periodic
    Hann window, half overlap, each segment's mean removed, density scaling), in NumPy.

    Here so that ``aerobat log plot`` does not import ``scipy.signal`` (about 45 MB of the process's memory)
    for it; segment by segment, without a table of them all.
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


def _psd(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    dt = float(np.median(np.diff(t)))
    x = x[np.isfinite(x)]
    return welch(x - x.mean(), 1.0 / dt, 1024)


def plot_log_spectra(log: FlightLog) -> Any:
    """Power spectra of the gyro per axis and of the motor commands (noise, vibration, filter corners)."""
    fig = new_figure(figsize=(11, 6))
    ax_gyro, ax_motor = fig.subplots(1, 2)
    if log.has(Channel.GYRO):
        g = log.signals[Channel.GYRO]
        for k, name in enumerate(_AXES):
            f, p = _psd(g.time_s, np.degrees(g.values[:, k]))
            ax_gyro.semilogy(f[p > 0], p[p > 0], lw=0.8, label=name)
        ax_gyro.set_title(f"gyro (logged at {g.rate_hz:.0f} Hz)")
        ax_gyro.set_ylabel("PSD [(°/s)²/Hz]")
        ax_gyro.legend()
    if log.has(Channel.MOTOR_COMMAND):
        m = log.signals[Channel.MOTOR_COMMAND]
        for j, name in enumerate(m.columns):
            f, p = _psd(m.time_s, m.values[:, j])
            ax_motor.semilogy(f[p > 0], p[p > 0], lw=0.8, label=name)
        ax_motor.set_title(f"motor commands (logged at {m.rate_hz:.0f} Hz)")
        ax_motor.set_ylabel("PSD [1/Hz]")
        ax_motor.legend()
    for ax in (ax_gyro, ax_motor):
        ax.set_xlabel("frequency [Hz]")
        ax.grid(alpha=0.3, which="both")
    fig.suptitle(f"{log.name}: spectra")
    return fig


def plot_log_fit(fit: Any, log: Any, *, seconds: float = 6.0) -> Any:
    """Measured against predicted on the held-out blocks of ``log`` (a PreparedLog of the fit)."""
    from aerobat.quadrotor.identification.logfit import CHANNELS, predict, targets

    measured = targets(log)
    predicted = predict(log, fit.model, fit.layout, fit.geometry)
    rows = np.flatnonzero(log.holdout)
    fig = new_figure(figsize=(11, 9))
    axes = fig.subplots(4, 1, sharex=True)
    if len(rows):
        keep = rows[: int(seconds / log.dt_s)]
        t = log.time_s[keep]
        # draw held-out blocks back to back so gaps between them do not stretch the axis
        x = np.arange(len(keep)) * log.dt_s
        for c, ax in enumerate(axes):
            ax.plot(x, measured[keep, c], lw=0.8, label="measured")
            ax.plot(x, predicted[keep, c], lw=0.8, label="predicted")
            m = fit.holdout_metrics[c]
            ax.set_ylabel(f"{CHANNELS[c]}\n[{m.unit}]", fontsize=8)
            ax.set_title(f"held out: R² {m.r2:.2f}, correlation {m.correlation:.2f}, RMS error {m.rms_error:.3g}",
                         fontsize=9, loc="left")
            ax.grid(alpha=0.3)
        axes[0].legend(loc="upper right")
        axes[-1].set_xlabel(f"held-out time [s] (blocks from t = {t[0]:.1f} s on, back to back)")
    fig.suptitle(f"{fit.name}: identified model against the log")
    return fig
