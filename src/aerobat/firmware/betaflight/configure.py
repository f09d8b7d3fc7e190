"""Configure the firmware once through its CLI and keep the resulting eeprom.

Why a separate process: entering the CLI sets the CLI arming-disable flag for
the rest of the process (even after ``exit noreboot``), and CLI traffic
arrives at wall-clock moments, which would make a lockstep run
non-deterministic. So :func:`ensure_eeprom` starts a SITL from a blank eeprom,
keeps it stepping (level, at rest) from a background thread so that its serial
task runs, applies ``settings.toml`` over TCP, sends ``save`` (the SITL writes
``eeprom.bin`` and exits), checks the saved values in a second process, and
caches ``eeprom.bin``. Flying processes start from a copy of it and never open
the CLI.

Before a firmware starts, :func:`check_commands` holds every command against the
CLI's line rules and every ``set`` value against the build's table
(``sitl_settings.json``): whatever made the settings (``settings.toml``, a tune,
code), nothing reaches the CLI that it would run otherwise or read back changed.
"""

from __future__ import annotations

import argparse
import fcntl
import re
import shutil
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from aerobat.errors import ConfigError

from .build import ensure_sitl
from .cli_grammar import line_problem, shown
from .errors import BetaflightError, ConfigureFailed, FirmwareNotResponding
from .packets import SitlState
from .settings import BetaflightSettings, load_settings
from .sitl import SitlProcess
from .sitl_table import Verdict, load_table

__all__ = [
    "ARMING_DIAGNOSIS_TIMEOUT_S",
    "AT_REST_LEVEL",
    "AtRestStepper",
    "check_arms",
    "check_commands",
    "ensure_eeprom",
    "step_at_rest",
]

AT_REST_LEVEL = SitlState(
    time_s=0.0,
    gyro_frd_rad_s=(0.0, 0.0, 0.0),
    specific_force_frd_m_s2=(0.0, 0.0, -9.80665),
    quat_wxyz_frd_to_ned=(1.0, 0.0, 0.0, 0.0),
)
"""Sensors of a level quad standing still (time filled in per step)."""

Progress = Callable[[str], None]


class AtRestStepper:
    """Keeps a SITL stepping at rest from a background thread until stopped or the firmware exits."""

    def __init__(self, sitl: SitlProcess) -> None:
        self._sitl = sitl
        self._stop = threading.Event()
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="sitl-at-rest", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            step_at_rest(self._sitl, self._stop.is_set)
        except FirmwareNotResponding as error:  # expected after `save`
            self.error = error

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=10.0)


def step_at_rest(sitl: SitlProcess, stop: Callable[[], bool], steps: int | None = None) -> int:
    """Step ``sitl`` with :data:`AT_REST_LEVEL` until ``stop()`` is true (or ``steps`` are done).

    Returns the number of steps taken.
    """
    period_s = sitl.gyro_period_us / 1e6
    taken = 0
    while not stop() and (steps is None or taken < steps):
        sitl.step(AT_REST_LEVEL._replace(time_s=(sitl.steps + 1) * period_s))
        taken += 1
    return taken


def _apply(sitl: SitlProcess, settings: BetaflightSettings, say: Progress) -> str:
    """Apply the settings over the CLI and save; returns the CLI transcript."""
    stepper = AtRestStepper(sitl)
    transcript = []
    try:
        with sitl.open_link() as link:
            transcript.append(link.cli.enter())
            for command in settings.cli_commands():
                output = link.cli.command(command)
                if command.startswith("feature") and output.startswith("Unavailable"):
                    raise ConfigureFailed(f"CLI command {command!r}: {output.strip()} in this build")
                transcript.append(f"# {command}\n{output}")
            say(f"applied {len(settings.cli_commands())} CLI commands; saving")
            transcript.append(link.cli.save())
        deadline = time.monotonic() + 10.0
        while sitl.alive() and time.monotonic() < deadline:
            time.sleep(0.02)
        if sitl.alive():
            raise ConfigureFailed("the SITL did not exit after `save`")
    finally:
        stepper.stop()
    return "\n".join(transcript)


