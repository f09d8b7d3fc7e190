"""What every command shares: options, the store resolver, output folders and printing.

Strings become objects here and nowhere deeper: a ``--plant arena --arena f.toml --seed 3``
becomes a :class:`~aerobat.plants.PlantChoice`, a ``--rule tsvd+isc`` a
:class:`~aerobat.core.rules.RuleChoice`, a ``--db`` (or its default) an open
:class:`~aerobat.store.Store`.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from aerobat.core.bounds import SEEDS, Integer, choices_of
from aerobat.core.correction import CorrectionKind
from aerobat.errors import AerobatError, ConfigError, OutputError
from aerobat.quadrotor.feedback import FeedbackScheme
from aerobat.quadrotor.maneuvers.flip import DIMS, FLIPS, MAX_RATE_DEG_S, Axis, Coast
from aerobat.quadrotor.program import MANEUVER_RAMP_S

__all__ = [
    "CommandFailed",
    "HelpFormatter",
    "Parser",
    "add_db_option",
    "add_maneuver_options",
    "add_plant_options",
    "add_tune_option",
    "old_spelling",
    "console",
    "each_of",
    "maneuver_from_args",
    "open_store",
    "output_dir",
    "quiet_stdout",
    "parse_pair",
    "plural",
    "plant_choice_from_args",
    "plant_settings_path",
    "refuse_overwrite",
    "check_outputs",
    "check_plot_files",
    "session_folder",
    "rule_choice_from_args",
    "session_ref",
    "text_path",
]

EXIT_USAGE = 2


class CommandFailed(AerobatError):
    """A command ran but its result is a failure (a session that did not complete, failed study jobs…)."""


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows each option's default — unless its help already says what it defaults to, or there is none."""

    def _split_lines(self, text: str, width: int) -> list[str]:
        """Wrapped between words only: never inside a path (``out/session-ID``) or a hyphenated word."""
        import textwrap

        return textwrap.wrap(" ".join(text.split()), width, break_on_hyphens=False, break_long_words=False)

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "default" in text or "required" in text or action.default in (None, argparse.SUPPRESS):
            return text
        if isinstance(action, argparse._StoreTrueAction):  # noqa: SLF001 - argparse has no public name for it
            return text + " (default: off)"
        return super()._get_help_string(action) or ""


class _OldSpelling(argparse.Action):
    """An option's earlier name, still accepted (hidden from --help): converts and stores under the new dest."""

    def __init__(self, option_strings: list[str], dest: str, convert: Any = None, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, help=argparse.SUPPRESS, default=argparse.SUPPRESS, **kwargs)
        self.convert = convert

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        setattr(namespace, self.dest, self.convert(values) if self.convert is not None else values)


def old_spelling(p: argparse.ArgumentParser, old: str, dest: str, *, type: Any = None, convert: Any = None) -> None:
    """Accept ``old`` (an option's name before docs/cli.md's vocabulary) as the option stored in ``dest``."""
    p.add_argument(old, dest=dest, action=_OldSpelling, type=type, convert=convert)


_NO_VALUE = ("--", "")
_UNIT_METAVARS = (("-rad-s", "RAD/S"), ("-deg-s", "DEG/S"), ("-m-s2", "M/S²"), ("-mm", "MM"), ("-deg", "DEG"),
                  ("-rad", "RAD"), ("-kg", "KG"), ("-m", "M"), ("-s", "S"))


def _metavar(option: str, kind: Any) -> str | None:
    if option == "--out":
        return "DIR"
    if kind is int or getattr(kind, "metavar", None) == "N":
        return "N"
    for suffix, unit in _UNIT_METAVARS:
        if option.endswith(suffix):
            return unit
    return None


