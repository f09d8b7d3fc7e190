"""The figure of a replayed flight: real and simulated traces overlaid, as a blackbox viewer shows them."""

from __future__ import annotations

from typing import Any

import numpy as np

from aerobat.plotting.files import new_figure

__all__ = ["plot_replay", "plot_replay_spectra", "plot_replay_steps", "plot_what_if"]

_AXES = ("roll", "pitch", "yaw")


def plot_replay(result: Any) -> Any:
    """Per axis the logged set point, the tune's set point, the logged and the simulated gyro; then the motors.

    ``result`` is an :class:`aerobat.experiments.log_replay.LogReplay`.
    """
    fig = new_figure(figsize=(11, 12))
    axes = fig.subplots(6, 1, sharex=True)
    t = result.time_s
    for k, name in enumerate(_AXES):
        ax = axes[k]
        ax.plot(t, result.setpoint_log[:, k], lw=0.9, color="tab:orange", label="set point (log)")
        if np.all(np.isfinite(result.setpoint_sim[:, k])):
            ax.plot(t, result.setpoint_sim[:, k], lw=0.7, ls="--", color="k", label="set point (SITL)")
        else:
            ax.plot(t, result.setpoint_model[:, k], lw=0.7, ls="--", color="k", label="set point (tune's curve)")
        ax.plot(t, result.gyro_log[:, k], lw=0.7, color="tab:blue", label="gyro (log)")
        ax.plot(t, result.gyro_sim[:, k], lw=0.7, color="tab:red", label="gyro (SITL)")
        g = result.gyro[k]
        ax.set_title(f"{name}: gyro rms difference {g.rms:.1f} °/s, correlation {g.correlation:.3f}", fontsize=9,
                     loc="left")
        ax.set_ylabel(f"{name} [°/s]")
        ax.legend(loc="upper right", fontsize=7, ncol=4)
        ax.grid(alpha=0.3)
    for j in range(4):
        line = axes[3].plot(t, result.motors_log[:, j], lw=0.6, label=f"M{j + 1} log")[0]
        axes[3].plot(t, result.motors_sim[:, j], lw=0.6, ls="--", color=line.get_color(), label=f"M{j + 1} SITL")
    axes[3].set_ylabel("motors [fraction]")
    axes[3].legend(loc="upper right", fontsize=7, ncol=4)
    axes[3].grid(alpha=0.3)
    for k, name in enumerate(_AXES):
        axes[4].plot(t, result.setpoint_log[:, k] - result.gyro_log[:, k], lw=0.6, label=f"{name} log")
        axes[4].plot(t, result.setpoint_model[:, k] - result.gyro_sim[:, k], lw=0.6, ls="--", label=f"{name} SITL")
    axes[4].set_ylabel("tracking error [°/s]")
    for k, name in enumerate(_AXES):
        axes[5].plot(t, result.pid_log[:, 0, k], lw=0.6, label=f"P {name} log")
        axes[5].plot(t, result.pid_sim[:, 0, k], lw=0.6, ls="--", label=f"P {name} SITL")
    axes[5].set_ylabel("P term [firmware]")
    axes[5].legend(loc="upper right", fontsize=7, ncol=3)
    axes[5].grid(alpha=0.3)
    axes[5].set_xlabel("log time [s]")
    axes[4].legend(loc="upper right", fontsize=7, ncol=3)
    axes[4].grid(alpha=0.3)
    lo, hi = result.window_s
    fig.suptitle(f"{result.log} {lo:g}–{hi:g} s through Betaflight 4.6 SITL with the log's tune; airframe: "
                 f"{result.airframe}", fontsize=10)
    return fig