_GET_PATTERN = re.compile(r"^(\w+) = (.*?)\s*$", re.MULTILINE)
_SET_COMMAND = re.compile(r"set ([a-z0-9_]+) = (.*)")


def check_commands(settings: BetaflightSettings) -> None:
    """Refuse the settings unless the CLI runs each of their commands as written and takes each ``set`` value.

    Every command must be a line the firmware's CLI runs as written (:func:`.cli_grammar.line_problem`);
    every ``set NAME = VALUE`` must name a setting of this SITL build and give it a value the build
    accepts (:meth:`.sitl_table.SettingRange.checked`), written as the firmware prints it back (what
    :func:`_verify` compares).

    Raises
    ------
    ConfigError
        Naming the settings (and the tune), the command and what is wrong; nothing is started.
    """
    table = load_table()
    origin = str(settings.path) + (f" with the tune {settings.tune.tune.source}" if settings.tune is not None else "")
    for command in settings.cli_commands():
        problem = line_problem(command)
        match = _SET_COMMAND.fullmatch(command) if problem is None else None
        if match is not None:
            name, value = match.groups()
            entry = table.get(name)
            checked = entry.checked(value) if entry is not None else None
            if checked is None:
                problem = f"{name} is not a setting of this SITL build ({table.firmware})"
            elif checked.verdict is not Verdict.ACCEPTED:
                problem = checked.reason
            elif checked.value.upper() != value.upper():
                problem = f"the firmware would read it back as {checked.value!r}; write that"
        if problem is not None:
            raise ConfigError(f"{origin}: {shown(command, 80)}: {problem}")


def _verify(sitl: SitlProcess, settings: BetaflightSettings) -> None:
    """Read every configured value back through the CLI of a process started from the saved eeprom."""
    stepper = AtRestStepper(sitl)
    try:
        with sitl.open_link() as link:
            link.cli.enter()
            for name, expected in settings.values:
                output = link.cli.command(f"get {name}")
                found = {match.group(1): match.group(2) for match in _GET_PATTERN.finditer(output)}
                if found.get(name, "").upper() != expected.upper():
                    raise ConfigureFailed(f"saved eeprom has {name} = {found.get(name)!r}, expected {expected!r}")
            aux_output = link.cli.command("aux")
            for slot, mode in enumerate(settings.modes.values()):
                if mode.cli_command(slot) not in aux_output:
                    raise ConfigureFailed(f"saved eeprom lacks {mode.cli_command(slot)!r}")
    finally:
        stepper.stop()


ARMING_DIAGNOSIS_TIMEOUT_S = 15.0
"""How long :func:`check_arms` waits for the firmware's arming-disable flags after it did not arm [s, wall]."""


def check_arms(binary: Path, eeprom: Path, settings: BetaflightSettings, *, calibration_s: float = 1.6) -> None:
    """Power a fresh process from ``eeprom`` on at rest, give ARM as the pilot does, and raise unless it arms.

    Raises
    ------
    ConfigureFailed
        The firmware refuses to arm; the message names the arming-disable flags it reports (MSP_STATUS_EX).
    """
    from .rc import AUX_CHANNEL_COUNT, RC_MID_US, RC_MIN_US

    def channels(arm: bool) -> tuple[int, ...]:
        aux = settings.aux_us(ARM=arm, ANGLE=True)
        return (RC_MID_US, RC_MID_US, RC_MIN_US, RC_MID_US, *aux, *([RC_MIN_US] * (AUX_CHANNEL_COUNT - len(aux))))

    with SitlProcess(binary, eeprom) as sitl:
        period_s = sitl.gyro_period_us / 1e6
        sitl.set_rc(channels(False))
        step_at_rest(sitl, lambda: False, steps=int(calibration_s / period_s))
        sitl.set_rc(channels(True))
        for _ in range(int(1.0 / period_s)):
            motors = sitl.step(AT_REST_LEVEL._replace(time_s=(sitl.steps + 1) * period_s))
            if min(motors) > 0.0:
                return
        stepper = AtRestStepper(sitl)
        try:
            with sitl.open_link() as link:
                # the answer comes only as the stepper advances the firmware, which a loaded machine slows
                # (a 1 s wait failed under five processes on two cores): a diagnosis can wait
                flags = link.msp.status_ex(timeout_s=ARMING_DIAGNOSIS_TIMEOUT_S).arming_disable_flags
        finally:
            stepper.stop()
    why = (f"arming disabled by {', '.join(flags)}" if flags else
           f"the ARM switch (AUX{settings.modes['ARM'].aux}) did not arm it and it reports no arming-disable flag")
    raise ConfigureFailed(f"the firmware would not arm with these settings: {why}")