def _with_metavar(args: tuple[Any, ...], kwargs: dict[str, Any]) -> dict[str, Any]:
    """``kwargs`` with the metavar an option's name and type imply (N, DIR, the unit), unless one is given."""
    options = [a for a in args if isinstance(a, str) and a.startswith("-")]
    takes_value = kwargs.get("action") in (None, "store", "append") and "choices" not in kwargs
    metavar = _metavar(options[0], kwargs.get("type")) if options and takes_value and "metavar" not in kwargs else None
    return kwargs if metavar is None else {**kwargs, "metavar": metavar}


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors and the documented exit status for bad usage.

    Options are never matched by a prefix (``--flip`` is not ``--flips``): an unknown option is
    refused with the nearest known one as a suggestion. An option's value is never ``--`` or empty
    (argparse would pass an empty list on, or nothing at all).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def add_argument(self, *args: Any, **kwargs: Any) -> argparse.Action:
        """An option's metavar says what it takes: N for a count, DIR for ``--out``, the unit for a quantity."""
        return super().add_argument(*args, **_with_metavar(args, kwargs))

    def add_argument_group(self, *args: Any, **kwargs: Any) -> Any:
        """A titled group of options in the help, whose options get their metavars as the parser's do."""
        group = super().add_argument_group(*args, **kwargs)
        plain = group.add_argument
        group.add_argument = lambda *names, **options: plain(*names, **_with_metavar(names, options))  # type: ignore
        return group

    def error(self, message: str) -> NoReturn:
        unknown = self._unknown_options() if "arguments are required" in message else []
        if unknown:  # an unknown option explains a missing argument better than the other way round
            message = f"unrecognized arguments: {' '.join(unknown)}{self._did_you_mean(unknown[0])}"
        self.exit(EXIT_USAGE, f"aerobat: error: {message}\n")

    def _unknown_options(self) -> list[str]:
        known = {s for a in self._actions for s in a.option_strings}  # noqa: SLF001
        words = getattr(self, "_words", [])
        cut = words.index("--") if "--" in words else len(words)
        return [w for w in words[:cut] if w.startswith("-") and len(w) > 1 and w.split("=", 1)[0] not in known
                and not self._negative_number_matcher.match(w)]

    def _get_values(self, action: argparse.Action, arg_strings: list[str]) -> Any:
        if action.option_strings and action.nargs != 0 and any(a in _NO_VALUE for a in arg_strings):
            given = next(a for a in arg_strings if a in _NO_VALUE)
            what = "an empty name" if not given.strip() else repr(given)
            self.error(f"{action.option_strings[0]}: expected a value, got {what}")
        return super()._get_values(action, arg_strings)

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        self._words = [str(a) for a in (args if args is not None else sys.argv[1:])]
        namespace, extras = super().parse_known_args(args, namespace)
        leaf = not any(isinstance(a, argparse._SubParsersAction) for a in self._actions)  # noqa: SLF001
        unknown = [e for e in extras if e.startswith("-") and e not in _NO_VALUE]
        if leaf and unknown:
            self.error(f"unrecognized arguments: {' '.join(extras)}{self._did_you_mean(unknown[0])}")
        return namespace, extras

    def _did_you_mean(self, token: str) -> str:
        import difflib

        name = token.split("=", 1)[0]
        known = [s for a in self._actions if a.help != argparse.SUPPRESS for s in a.option_strings]  # noqa: SLF001
        close = difflib.get_close_matches(name, known, n=1, cutoff=0.75)
        return f" (did you mean {close[0]}?)" if close else ""


def quiet_stdout() -> None:
    """The reader of standard output left: send the rest to /dev/null so later writes cannot fail."""

    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    finally:
        os.close(devnull)


def console(json_mode: bool = False) -> Any:
    """A rich console on stdout (stderr when stdout carries JSON); 100 columns when not a terminal.

    When the reader of standard output leaves (``aerobat … | head``), the console raises
    :class:`BrokenPipeError` once and sends everything after it to /dev/null (rich's default
    would exit the process with status 1, in the middle of whatever it was doing).
    """
    from rich.console import Console

    class _Console(Console):
        def on_broken_pipe(self) -> None:
            quiet_stdout()
            raise BrokenPipeError("standard output was closed")

    stream = sys.stderr if json_mode else sys.stdout
    try:
        tty = stream.isatty()
    except (ValueError, OSError):  # a closed stream
        tty = False
    return _Console(file=stream, highlight=False, markup=False, width=None if tty else 100, soft_wrap=True)


# ------------------------------------------------------------------ parsing


