"""Figures of a flight log, as a pilot reads a blackbox viewer, and of a log identification."""

from __future__ import annotations

from typing import Any

import numpy as np

from aerobat.plotting.files import new_figure
from aerobat.quadrotor.flightlog import Channel, FlightLog
from aerobat.quadrotor.log_analysis import (
    GYRO_SATURATION_DEG_S,
    RESPONSE_S,
    Crash,
    StepResponse,
    estimate_step_response,
    find_crash,
    plot_limits,
    throttle_spectrogram,
    welch,
)

__all__ = ["draw_step", "log_crash", "plot_log_fit", "plot_log_pid", "plot_log_spectra", "plot_log_spectrogram",
           "plot_log_step_response", "plot_log_traces", "step_words", "welch"]

_AXES = ("roll", "pitch", "yaw")


def _cut(log: FlightLog, window_s: tuple[float, float] | None) -> FlightLog:
    return log.window(*window_s) if window_s else log


def log_crash(log: FlightLog) -> Crash | None:
    """The crash at the end of ``log`` (:func:`aerobat.quadrotor.log_analysis.find_crash`), or None."""
    if not log.has(Channel.GYRO):
        return None
    g = log.signals[Channel.GYRO]
    acc = log.signals.get(Channel.SPECIFIC_FORCE) if log.has(Channel.SPECIFIC_FORCE) else None
    return find_crash(g.time_s, np.degrees(g.values), None if acc is None else acc.values,
                      None if acc is None else acc.time_s)


def _before(time_s: np.ndarray, values: np.ndarray, crash: Crash | None) -> np.ndarray:
    return values if crash is None else values[time_s < crash.time_s]


def _mark_crash(axes: Any, crash: Crash | None, end_s: float, *, label_axis: Any = None) -> None:
    if crash is None:
        return
    for ax in axes:
        ax.axvspan(crash.time_s, end_s, color="tab:red", alpha=0.12, lw=0)
    if label_axis is not None:
        label_axis.annotate(f"crash from {crash.time_s:.2f} s: {crash.reason}", xy=(crash.time_s, 1.0),
                            xycoords=("data", "axes fraction"), xytext=(-4, -12), textcoords="offset points",
                            ha="right", fontsize=8, color="tab:red")