def ensure_eeprom(
    binary: Path | None = None,
    settings_path: Path | None = None,
    *,
    cache_dir: Path | None = None,
    verify: bool = True,
    progress: Progress | None = None,
    settings: BetaflightSettings | None = None,
) -> Path:
    """Return a configured ``eeprom.bin`` for ``binary``, creating it on first use.

    Parameters
    ----------
    binary : Path, optional
        Lockstep SITL binary (default :func:`.build.ensure_sitl`).
    settings_path : Path, optional
        Settings file (default: the packaged ``settings.toml``).
    cache_dir : Path, optional
        Cache root passed to :func:`.build.ensure_sitl` when ``binary`` is None.
    verify : bool
        Read the values back from the saved eeprom in a second process.
    progress : callable, optional
        Called with one line of text per stage.
    settings : BetaflightSettings, optional
        Settings already loaded (e.g. with a tune, :meth:`.BetaflightSettings.with_tune`); overrides
        ``settings_path``.

    Returns
    -------
    Path
        ``eeprom-<settings sha256[:12]>.bin`` next to the binary.

    Raises
    ------
    ConfigError
        A command the CLI would not run as written, or a value the build does not take
        (:func:`check_commands`); nothing was started.
    ConfigureFailed
        The CLI rejected a command, or the saved eeprom does not hold the values.
    FirmwareUnavailable, FirmwareNotResponding
        The firmware could not be built or started.
    """
    say = progress or (lambda _line: None)
    settings = settings if settings is not None else load_settings(settings_path)
    check_commands(settings)
    binary = Path(binary) if binary is not None else ensure_sitl(cache_dir, progress=progress)
    eeprom = binary.parent / f"eeprom-{settings.sha256[:12]}.bin"
    if eeprom.is_file():
        return eeprom
    lock_path = eeprom.with_suffix(".lock")
    with open(lock_path, "a") as lock:  # internal
        fcntl.flock(lock, fcntl.LOCK_EX)
        if eeprom.is_file():
            return eeprom
        say(f"configuring from a blank eeprom with {settings.path.name} (revision {settings.revision})")
        with SitlProcess(binary, None) as sitl:
            workdir = sitl.workdir
            assert workdir is not None
            transcript = _apply(sitl, settings, say)
            saved = workdir / "eeprom.bin"
            if not saved.is_file():
                raise ConfigureFailed(f"no eeprom.bin was saved in {workdir}")
            staged = eeprom.with_suffix(".tmp")
            shutil.copyfile(saved, staged)
        (binary.parent / f"{eeprom.stem}.cli.txt").write_text(transcript)  # internal
        if verify:
            say("verifying the saved eeprom in a fresh process")
            try:
                with SitlProcess(binary, staged) as check:
                    _verify(check, settings)
                if settings.tune is not None:  # a tune may hold what keeps the firmware from arming
                    say("checking that the firmware arms with the tune")
                    check_arms(binary, staged, settings)
            except BaseException:
                staged.unlink(missing_ok=True)
                raise
        staged.replace(eeprom)
        say(f"configured eeprom: {eeprom}")
        return eeprom


def main(argv: list[str] | None = None) -> int:
    """Command line: configure (or find) the eeprom and print its path."""
    parser = argparse.ArgumentParser(description="Configure the Betaflight SITL eeprom (cached).")
    parser.add_argument("--cache-dir", type=Path, default=None)
    parser.add_argument("--settings", type=Path, default=None)
    args = parser.parse_args(argv)
    try:
        eeprom = ensure_eeprom(settings_path=args.settings, cache_dir=args.cache_dir, progress=print)
    except BetaflightError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    print(eeprom)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