def plural(n: int, word: str, words: str | None = None) -> str:
    """``1 iteration``, ``2 iterations``: a count with its noun."""
    return f"{n} {word if n == 1 else (words or word + 's')}"


def parse_pair(text: str, option: str) -> tuple[float, float]:
    """``Y,Z`` in metres, finite and within ±1000 m."""
    parts = str(text).split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise ConfigError(f"{option} {text!r}: expected two numbers Y,Z in metres") from None
    if len(values) != 2 or not all(math.isfinite(v) and abs(v) <= 1000.0 for v in values):
        raise ConfigError(f"{option} {text!r}: expected two finite numbers Y,Z within ±1000 m")
    return values  # type: ignore[return-value]


def session_ref(text: str) -> str:
    """A session or study reference: a positive id or ``last``."""
    value = text.strip().lower()
    if value == "last" or (value.isdigit() and 1 <= int(value) < 2**63):
        return value
    raise argparse.ArgumentTypeError(f"{text!r}: expected an id (1, 2, …) or 'last'")


def bounded_int(low: int, high: int) -> Any:
    """An argparse type: an integer in [low, high] (no floats, no huge numbers)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: expected an integer in {low} … {high}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{value}: allowed {low} … {high}")
        return value

    parse.metavar = "N"  # type: ignore[attr-defined]
    return parse


def each_of(constraint: Integer) -> tuple[int, ...]:
    """The integers a bounded :class:`~aerobat.core.bounds.Integer` allows, as an option's choices."""
    low, high = constraint.bounds()
    return tuple(range(low, high + 1))


def finite_float(low: float, high: float, unit: str = "") -> Any:
    """An argparse type: a finite number in [low, high]."""
    suffix = f" {unit}" if unit else ""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: expected a number in [{low:g}, {high:g}]{suffix}") from None
        if not (math.isfinite(value) and low <= value <= high):
            raise argparse.ArgumentTypeError(f"{text}: allowed [{low:g}, {high:g}]{suffix}")
        return value

    return parse


# ------------------------------------------------------------------ options


_FLIP_DEFAULTS = {"flips": 3, "max_rate_deg_s": 1800.0, "dims": 3, "axis": "roll", "coast": "min", "ramp_s": 0.1}
_TRANSLATION_DEFAULTS = {"to": "5,5", "final_angle_deg": 0.0}
_OPTION_OF = {"to": "--to-m"}  # options whose name is not their dest's


