"""``aerobat learn``: design, then learn on a plant, every trial committed to the store.

The session logic is :mod:`aerobat.experiments.sessions`; this module turns options
into its arguments, prints progress, handles Ctrl-C (the first stops after the
trial in flight, a second abandons it) and writes figures.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from typing import Any

from aerobat.cli.common import (
    CommandFailed,
    HelpFormatter,
    add_db_option,
    add_maneuver_options,
    add_plant_options,
    bounded_int,
    check_outputs,
    console,
    maneuver_from_args,
    old_spelling,
    open_store,
    output_dir,
    plant_choice_from_args,
    plural,
    rule_choice_from_args,
    session_folder,
    session_ref,
    text_path,
)
from aerobat.cli.show import print_stored_session
from aerobat.core.bounds import ITERATIONS
from aerobat.errors import ConfigError

__all__ = ["KILL_LINE", "register"]

KILL_LINE = "aerobat: kill: the flight in progress disarms now; then learning stops"
"""What ``learn`` on a flight controller prints at once on Ctrl-C, the operator's kill (the session's own line
follows when it has stopped: ``aerobat: failed: stopped: trial N aborted: kill …``, exit 1)."""


class Interrupts:
    """SIGINT/SIGTERM while learning: the first lets the trial in flight finish, then stops; a second aborts it.

    With a plant that has a ``kill()`` (a real flight controller, ``--plant fc``), the first is the
    operator's kill: the flight in progress disarms at its next frame, and learning stops.
    """

    def __init__(self, kill: Any = None) -> None:
        self.kill = kill
        self.signum: int | None = None
        self._critical = 0
        self._pending = False
        self._stopping = False
        self._previous: dict[int, Any] = {}

    def install(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.signal(sig, self._handle)

    def restore(self, *, ignore: bool = False) -> None:
        """Put the previous handlers back, or with ``ignore`` ignore further signals (the process is ending)."""
        for sig, handler in self._previous.items():
            signal.signal(sig, signal.SIG_IGN if ignore else handler)
        self._previous.clear()

    def _handle(self, signum: int, frame: Any) -> None:
        if self.signum is None:
            self.signum = signum
            if self.kill is not None:
                self.kill()
                os.write(2, f"{KILL_LINE}\n".encode())
                return
            os.write(2, b"aerobat: stopping after the trial in flight (interrupt again to abort it)\n")
            return
        if self._stopping:  # learning has already stopped: nothing is in flight, the session is being closed
            os.write(2, b"aerobat: already stopping: closing the session\n")
            return
        if self._critical:
            self._pending = True
            return
        raise KeyboardInterrupt

    def requested(self) -> bool:
        """Polled between trials: True stops learning, and from then on a further interrupt is ignored
        (raised while the session is closed, it left the session open and the resume hint unprinted)."""
        if self.signum is not None:
            self._stopping = True
        return self.signum is not None

    @contextlib.contextmanager
    def critical(self) -> Iterator[None]:
        """A store commit: a second interrupt waits until it is done."""
        self._critical += 1
        try:
            yield
        finally:
            self._critical -= 1
            if self._pending and not self._critical:
                self._pending = False
                raise KeyboardInterrupt


def _cmd_learn(args: argparse.Namespace) -> int:
    from aerobat.experiments.sessions import resume_session, start_session, warm_start
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

    if args.resume is not None and args.from_session is not None:
        raise ConfigError("--resume and --from-session exclude each other: --resume continues a session, "
                          "--from-session starts a new one from another session's learned parameters")
    if args.resume is None and args.maneuver is None and args.maneuver_source is None:
        raise ConfigError("learn: name a maneuver (flip, translation or --maneuver FILE), or continue a stored "
                          "session with --resume SESSION")
    if args.resume is None:
        # everything cheap is checked before the store is touched and before the (long) design
        config = vehicle_from_name_or_file(args.vehicle)
        if args.plant_vehicle is not None and not args.plant_vehicle.strip():
            raise ConfigError("--plant-vehicle '': empty; name a preset or a vehicle .toml file")
        plant_config = vehicle_from_name_or_file(args.plant_vehicle) if args.plant_vehicle is not None else None
        maneuver = maneuver_from_args(args, config)
        plant = plant_choice_from_args(args)
        rule = rule_choice_from_args(args)
        plant.spec.check_available()
    with open_store(args, synchronous="full" if args.fsync else "normal") as store:
        if args.out is not None:  # an unusable --out (or a file in it linked to the store) fails now, not later
            folder = output_dir(text_path(args.out, "--out"))
            check_outputs({folder / name: "--out" for name in _WRITTEN}, stores=(store.path,))
        if args.resume is None:
            start, source = None, None
            if args.from_session is not None:
                start, source = warm_start(store, args.from_session, maneuver)
            run = start_session(store, maneuver, model=config, plant=plant, rule=rule,
                                iterations=args.iterations if args.iterations is not None else 30,
                                correction=args.correction, start_params=start, warm_start_from=source,
                                force=args.force, command=args.argv, plant_model=plant_config,
                                design_model=args.design_model)
        else:
            run = resume_session(store, args.resume, iterations=args.iterations, take_over=args.take_over)
            if args.maneuver is not None or args.maneuver_source is not None:
                _check_same_session(args, store, run)
        return _run(store, run, args)


def _check_same_session(args: argparse.Namespace, store: Any, run: Any) -> None:
    """With --resume, a full command line must describe the stored session."""
    from aerobat.experiments.sessions import spec_difference
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file, vehicle_table

    config = vehicle_from_name_or_file(args.vehicle)
    given_spec = json.loads(json.dumps(maneuver_from_args(args, config).spec()))
    stored_spec = json.loads(json.dumps(run.maneuver.spec()))
    differences = []
    if json.dumps(stored_spec, sort_keys=True) != json.dumps(given_spec, sort_keys=True):
        differences.append(f"maneuver: {spec_difference(stored_spec, given_spec)}")
    plant = plant_choice_from_args(args)
    if plant.kind != run.plant_choice.kind:
        differences.append(f"--plant {plant.kind} (stored: {run.plant_choice.kind})")
    elif plant.settings_table() != run.plant_choice.settings_table():
        differences.append("the plant's settings differ from the stored plant's")
    if plant.seed != run.plant_choice.seed:
        differences.append(f"--seed {plant.seed} (stored: {run.plant_choice.seed})")
    if args.feedback is not None and plant.feedback != run.plant_choice.feedback:
        differences.append(f"--feedback {args.feedback} (stored: {run.plant_choice.feedback.scheme.value})")
    if vehicle_table(config) != vehicle_table(run.model):
        differences.append(f"--vehicle {args.vehicle} differs from the stored vehicle")
    if rule_choice_from_args(args).to_table() != run.rule_choice.to_table():
        differences.append(f"--rule {args.rule} --gamma {args.gamma} (stored: {run.rule_choice.to_table()})")
    if args.design_model is not None and args.design_model != run.design_model.value:
        differences.append(f"--design-model {args.design_model} (stored: {run.design_model.value})")
    if args.correction != run.design.correction_kind:
        differences.append(f"--correction {args.correction} (stored: {run.design.correction_kind})")
    if differences:
        raise ConfigError(f"--resume {run.id}: the command line describes another session: "
                          f"{'; '.join(differences)}; give only --resume {run.id} to use the stored settings")


def _run(store: Any, run: Any, args: argparse.Namespace) -> int:
    from aerobat.experiments.designing import thrust_margin_line
    from aerobat.experiments.reports import session_figures, session_json
    from aerobat.experiments.sessions import position_error_m
    from aerobat.plotting import write_text

    sid = run.id
    hint = f"aerobat learn --resume {sid} --db {store.path}"
    out_console = console(args.json)

    closed = {"stdout": False}

    def say(text: str) -> None:
        if closed["stdout"]:
            return
        try:
            out_console.print(text, soft_wrap=True)
            out_console.file.flush()
        except (BrokenPipeError, ValueError, OSError):  # the reader left (`aerobat learn … | head -3`)
            closed["stdout"] = True

    verb = "resumed" if run.resumed else "started"
    say(f"session {sid} {verb} in {store.path}: {run.maneuver.name} on {run.plant_choice.kind} "
        f"(seed {run.plant_choice.seed}, feedback {run.plant_choice.feedback.scheme.value}, rule "
        f"{run.rule_choice.label}), {run.measured} of {plural(run.target, 'measured iteration')} done")
    say(f"  designed on the {run.design_model.value} model: {run.design_model_description}")
    if run.full_output_share is not None:
        say(thrust_margin_line(run.full_output_share))
    if not run.exact:
        say(f"  note: resumed trials will not repeat an uninterrupted run exactly: {run.inexact_because}")

    progress = _Progress(run.measured, run.target)
    legend = ["  (each trial: γ is the update's step, Sect. 4; scale the part of it kept inside the parameters' "
              "bounds, Sect. 4.2)"]

    def on_iteration(it: Any) -> None:  # printed only once committed: every line is a stored iteration
        when = progress.tick(it.measured)
        while legend:  # above the first trial's line
            say(legend.pop())
        if it.measured:
            say(f"  {it.index:3d}  ok          position error {position_error_m(run.maneuver, it.error):7.3f} m  "
                f"γ={it.gamma:.2f}  scale={it.scale:.2f}  {when}")
        else:
            say(f"  {it.index:3d}  {it.status.value:10s}  {it.message}  {when}")
        for warning in it.warnings:
            say(f"  warning: {warning}")

    # the folder and every file written at the end are checked before the first flight (issue 31 D4)
    out = session_folder(args, store, sid, explicit=args.out if args.out is not None else _stored_out(store, sid))
    check_outputs({out / name: "--out" for name in _WRITTEN}, stores=(store.path,))
    interrupts = Interrupts(kill=getattr(run.plant, "kill", None))
    interrupts.install()
    try:
        outcome = run.run(on_iteration=on_iteration, critical=interrupts.critical,
                          should_stop=lambda: interrupts.requested() or closed["stdout"])
    except Exception as exc:
        from aerobat.errors import StoreError

        if isinstance(exc, StoreError):
            raise CommandFailed(f"{exc}; session {sid} keeps every iteration stored before this one: resume with "
                                f"`{hint}` once fixed") from None
        raise
    finally:
        # once stopped by a signal, the program only closes the session and exits: a repeated Ctrl-C must
        # not kill it by signal while the interpreter shuts down (in-process callers get their handlers back)
        interrupts.restore(ignore=interrupts.requested() and getattr(args, "standalone", False))
    from aerobat.core.learning import SessionStatus

    if outcome.status is SessionStatus.INTERRUPTED:
        signum = interrupts.signum or (signal.SIGPIPE if closed["stdout"] else signal.SIGINT)
        why = "standard output was closed: " if closed["stdout"] and not interrupts.signum else ""
        print(f"aerobat: interrupted: {why}session {sid} stopped after iteration {outcome.last_index} "
              f"with {outcome.measured} of {plural(outcome.target, 'measured iteration')} stored; resume with: {hint}",
              file=sys.stderr, flush=True)
        return 128 + int(signum)
    data = session_json(store, sid)
    data["wall_s"] = outcome.wall_s
    write_text(out / "session.json", json.dumps(data, indent=1))
    notes = session_figures(store, sid, out)
    if args.json:
        print(json.dumps({k: data[k] for k in ("error_names", "parameter_names", "iterations", "final_params",
                                                "status", "message", "plant", "session_id", "db")}))
    else:
        print_stored_session(store, sid, iterations=True, table=False)  # each row was printed as it was stored
        out_console.print(f"per-iteration table: aerobat show {sid} --db {store.path}")
        for warning in outcome.warnings:
            out_console.print(f"warning: {warning}")
        for note in notes:
            out_console.print(note)
        out_console.print(f"figures and session.json in {out}/")
    if not outcome.completed:
        raise CommandFailed(f"{outcome.message}; session {sid} is stored: resume with `{hint}`")
    return 0


_WRITTEN = ("session.json", "learning.png", "side_views.png")
class _Progress:
    """``[3/30, 4 s, about 36 s left]``: measured trials of the target, the time so far, and the estimate
    from this run's trials."""

    def __init__(self, measured: int, target: int) -> None:
        self.measured, self.target = measured, target
        self.started = time.perf_counter()
        self.trials = 0

    def tick(self, measured: bool) -> str:
        self.trials += 1
        self.measured += int(measured)
        elapsed = time.perf_counter() - self.started
        left = max(self.target - self.measured, 0)
        # every trial of this run, failed ones included, took time: the estimate is per trial flown
        estimate = f", about {_duration(elapsed / self.trials * left)} left" if left else ", done"
        return f"[{self.measured}/{self.target}, {_duration(elapsed)}{estimate}]"


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _stored_out(store: Any, sid: int) -> str | None:
    """The ``--out`` the session was started (or last resumed) with, from its stored command line."""
    command = list(store.session(sid).command or [])
    for k, word in enumerate(command):
        if word == "--out" and k + 1 < len(command):
            return str(command[k + 1])
        if word.startswith("--out="):
            return word.split("=", 1)[1]
    return None