def plot_log_traces(log: FlightLog, *, window_s: tuple[float, float] | None = None) -> Any:
    """Gyro with the set point drawn over it per axis, motors and throttle, over the log (or ``window_s``).

    A crash at the log's end (:func:`log_crash`) is shaded and named, and the rate axes' limits hold the
    flight before it without its saturated samples, so the crash does not flatten the flight.
    """
    crash = log_crash(log)
    log = _cut(log, window_s)
    fig = new_figure(figsize=(11, 9))
    axes = fig.subplots(5, 1, sharex=True)
    end = max((s.time_s[-1] for s in log.signals.values() if s.samples), default=0.0)

    def series(ch: Channel) -> tuple[np.ndarray, np.ndarray] | None:
        return (log.signals[ch].time_s, log.signals[ch].values) if log.has(ch) else None

    gyro, sp = series(Channel.GYRO), series(Channel.RATE_SETPOINT)
    for k, name in enumerate(_AXES):
        ax = axes[k]
        shown = []
        if gyro is not None:
            ax.plot(gyro[0], np.degrees(gyro[1][:, k]), lw=0.6, color="tab:blue", label="gyro", zorder=2)
            shown.append(_before(gyro[0], np.degrees(gyro[1][:, k]), crash))
        if sp is not None:  # drawn over the gyro: the set point is what the pilot asked for
            ax.plot(sp[0], np.degrees(sp[1][:, k]), lw=0.9, color="k", alpha=0.85, label="set point", zorder=3)
            shown.append(_before(sp[0], np.degrees(sp[1][:, k]), crash))
        limits = plot_limits(*shown, saturation=GYRO_SATURATION_DEG_S)
        if limits is not None:
            ax.set_ylim(*limits)
        ax.set_ylabel(f"{name} [°/s]")
        ax.legend(loc="upper left", fontsize=8)
        ax.grid(alpha=0.3)
    motors = series(Channel.MOTOR_COMMAND)
    if motors is not None:
        names = log.signals[Channel.MOTOR_COMMAND].columns
        for j in range(motors[1].shape[1]):
            axes[3].plot(motors[0], motors[1][:, j], lw=0.6, label=names[j])
        axes[3].legend(loc="upper left", fontsize=8, ncol=4)
    axes[3].set_ylabel("motors [fraction]")
    axes[3].grid(alpha=0.3)
    throttle = series(Channel.THROTTLE)
    if throttle is not None:
        axes[4].plot(throttle[0], throttle[1][:, 0], lw=0.8, color="k", label="throttle")
    acc = series(Channel.SPECIFIC_FORCE)
    if acc is not None:
        twin = axes[4].twinx()
        twin.plot(acc[0], acc[1][:, 2] / 9.81, lw=0.5, color="tab:green", alpha=0.7)
        twin.set_ylabel("specific force z [g]", color="tab:green")
        limits = plot_limits(_before(acc[0], acc[1][:, 2] / 9.81, crash))
        if limits is not None:
            twin.set_ylim(*limits)
    axes[4].set_ylabel("throttle [fraction]")
    axes[4].set_xlabel("time [s]")
    axes[4].grid(alpha=0.3)
    _mark_crash(axes, crash if crash is not None and crash.time_s <= end else None, end, label_axis=axes[0])
    meta = log.metadata
    fig.suptitle(f"{log.name}: {meta.firmware} {meta.firmware_version} {meta.board} {meta.craft_name}".strip())
    return fig


def plot_log_pid(log: FlightLog, *, window_s: tuple[float, float] | None = None) -> Any | None:
    """The rate loop's P, I, D and feedforward terms per axis (firmware units); None if the log has none."""
    terms = [(c, n) for c, n in ((Channel.PID_P, "P"), (Channel.PID_I, "I"), (Channel.PID_D, "D"),
                                 (Channel.PID_F, "F")) if log.has(c)]
    if not terms:
        return None
    crash = log_crash(log)
    log = _cut(log, window_s)
    fig = new_figure(figsize=(11, 8))
    axes = fig.subplots(3, 1, sharex=True)
    end = max((s.time_s[-1] for s in log.signals.values() if s.samples), default=0.0)
    colors = {"P": "tab:blue", "I": "tab:green", "D": "tab:red", "F": "tab:purple"}
    for k, name in enumerate(_AXES):
        ax = axes[k]
        shown = []
        for channel, term in terms:
            s = log.signals[channel]
            if not s.samples or s.values.shape[1] <= k:  # Betaflight 4.2 logs no yaw feedforward
                continue
            ax.plot(s.time_s, s.values[:, k], lw=0.6, color=colors[term], label=term)
            shown.append(_before(s.time_s, s.values[:, k], crash))
        limits = plot_limits(*shown)
        if limits is not None:
            ax.set_ylim(*limits)
        ax.set_ylabel(f"{name} [firmware units]")
        ax.legend(loc="upper left", fontsize=8, ncol=4)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    _mark_crash(axes, crash if crash is not None and crash.time_s <= end else None, end, label_axis=axes[0])
    fig.suptitle(f"{log.name}: rate loop terms (P, I, D, feedforward)")
    return fig