def plot_replay_steps(result: Any) -> Any:
    """Per axis the step response from set point to gyro, estimated the same way from the log and from the SITL
    (:func:`aerobat.quadrotor.log_analysis.estimate_step_response`), with the medians of the steps found.

    ``result`` is an :class:`aerobat.experiments.log_replay.LogReplay`.
    """
    from aerobat.plotting.flightlog import draw_step, step_words
    from aerobat.quadrotor.log_analysis import estimate_step_response

    fig = new_figure(figsize=(12, 4.4))
    axes = fig.subplots(1, 3, sharey=True)
    t = result.time_s
    found = result.step_summary()
    for k, (ax, name) in enumerate(zip(axes, _AXES, strict=True)):
        logged = estimate_step_response(t, result.setpoint_log[:, k], result.gyro_log[:, k])
        sim_sp = result.setpoint_sim[:, k] if np.all(np.isfinite(result.setpoint_sim[:, k])) \
            else result.setpoint_model[:, k]
        simulated = estimate_step_response(t, sim_sp, result.gyro_sim[:, k])
        draw_step(ax, logged, "log", "tab:blue")
        draw_step(ax, simulated, "SITL", "tab:red")
        steps = found.get(name, {})
        title = f"{name}\nlog: {step_words(logged)}\nSITL: {step_words(simulated)}"
        if steps.get("steps"):
            count = int(steps["steps"])
            title += (f"\n{count} step{'s' if count != 1 else ''} found: rise {1e3 * steps['rise_log_s']:.0f} / "
                      f"{1e3 * steps['rise_sim_s']:.0f} ms, overshoot {100 * steps['overshoot_log']:.0f} / "
                      f"{100 * steps['overshoot_sim']:.0f} % (log / SITL)")
        ax.set_title(title, fontsize=8, loc="left")
        ax.axhline(1.0, color="k", lw=0.6, ls=":")
        ax.set_xlabel("time after the step [ms]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("gyro ÷ set-point step")
    lo, hi = result.window_s
    fig.suptitle(f"{result.log} {lo:g}–{hi:g} s: step responses, logged and through the SITL", fontsize=10)
    return fig


def plot_replay_spectra(result: Any) -> Any:
    """Per axis the power spectra over the replayed window (Welch, 256-sample segments): the logged gyro (after the
    firmware's filters) against the SITL's true rates; and, where the log records it, the gyro before the filters
    against the gyro the SITL's firmware read (its sensor errors and the airframe's vibration lines, sampled at the
    log's instants): what the firmware's filters meet in the air and in the SITL.

    ``result`` is an :class:`aerobat.experiments.log_replay.LogReplay`.
    """
    from aerobat.quadrotor.identification.vibration import LOW_HZ
    from aerobat.quadrotor.log_analysis import welch

    before = result.gyro_unfiltered_log is not None and result.gyro_sensor_sim is not None
    rows: list[tuple[tuple[np.ndarray, str], tuple[np.ndarray, str]]] = [
        ((result.gyro_log, "log (after the filters)"), (result.gyro_sim, "SITL (true rates)"))]
    if before:
        rows.append(((result.gyro_unfiltered_log, "log (before the filters)"),
                     (result.gyro_sensor_sim, "SITL (the gyro its firmware read)")))
    fig = new_figure(figsize=(12, 4.2 * len(rows)))
    grid = np.atleast_2d(fig.subplots(len(rows), 3, sharey="row"))
    t = result.time_s
    fs = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 1.0
    segment = int(min(256, t.size))
    for r, pair in enumerate(rows):
        for k, (ax, name) in enumerate(zip(grid[r], _AXES, strict=True)):
            for (series, label), color in zip(pair, ("tab:blue", "tab:red"), strict=True):
                x = series[:, k]
                f, p = welch(x - x.mean(), fs, segment)
                keep = p > 0
                ax.semilogy(f[keep], p[keep], lw=0.8, color=color, label=label)
            title = name
            if r == 1 and result.vibration:
                m = result.vibration[k]
                title += (f", before the filters; log / SITL above {LOW_HZ:g} Hz:\nrms {m.rms_log_deg_s:.1f} / "
                          f"{m.rms_sim_deg_s:.1f} °/s, strongest line {m.peak_log_hz:.0f} / {m.peak_sim_hz:.0f} Hz")
            ax.set_title(title, fontsize=8 if r else 10, loc="left" if r else "center")
            ax.set_xlabel("frequency [Hz]")
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize=7)
        grid[r][0].set_ylabel("gyro PSD [(°/s)²/Hz]")
    lo, hi = result.window_s
    fig.suptitle(f"{result.log} {lo:g}–{hi:g} s: gyro spectra, logged and through the SITL "
                 f"(Welch, {segment}-sample segments at {fs:.0f} Hz; above {fs / 2:.0f} Hz a line appears folded)",
                 fontsize=10)
    return fig