def register(sub: Any) -> None:
    p = sub.add_parser("learn", help="design, then learn on a plant (every iteration goes to the store)",
                       formatter_class=HelpFormatter)
    add_maneuver_options(p, optional=True)
    add_plant_options(p)
    p.add_argument("--trials", dest="iterations", type=bounded_int(*ITERATIONS.bounds()), default=None,
                   help="measured trials, one learning iteration each (default: 30; with --resume the stored target)")
    old_spelling(p, "--iterations", "iterations", type=bounded_int(*ITERATIONS.bounds()))
    p.add_argument("--gamma", default="paper", help="'paper', that is max(1/i, 0.1), or a constant in (0, 1]")
    p.add_argument("--rule", default="paper",
                   help="update rule: paper, tsvd, damped, kalman, broyden, or <rule>+isc (docs/method.md)")
    p.add_argument("--out", default=None, help="folder for figures and session.json "
                                               "(default: out/STORE-HASH/session-ID, one per store and session)")
    p.add_argument("--resume", metavar="SESSION", type=session_ref,
                   help="continue a stored session (id or 'last') with its parameters, counters and plant state "
                        "(default: start a new one)")
    p.add_argument("--from-session", metavar="SESSION", type=session_ref,
                   help="start a new session from another session's learned parameters, same maneuver (default: p⁰)")
    p.add_argument("--plant-vehicle", default=None, metavar="NAME|FILE",
                   help="the vehicle the plant is built around, if not --vehicle (a simulated plant makes its true "
                        "vehicle and its onboard controller from it): with a vehicle identified on the arena as "
                        "--vehicle, give the one the arena flew, e.g. hummingbird (default: --vehicle)")
    p.add_argument("--force", action="store_true", help="learn even if the design did not converge")
    p.add_argument("--take-over", action="store_true",
                   help="with --resume: take a session last run on another machine whose process is gone")
    p.add_argument("--fsync", action="store_true",
                   help="make every commit survive power loss too (an fsync per iteration)")
    add_db_option(p)
    p.set_defaults(func=_cmd_learn)
