"""The ``aerobat`` command: the parser, and the one table from exceptions to exit statuses.

=======  ==================================================================
status   meaning
=======  ==================================================================
0        done
1        it ran and failed: a design or solve did not converge, a trial
         crashed, an identification had too few usable trials or too large a
         residual, a study job failed, an optional package is missing (its
         install hint is printed), the disk is full, the store is locked
2        bad input: an option, a file, a field or a value out of range; a
         store that is not an aerobat store, a session that does not exist
70       an internal error (a bug): one line, ``--debug`` shows the traceback
128+n    stopped by signal n (130 for Ctrl-C) after storing what was done; 141
         (SIGPIPE), silently, when the reader of standard output left (``| head``)
=======  ==================================================================

Every error is one line on stderr: ``aerobat: error: …`` (status 2) or
``aerobat: failed: …`` (1 and 70). Nothing here is imported by the library.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Iterator, Sequence
from typing import Any

from aerobat.cli.common import CommandFailed, HelpFormatter, Parser
from aerobat.errors import (
    ConfigError,
    DesignFailed,
    DiskFull,
    IdentificationFailed,
    MissingDependency,
    OutputError,
    PlantError,
    SessionInUse,
    SessionNotFound,
    SolveFailed,
    StoreAccessError,
    StoreError,
    StoreFormatError,
    StoreVersionError,
    WorkersUnavailable,
)

__all__ = ["EXIT_FAILED", "EXIT_INTERNAL", "EXIT_OK", "EXIT_USAGE", "build_parser", "exit_status", "main"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_INTERNAL = 70
EXIT_STOPPED_BY_PIPE = 128 + 13  # SIGPIPE: what `yes | head -1` reports for `yes`

_USAGE = (ConfigError, StoreAccessError, StoreFormatError, StoreVersionError, SessionNotFound, SessionInUse)
_FAILED = (DesignFailed, IdentificationFailed, SolveFailed, PlantError, MissingDependency, DiskFull, StoreError,
           CommandFailed, WorkersUnavailable)


def exit_status(exc: BaseException) -> int:
    """The documented exit status of an exception (see the module's table)."""
    if isinstance(exc, DiskFull):
        return EXIT_FAILED
    if isinstance(exc, _USAGE) or isinstance(exc, OutputError):
        return EXIT_USAGE
    if isinstance(exc, _FAILED):
        return EXIT_FAILED
    return EXIT_INTERNAL


def _commands(only: str | None = None) -> list:
    if only == "log":  # the other commands' options name the plants: importing them compiles nothing but
        from aerobat.cli import log  # loads numba and the arena (~0.5 s of a `log info`), which log needs not

        return [log]
    from aerobat.cli import (
        benchmark,
        browse,
        design,
        identify,
        learn,
        log,
        sessions,
        setup,
        simulate,
        study,
        tune,
        vehicles,
    )

    return [simulate, design, learn, sessions, browse, benchmark, study, identify, vehicles, log, tune, setup]


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The whole command line, or (``only="log"``) just the ``log`` command's part of it."""
    from aerobat import __version__

    parser = Parser(prog="aerobat", description="Design and learn fast open-loop quadrocopter maneuvers "
                    "(Lupashin & D'Andrea 2012).", formatter_class=HelpFormatter)
    parser.add_argument("--debug", action="store_true", help="show tracebacks for errors (accepted anywhere)")
    parser.add_argument("--version", action="version", version=f"aerobat {__version__}")
    sub = parser.add_subparsers(dest="command", parser_class=Parser, metavar="COMMAND")
    for module in _commands(only):
        module.register(sub)
    return parser


def _missing_command(parser: argparse.ArgumentParser, args: argparse.Namespace) -> str:
    """``benchmark: name a command: translation, map`` for a command group given without its command."""
    path: list[str] = []
    while True:
        group = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)  # noqa: SLF001
        if group is None:
            return "name a command"
        name = getattr(args, group.dest, None)
        if name is None or name not in group.choices:
            return f"{' '.join(path) or 'aerobat'}: name a command: {', '.join(group.choices)}"
        path.append(name)
        parser = group.choices[name]


def _one_line(exc: BaseException) -> str:
    """The message on one line: line breaks become spaces, other control characters their escapes."""
    text = " ".join(str(exc).splitlines()) or type(exc).__name__
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in text)


def _valued_options(parser: argparse.ArgumentParser) -> set[str]:
    """Every option string that takes one value, in any command."""
    out: set[str] = set()
    for action in parser._actions:  # noqa: SLF001 - argparse has no public list of its actions
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
            for sub in action.choices.values():
                out |= _valued_options(sub)
        elif action.option_strings and action.nargs in (None, "?"):  # one value; `--window-s -1 5` is argparse's
            out.update(action.option_strings)
    return out