def _psd(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    dt = float(np.median(np.diff(t)))
    x = x[np.isfinite(x)]
    return welch(x - x.mean(), 1.0 / dt, 1024)


def _flight(log: FlightLog, window_s: tuple[float, float] | None) -> tuple[FlightLog, Crash | None]:
    """``log`` cut to ``window_s`` and ended where a crash at its end starts; and the crash."""
    crash = log_crash(log)
    log = _cut(log, window_s)
    return (log.window(-np.inf, crash.time_s) if crash is not None else log), crash


def _enough(log: FlightLog, *channels: Channel) -> bool:
    """Every one of ``channels`` has samples enough for a spectrum or a fit (at least 4)."""
    return all(log.has(c) and log.signals[c].samples >= 4 for c in channels)


def _span(log: FlightLog, crash: Crash | None) -> tuple[float, float]:
    """The log's time span [s], ending where a crash starts."""
    starts = [s.time_s[0] for s in log.signals.values() if s.samples]
    ends = [s.time_s[-1] for s in log.signals.values() if s.samples]
    lo, hi = (min(starts), max(ends)) if starts else (0.0, 0.0)
    return lo, (min(hi, crash.time_s) if crash is not None else hi)


def _covers(log: FlightLog, crash: Crash | None, rate_hz: float, samples: int, segment: int) -> str:
    lo, hi = _span(log, crash)
    segments = max((samples - segment) // (segment - segment // 2) + 1, 0) if samples >= segment else 0
    before = " (before the crash)" if crash is not None and crash.time_s <= hi + 1e-9 else ""
    return (f"{lo:.1f}–{hi:.1f} s{before}: {segments} half-overlapping segments of {segment} samples "
            f"({segment / rate_hz:.2f} s)")


def plot_log_spectra(log: FlightLog, *, window_s: tuple[float, float] | None = None) -> Any:
    """Power spectra of the gyro per axis and of the motor commands (noise, vibration, filter corners).

    Over the log (or ``window_s``), up to a crash at its end; the title says which window they cover.
    """
    log, crash = _flight(log, window_s)
    fig = new_figure(figsize=(11, 6))
    ax_gyro, ax_motor = fig.subplots(1, 2)
    covers = ""
    if _enough(log, Channel.GYRO):
        g = log.signals[Channel.GYRO]
        for k, name in enumerate(_AXES):
            f, p = _psd(g.time_s, np.degrees(g.values[:, k]))
            ax_gyro.semilogy(f[p > 0], p[p > 0], lw=0.8, label=name)
        ax_gyro.set_title(f"gyro (logged at {g.rate_hz:.0f} Hz)")
        ax_gyro.set_ylabel("PSD [(°/s)²/Hz]")
        ax_gyro.legend()
        covers = _covers(log, crash, g.rate_hz, g.samples, min(1024, g.samples))
    if _enough(log, Channel.MOTOR_COMMAND):
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
    fig.suptitle(f"{log.name}: spectra over {covers}" if covers else f"{log.name}: spectra")
    return fig


def plot_log_spectrogram(log: FlightLog, *, window_s: tuple[float, float] | None = None) -> Any | None:
    """The gyro's spectrum against throttle per axis (as Blackbox Explorer and PIDtoolbox draw it).

    Motor-harmonic noise is a line that climbs with throttle; a frame resonance stays put. A line above the
    log's Nyquist frequency appears folded, so it falls as it climbs (docs/logs.md: the ROMA F5's rotors at
    140–270 Hz in a 250 Hz log). The gyro before the firmware's filters where the log has it
    (:attr:`~aerobat.quadrotor.flightlog.Channel.GYRO_UNFILTERED`), else the logged one. None if the log has no
    gyro or no throttle.
    """
    log, crash = _flight(log, window_s)
    if not _enough(log, Channel.GYRO, Channel.THROTTLE):
        return None
    unfiltered = log.has(Channel.GYRO_UNFILTERED)
    g = log.signals[Channel.GYRO_UNFILTERED if unfiltered else Channel.GYRO]
    which = "unfiltered gyro" if unfiltered else "gyro"
    throttle = log.signals[Channel.THROTTLE].at(g.time_s)[:, 0]
    maps = [throttle_spectrogram(g.time_s, np.degrees(g.values[:, k]), throttle) for k in range(3)]
    if any(m is None for m in maps):
        return None
    fig = new_figure(figsize=(12, 4.5))
    axes = fig.subplots(1, 3, sharey=True)
    finite = np.concatenate([m.power_db[np.isfinite(m.power_db)] for m in maps if m is not None])
    vmin, vmax = (np.percentile(finite, 2), np.percentile(finite, 99.5)) if finite.size else (None, None)
    image = None
    for ax, name, m in zip(axes, _AXES, maps, strict=True):
        assert m is not None
        centres = 50.0 * (m.throttle_edges[:-1] + m.throttle_edges[1:])
        image = ax.pcolormesh(m.frequency_hz, centres, m.power_db, shading="nearest", cmap="inferno",
                              vmin=vmin, vmax=vmax)
        ax.set_title(f"{which} {name}", fontsize=10)
        ax.set_xlabel("frequency [Hz]")
    axes[0].set_ylabel("throttle [%]")
    if image is not None:
        fig.colorbar(image, ax=list(axes), label="PSD [dB re (°/s)²/Hz]")
    m0 = maps[0]
    assert m0 is not None
    covers = _covers(log, crash, g.rate_hz, g.samples, int(round(m0.segment_s * g.rate_hz)))
    fig.suptitle(f"{log.name}: {which} spectrum against throttle over {covers}\n"
                 f"bins without a segment blank; sampled at {g.rate_hz:.0f} Hz, a line above {g.rate_hz / 2:.0f} Hz "
                 f"appears folded (it falls as it climbs)", fontsize=10)
    return fig


def plot_log_step_response(log: FlightLog, *, window_s: tuple[float, float] | None = None) -> Any | None:
    """The rate loop's step response per axis, estimated from set point and gyro
    (:func:`aerobat.quadrotor.log_analysis.estimate_step_response`); None if the log has no set point or gyro."""
    log, crash = _flight(log, window_s)
    if not _enough(log, Channel.GYRO, Channel.RATE_SETPOINT):
        return None
    g = log.signals[Channel.GYRO]
    sp = log.signals[Channel.RATE_SETPOINT].at(g.time_s)
    fig = new_figure(figsize=(12, 4.2))
    axes = fig.subplots(1, 3, sharey=True)
    for k, (ax, name) in enumerate(zip(axes, _AXES, strict=True)):
        r = estimate_step_response(g.time_s, np.degrees(sp[:, k]), np.degrees(g.values[:, k]))
        draw_step(ax, r, "log", "tab:blue")
        ax.set_title(f"{name}: {step_words(r)}", fontsize=9)
        ax.set_xlabel("time after the step [ms]")
        ax.axhline(1.0, color="k", lw=0.6, ls=":")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("gyro ÷ set-point step")
    lo, hi = _span(log, crash)
    fig.suptitle(f"{log.name}: step response from set point to gyro, {lo:.1f}–{hi:.1f} s (least-squares "
                 f"impulse response over {RESPONSE_S * 1000:.0f} ms, averaged over segments; band: ±1 std)",
                 fontsize=10)
    return fig


def draw_step(ax: Any, r: StepResponse | None, label: str, color: str) -> None:
    """Draw a step response with its ±1 std band on ``ax`` (nothing if ``r`` is None)."""
    if r is None:
        return
    ms = 1000.0 * r.time_s
    ax.plot(ms, r.mean, color=color, lw=1.2, label=f"{label} ({r.segments} segments)")
    ax.fill_between(ms, r.mean - r.spread, r.mean + r.spread, color=color, alpha=0.15, lw=0)
    ax.legend(loc="lower right", fontsize=8)


def step_words(r: StepResponse | None) -> str:
    """A step response in words: 50 % time, rise time, overshoot."""
    if r is None:
        return "too little set-point movement to estimate"
    rise = f"{1000 * r.rise_s:.0f} ms" if np.isfinite(r.rise_s) else "never 90 %"
    delay = f"{1000 * r.delay_s:.0f} ms" if np.isfinite(r.delay_s) else "never"
    return f"50 % at {delay}, rise {rise}, overshoot {100 * r.overshoot:.0f} %"


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