def add_maneuver_options(p: argparse.ArgumentParser, *, optional: bool = False, families: tuple[str, ...] = (
        "flip", "translation")) -> None:
    """The maneuver family and its options, the design vehicle and the correction matrix.

    Options of the other family are refused (not ignored): their defaults are applied by
    :func:`maneuver_from_args`, which knows the family.
    """
    p.add_argument("maneuver", nargs="?", choices=families,
                   help="maneuver family (required unless --maneuver" + (" or --resume" if optional else "") + ")")
    p.add_argument("--maneuver", dest="maneuver_source", metavar="FILE.toml|package.module:Name", default=None,
                   help="a maneuver file (docs/maneuvers.md) or a Python maneuver, instead of a family (default: none)")
    p.add_argument("--flips", type=bounded_int(*FLIPS.bounds()), default=None,
                   help="number of flips c_N, flip only (default: 3)")
    p.add_argument("--max-rate-deg-s", type=finite_float(*MAX_RATE_DEG_S.bounds(), "deg/s"), default=None,
                   help="coast rate c_pmax [deg/s], flip only (default: 1800)")
    p.add_argument("--dims", type=int, choices=each_of(DIMS), default=None,
                   help="2D with 5 parameters or 3D with 9, flip only (default: 3)")
    p.add_argument("--axis", choices=choices_of(Axis), default=None, help="flip axis, flip only (default: roll)")
    p.add_argument("--coast", choices=choices_of(Coast), default=None,
                   help="coast collective β̲ or β̄, flip only (default: min)")
    p.add_argument("--ramp-s", type=finite_float(*MANEUVER_RAMP_S.bounds(), "s"), default=None,
                   help="thrust ramp-down duration [s], flip only (default: 0.1)")
    p.add_argument("--to-m", dest="to", metavar="Y,Z", default=None,
                   help="target Y,Z [m], translation only (default: 5,5)")
    old_spelling(p, "--to", "to")
    p.add_argument("--final-angle-deg", type=finite_float(-2300.0, 2300.0, "deg"), default=None,
                   help="final roll angle [deg], translation only (default: 0)")
    old_spelling(p, "--final-angle-rad", "final_angle_deg", type=finite_float(-40.0, 40.0, "rad"),
                 convert=math.degrees)
    p.add_argument("--vehicle", default="hummingbird", help="design vehicle: a preset name or a vehicle TOML file")
    p.add_argument("--correction", choices=choices_of(CorrectionKind), default="tsvd",
                   help="right inverse used for C, see docs/results.md")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _apply_family_defaults(args: argparse.Namespace) -> None:
    """Refuse the other family's options; fill in this family's defaults."""
    if args.maneuver is None:  # --maneuver FILE: no family option applies
        given = [name for name in (*_FLIP_DEFAULTS, *_TRANSLATION_DEFAULTS) if getattr(args, name, None) is not None]
        if given:
            options = ", ".join(_OPTION_OF.get(name, "--" + name.replace("_", "-")) for name in given)
            raise ConfigError(f"{options}: does not apply to --maneuver (only to the flip and translation families)")
        return
    mine, other = ((_FLIP_DEFAULTS, _TRANSLATION_DEFAULTS) if args.maneuver == "flip"
                   else (_TRANSLATION_DEFAULTS, _FLIP_DEFAULTS))
    given = [name for name in other if getattr(args, name, None) is not None]
    if given:
        options = ", ".join(_OPTION_OF.get(name, "--" + name.replace("_", "-")) for name in given)
        raise ConfigError(f"{options}: does not apply to a {args.maneuver} (only to a "
                          f"{'translation' if args.maneuver == 'flip' else 'flip'})")
    for name, value in mine.items():
        if getattr(args, name, None) is None:
            setattr(args, name, value)


def add_plant_options(p: argparse.ArgumentParser, *, kinds: tuple[str, ...] | None = None,
                      default: str | None = "arena", feedback: bool = True) -> None:
    """``--plant`` and each plant's settings file, ``--seed``, and ``--feedback`` unless the command fixes it."""
    from aerobat.plants import PLANTS

    choices = kinds or PLANTS.names()
    p.add_argument("--plant", choices=choices, default=default,
                   help="what flies the program" if default is not None else
                   "the plant the design is for: its firmware model with --design-model firmware (default: none, "
                   "a design on the paper's model)")
    for name, spec in PLANTS.items():
        if spec.option is not None and name in choices:
            p.add_argument(spec.option, metavar="FILE.toml",
                          help=f"{name} settings, only with --plant {name} (default: the {name} plant's own)")
    add_tune_option(p, choices)
    p.add_argument("--seed", type=bounded_int(*SEEDS.bounds()), default=0, help="seed of the plant's random generator")
    add_design_model_option(p)
    if not feedback:
        return
    p.add_argument("--feedback", choices=choices_of(FeedbackScheme), default=None,
                   help="what the vehicle's onboard loop mixes into the program: none is the paper's open "
                        "loop, attitude, tracking; see docs/feedback.md (default: the plant's best measured, "
                        "tracking on the arena and Betaflight, none on RotorPy)")


def add_tune_option(p: argparse.ArgumentParser, choices: Sequence[str], *, flown_by: str = "the firmware") -> None:
    """``--tune FILE[:N]`` when one of the plants ``choices`` flies a pilot's tune
    (:attr:`aerobat.plants.PlantSpec.tune`)."""
    from aerobat.plants import PLANTS

    tuned = [name for name in choices if PLANTS.get(name, source="--plant").tune is not None]
    if not tuned:
        return
    p.add_argument("--tune", metavar="FILE[:N]",
                   help=f"a real quad's Betaflight configuration flown by {flown_by}, only with --plant "
                        f"{' or '.join(tuned)}: a CLI diff or dump, or a blackbox log .bbl, .bfl or .txt whose header "
                        f"is used, FILE:N its log N (default: aerobat's own settings)")
    p.add_argument("--tune-log-index", type=bounded_int(1, 10**6), default=None, metavar="N",
                   help=argparse.SUPPRESS)  # before FILE:N; kept so that older command lines still run


