"""``--tune FILE``: a real quad's Betaflight configuration, read and checked as the firmware would take it,
and applied to the plant that flies it (the plants whose spec has :attr:`aerobat.plants.PlantSpec.tune`;
the option itself is :func:`aerobat.cli.common.add_tune_option`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from aerobat.errors import ConfigError

__all__ = ["read_tune", "with_tune_from_args"]


def read_tune(path: str | Path, log_index: int | None = None,
              option: str = "--tune-log-index") -> tuple[Any, dict[str, float], str]:
    """What the tune in ``path`` (``FILE:N``: log N of a blackbox file) becomes on the SITL, checked as the
    firmware would be configured; nothing runs. ``log_index`` is the log given by ``option`` instead.

    Returns the :class:`~aerobat.firmware.betaflight.translate.TuneReport`, the tune's full-stick rates
    [deg/s] per axis and its ``rates_type``. A tune that cannot be read, names an unknown setting or
    holds a value that is no value of its setting is bad input (:class:`~aerobat.errors.ConfigError`).
    """
    from aerobat.firmware.betaflight.configure import check_commands
    from aerobat.firmware.betaflight.settings import load_settings
    from aerobat.firmware.betaflight.translate import translate
    from aerobat.firmware.betaflight.tune import TuneError, load_tune
    from aerobat.logs.refs import parse_log_ref

    named = parse_log_ref(path)
    ref = named.with_index(log_index, option)
    try:
        tune = load_tune(ref.path, log_index=ref.index)
    except TuneError as exc:  # a log named by the option: the refusal says so
        raise (TuneError(f"{exc} ({option} {log_index})") if log_index is not None and named.index is None
               else exc) from None
    report = translate(tune)  # unknown settings raise here, naming the file and line
    tuned = load_settings().with_tune(report)
    check_commands(tuned)  # the last check before the firmware's CLI, as configuring it runs it
    rates = {axis: tuned.rate_deg_s(axis, 1.0) for axis in ("roll", "pitch", "yaw")}
    return report, rates, tuned.value("rates_type")


def with_tune_from_args(args: argparse.Namespace, choice: Any) -> Any:
    """``choice`` with ``--tune FILE`` (``--tune-log-index N``) applied; prints what the tune became (stderr).

    A tune that cannot be read or names an unknown setting is bad input (exit 2), before anything flies.
    """
    tune_path = getattr(args, "tune", None)
    log_index = getattr(args, "tune_log_index", None)
    if tune_path is None:
        if log_index is not None:
            raise ConfigError("--tune-log-index applies only with --tune FILE")
        return choice
    from aerobat.plants import PlantChoice, tuned_plants

    if choice.spec.tune is None:
        raise ConfigError(f"--tune applies only with --plant {' or '.join(tuned_plants())} (got --plant {choice.kind})")
    import shlex

    report, rates, rates_type = read_tune(tune_path, log_index)
    shown = ", ".join(f"{axis} {rate:.0f}" for axis, rate in rates.items())
    whole = "aerobat tune " + shlex.quote(f"{tune_path}:{log_index}" if log_index is not None else str(tune_path))
    print(f"{report.summary(whole)}\n  the tune's full-stick rates [deg/s] ({rates_type}): {shown}; the pilot's "
          "sticks invert its rate and throttle curves", file=sys.stderr)
    return PlantChoice(choice.kind, choice.spec.tune(choice.settings, report.tune), choice.seed, choice.feedback)