def plot_what_if(result: Any) -> Any:
    """The log, its twin (the log's own tune) and the what-if tune over the same sticks: step responses per
    axis, then the tracking error, the motors' noise and their saturation side by side.

    ``result`` is an :class:`aerobat.experiments.log_whatif.WhatIf`.
    """
    from aerobat.plotting.flightlog import draw_step, step_words
    from aerobat.quadrotor.log_analysis import estimate_step_response

    fig = new_figure(figsize=(13, 8))
    grid = fig.subplots(2, 3)
    flown, other = result.flown, result.what_if

    def setpoint(r: Any) -> np.ndarray:
        return r.setpoint_sim if np.all(np.isfinite(r.setpoint_sim)) else r.setpoint_model

    colors = ("tab:blue", "tab:gray", "tab:red")
    for k, (ax, name) in enumerate(zip(grid[0], _AXES, strict=True)):
        curves = (estimate_step_response(flown.time_s, flown.setpoint_log[:, k], flown.gyro_log[:, k]),
                  estimate_step_response(flown.time_s, setpoint(flown)[:, k], flown.gyro_sim[:, k]),
                  estimate_step_response(other.time_s, setpoint(other)[:, k], other.gyro_sim[:, k]))
        for r, reading, color in zip(curves, result.readings, colors, strict=True):
            draw_step(ax, r, reading.name, color)
        ax.set_title(f"{name}\n" + "\n".join(f"{reading.name}: {step_words(r)}"
                                             for r, reading in zip(curves, result.readings, strict=True)),
                     fontsize=7, loc="left")
        ax.axhline(1.0, color="k", lw=0.6, ls=":")
        ax.set_xlabel("time after the step [ms]")
        ax.grid(alpha=0.3)
    grid[0][0].set_ylabel("gyro ÷ set-point step")
    width = 0.27
    x = np.arange(3)
    for j, (reading, color) in enumerate(zip(result.readings, colors, strict=True)):
        grid[1][0].bar(x + (j - 1) * width, [a.tracking_rms_deg_s for a in reading.axes], width, color=color,
                       label=reading.name)
    grid[1][0].set_xticks(x, _AXES)
    grid[1][0].set_ylabel("tracking error rms [°/s]")
    grid[1][0].legend(fontsize=7)
    names = [r.name for r in result.readings]
    grid[1][1].bar(np.arange(3), [100.0 * r.motor_noise_rms for r in result.readings], color=colors)
    grid[1][1].set_ylabel("motor noise above 20 Hz, rms [% of full]")
    grid[1][2].bar(np.arange(3), [100.0 * r.saturated_fraction for r in result.readings], color=colors)
    grid[1][2].set_ylabel("time with a motor ≥ 99 % [%]")
    for ax in (grid[1][1], grid[1][2]):
        ax.set_xticks(np.arange(3), [n.replace(", ", "\n") for n in names], fontsize=8)
    for ax in grid[1]:
        ax.grid(alpha=0.3, axis="y")
    shown = ", ".join(f"{d.name} {d.flown} → {d.what_if}" for d in result.differences[:5])
    more = f", … ({len(result.differences)} settings differ; the command lists them all)" \
        if len(result.differences) > 5 else ""
    lo, hi = flown.window_s
    fig.suptitle(f"{flown.log} {lo:g}–{hi:g} s: the logged sticks with the log's tune and with the what-if\n"
                 f"{shown or 'no setting differs'}{more}", fontsize=9)
    return fig