def plant_settings_path(args: argparse.Namespace) -> str | None:
    """The settings file given with ``--plant``'s own option (``--arena FILE``); another plant's is refused."""
    from aerobat.plants import PLANTS

    path = None
    for name, spec in PLANTS.items():
        if spec.option is None:
            continue
        given = getattr(args, spec.option.lstrip("-").replace("-", "_"), None)
        if given is None:
            continue
        if not str(given).strip():  # Path("") is the working folder
            raise ConfigError(f"{spec.option}: empty file name")
        if name != args.plant:
            raise ConfigError(f"{spec.option} applies only with --plant {name} (got --plant {args.plant})")
        path = given
    return path


def add_design_model_option(p: argparse.ArgumentParser) -> None:
    """``--design-model``: the model the nominal design runs on."""
    from aerobat.plants import DesignModel

    p.add_argument("--design-model", choices=choices_of(DesignModel), default=None,
                   help="the model the nominal design (p⁰, J, C) runs on: paper (its P rate loop and nominal "
                        "motors) or firmware (the plant's flight controller as configured: rates, RC smoothing, "
                        "PID with feedforward, filters, mixer, throttle path; docs/method.md) (default: firmware "
                        "on betaflight and fc, paper elsewhere)")


def add_db_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--db", metavar="PATH", help="experiment store (default: $AEROBAT_DB or ./aerobat.sqlite)")


# ------------------------------------------------------------------ objects from options


def maneuver_from_args(args: argparse.Namespace, config: Any) -> Any:
    """The maneuver the options describe, designed for ``config``."""
    source = getattr(args, "maneuver_source", None)
    if source is not None and args.maneuver is not None:
        raise ConfigError(f"name either a maneuver family ({args.maneuver}) or --maneuver {source}, not both")
    if source is None and args.maneuver is None:
        raise ConfigError("name a maneuver: a family (flip, translation) or --maneuver "
                          "FILE.toml|FILE.py:Name|package.module:Name")
    _apply_family_defaults(args)
    if source is not None:
        from aerobat.quadrotor.maneuvers import load_maneuver

        return load_maneuver(source, config.vehicle, option="--maneuver")
    if args.maneuver == "flip":
        from aerobat.quadrotor.maneuvers import MultiFlip

        return MultiFlip(vehicle=config.vehicle, flips=args.flips, max_rate_rad_s=math.radians(args.max_rate_deg_s),
                         axis=args.axis, dims=args.dims, coast_collective=args.coast, ramp_collective_s=args.ramp_s)
    from aerobat.quadrotor.maneuvers import translation_maneuver

    return translation_maneuver(config, parse_pair(args.to, "--to-m"),
                                final_angle_rad=math.radians(args.final_angle_deg))


def plant_choice_from_args(args: argparse.Namespace) -> Any:
    """``--plant``, its settings file and ``--seed`` as a :class:`~aerobat.plants.PlantChoice`.

    A settings option of another plant is refused rather than ignored.
    """
    from aerobat.plants import PlantChoice

    path = plant_settings_path(args)
    choice = PlantChoice.from_file(args.plant, path, seed=args.seed, feedback=getattr(args, "feedback", None))
    from aerobat.cli.tune_options import with_tune_from_args

    return with_tune_from_args(args, choice)




def rule_choice_from_args(args: argparse.Namespace) -> Any:
    """``--rule`` and ``--gamma`` as a :class:`~aerobat.core.rules.RuleChoice`."""
    from aerobat.core.rules import RuleChoice, ScheduleChoice, ScheduleKind

    schedule = None
    if args.gamma != "paper":
        try:
            value = float(args.gamma)
        except ValueError:
            raise ConfigError(f"--gamma {args.gamma!r}: use 'paper' or a number in (0, 1]") from None
        if not 0.0 < value <= 1.0:
            raise ConfigError(f"--gamma {args.gamma}: allowed (0, 1]")
        schedule = ScheduleChoice(ScheduleKind.CONSTANT, value=value)
    return RuleChoice.parse(args.rule, schedule=schedule, source="--rule")