def _negative_values(argv: list[str], valued: set[str] | None = None) -> list[str]:
    """``--to -2,4`` → ``--to=-2,4``: a value that starts with a minus sign is a value, not an option.

    Only options that take a value (``valued``, default: any) are joined: ``--json -1`` stays two words.
    """
    out: list[str] = []
    k = 0
    while k < len(argv):
        token = argv[k]
        following = argv[k + 1] if k + 1 < len(argv) else ""
        if (token.startswith("--") and "=" not in token and (valued is None or token in valued)
                and len(following) > 1 and following[0] == "-"
                and (following[1].isdigit() or following[1] == ".")):
            out.append(f"{token}={following}")
            k += 2
            continue
        out.append(token)
        k += 1
    return out


@contextlib.contextmanager
def _undecodable_names_printable() -> Iterator[None]:
    """Print file names as given, even undecodable ones (``\\xff`` in argv is ``\\udcff`` in Python).

    Standard output is strict UTF-8 by default, so printing such a name (``written to …``) would
    raise UnicodeEncodeError; ``surrogateescape`` writes back the bytes the user gave.
    """
    reconfigure = getattr(sys.stdout, "reconfigure", None)
    previous = getattr(sys.stdout, "errors", None)
    changed = False
    if previous == "strict" and reconfigure is not None:
        with contextlib.suppress(AttributeError, ValueError, OSError):
            reconfigure(errors="surrogateescape")
            changed = True
    try:
        yield
    finally:
        if changed and reconfigure is not None:
            with contextlib.suppress(AttributeError, ValueError, OSError):
                reconfigure(errors=previous)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (see the module's table)."""
    with _undecodable_names_printable(), _interrupts_redelivered():
        return _main(argv)


@contextlib.contextmanager
def _interrupts_redelivered() -> Iterator[None]:
    """A Ctrl-C (or a SIGTERM a command turns into :class:`~aerobat.cli.stopping.Stopped`) that lands in a
    finalizer is delivered again, to the main thread at its next instruction.

    Python runs signal handlers between instructions of the main thread, which may be inside a ``__del__``
    or a weak reference's callback that the garbage collector runs; an exception raised there cannot
    propagate, so Python prints "Exception ignored in …" with a traceback and the command carries on as if
    the key had not been pressed (the full fuzz campaign: ``browse --export`` went on until a second Ctrl-C).
    """
    import _thread
    import signal
    import threading

    previous = sys.unraisablehook

    def hook(unraisable: Any) -> None:
        if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
            # from another thread, a moment later: raised now, it would be raised inside this hook, and dropped
            # again; should it land in another finalizer, this hook sends it once more
            signum = getattr(unraisable.exc_value, "signum", signal.SIGINT)
            timer = threading.Timer(0.01, _thread.interrupt_main, args=(signum,))
            timer.daemon = True
            timer.start()
            return
        previous(unraisable)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        sys.unraisablehook = previous


def _main(argv: Sequence[str] | None) -> int:
    import os

    # the command line draws into files; only here is a backend chosen (by matplotlib when, and if,
    # a command imports it, or now if something already has)
    os.environ["MPLBACKEND"] = "Agg"
    if "matplotlib" in sys.modules:
        sys.modules["matplotlib"].use("Agg")
    standalone = argv is None
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    words = [a for a in argv if not a.startswith("-")]
    parser = build_parser("log" if words[:1] == ["log"] else None)
    argv = _negative_values([a for a in argv if a != "--debug"], _valued_options(parser))
    if not argv:  # bare `aerobat`: what it can do
        parser.print_help()
        return EXIT_OK
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a usage error already printed: a status, not an exception
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    args.debug = debug
    args.argv = argv
    args.standalone = standalone
    if getattr(args, "func", None) is None:  # a command group without its subcommand: show its commands
        with contextlib.suppress(SystemExit):
            parser.parse_args([*argv, "--help"])
        print(f"aerobat: error: {_missing_command(parser, args)}", file=sys.stderr)
        return EXIT_USAGE
    try:
        return int(args.func(args))
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM where a command turns it into Stopped
        from aerobat.cli.stopping import Stopped

        stopped = exc if isinstance(exc, Stopped) else None
        print(f"aerobat: {stopped.message if stopped else 'interrupted'}", file=sys.stderr)
        return 128 + (stopped.signum if stopped else 2)
    except BrokenPipeError:  # `aerobat … | head`: the reader left; nothing more to say, as a shell tool would
        from aerobat.cli.common import quiet_stdout

        quiet_stdout()  # the interpreter's last flush must not fail either ("Exception ignored … BrokenPipeError")
        return EXIT_STOPPED_BY_PIPE
    except Exception as exc:
        status = exit_status(exc)
        if debug:  # the traceback, then the same line and the same status as without --debug
            import traceback

            traceback.print_exc()
        if isinstance(exc, MissingDependency):
            print(f"aerobat: failed: {_one_line(exc)}", file=sys.stderr)
        elif status == EXIT_USAGE:
            print(f"aerobat: error: {_one_line(exc)}", file=sys.stderr)
        elif status == EXIT_FAILED:
            print(f"aerobat: failed: {_one_line(exc)}", file=sys.stderr)
        else:
            print(f"aerobat: failed: internal error: {type(exc).__name__}: {_one_line(exc)} "
                  f"(--debug shows a traceback)", file=sys.stderr)
        return status