# ------------------------------------------------------------------ store and files


def open_store(args: argparse.Namespace, *, create: bool = True, **options: Any) -> Any:
    """The store ``--db`` names, or ``$AEROBAT_DB``, or ``./aerobat.sqlite`` — one resolver for every command."""
    from aerobat.store import Store, default_path

    db = getattr(args, "db", None)
    store = Store(default_path() if db is None else db, create=create,
                  on_wait=lambda message: print(f"aerobat: {message}", file=sys.stderr, flush=True), **options)
    for problem in store.problems:
        print(f"aerobat: warning: {problem}", file=sys.stderr)
    return store


def output_dir(path: str | Path, option: str = "--out") -> Path:
    """Create (if needed) and return an output folder; :class:`OutputError` naming it if that is impossible."""
    if not str(path).strip():  # Path("") is ".": an empty --out would silently write into the working folder
        raise ConfigError(f"{option}: empty folder name")
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputError(f"{option} {out}: exists and is not a folder") from None
    except OSError as exc:
        raise OutputError(f"{option} {out}: cannot create the folder: {exc.strerror or exc}") from None
    return out


def text_path(path: str | Path, option: str) -> str:
    """``path`` as text the store can record; :class:`ConfigError` for a name with bytes that are not UTF-8."""
    text = str(path)
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        shown = text.encode("utf-8", "backslashreplace").decode("ascii", "backslashreplace")
        raise ConfigError(f"{option} {shown}: the name is not valid UTF-8 text, and the store records it; "
                          f"choose another name") from None
    return text


def refuse_overwrite(path: Path, *, store_path: Path | None, force: bool, option: str) -> None:
    """Refuse to write over a store (ever: ``store_path``, the default store, their journals, through any link)
    or over an existing file (unless ``force``); see :func:`aerobat.fileio.check_output`."""
    from aerobat.fileio import check_output

    check_output(path, option=option, force=force, stores=(store_path,) if store_path is not None else ())


def check_outputs(paths: Any, *, stores: Any = (), force: bool = True) -> None:
    """Check every file a command will write into its folder(s), before any work (issue 31 D4/E2).

    ``paths`` maps each file to the option that names it. Existing files are replaced only with
    ``force`` (a folder the command owns); the store is never written, whatever the links.
    """
    from aerobat.fileio import check_output

    for path, option in dict(paths).items():
        check_output(path, option=option, force=force, stores=stores)


def check_plot_files(args: Any, names: tuple[str, ...]) -> Path | None:
    """``--out``'s folder (created) with every file the command writes there checked, and ``--plot FILE``
    checked (never the store whatever the links, never an existing file: issue 31 D2), before any work."""
    from aerobat.fileio import check_output

    folder = output_dir(text_path(args.out, "--out")) if getattr(args, "out", None) is not None else None
    if folder is not None:
        check_outputs({folder / name: "--out" for name in names})
    if getattr(args, "plot", None) is not None:
        check_output(text_path(args.plot, "--plot"), option="--plot", can_force=False)
    return folder


def session_folder(args: Any, store: Any, session_id: int, *, option: str = "--out", explicit: Any = None) -> Path:
    """The folder a session's files go to, created and marked as the session's (:func:`aerobat.fileio.claim_folder`).

    ``explicit`` (or ``--out``) when given, else ``out/<store>-<hash>/session-ID`` (unique per store
    and session; a default folder holding another session's or store's output is never reused).
    A folder the user names is the user's: the files written there replace what is there (never
    the store, never through a link).
    """
    from aerobat.fileio import claim_folder, default_folder, folder_owner

    started = store.session(session_id).started_at
    owner = folder_owner(store.path, "session", session_id, started)
    chosen = explicit if explicit is not None else getattr(args, "out", None)
    named = chosen is not None
    if chosen is None:
        chosen = default_folder(store.path, "session", session_id, started)
    return claim_folder(text_path(chosen, option), owner, option=option, force=named)
