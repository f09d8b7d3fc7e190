"""A seeded fuzz campaign against the ``aerobat`` command line and the library's entry points (issue 19).

    python scripts/fuzz_campaign.py --cli 2000 --api 500 --seed 0 --report out/fuzz.json

The command line is discovered, not listed: the campaign walks ``aerobat.cli.app.build_parser()``
(nested ``benchmark``/``study`` commands included) and draws, for every invocation, a command,
its required positionals and one to four of its options. Values come from what the parser says
about each option: numeric extremes around the bounds of its type (read from the type's
closure), valid and invalid choices, session references, files of every kind (missing, a
folder, ``/dev/null``, read-only, the store itself, garbage TOML, names too long for the file
system, undecodable bytes), and mutants of the examples its help text or default gives.
Every invocation runs in-process (``aerobat.cli.main``) with standard output and error
captured at the Python and the file-descriptor level, in a scratch folder whose store
(``$AEROBAT_DB``) holds two real sessions and a study, and is stopped after ``--budget-s``
(SIGALRM sends SIGINT, as Ctrl-C would → exit 130, counted as *stopped*, not as a failure).

Outcomes: ``ok`` (0), ``bad-input`` (2, one ``aerobat: error:`` line), ``failed`` (1, one
``aerobat: failed:`` line), ``stopped`` (the time budget), and ``INTERNAL``: exit 70, any other
status, an exception or ``SystemExit`` escaping ``main``, a traceback anywhere, a failure
that is not exactly one line, a value the parser must refuse that was not refused with
exit 2 by a message naming the option, or a store that no longer opens afterwards.

The library half calls the public entry points (the ``aerobat`` exports and a few more)
with one or two arguments replaced by wrong types, None, nan/inf, negatives, booleans,
huge integers and wrong-shaped arrays. Success or an :class:`aerobat.errors.AerobatError`
is fine; any other exception is ``INTERNAL``.

The few option names written here only make valid work cheap (a one-flip 2D flip, one
iteration, one worker) or give required options a valid example; if an option is renamed
its hint is simply not applied. Exit status: 0 when nothing was internal, 1 otherwise,
3 if a call could not be stopped (the report then names it).
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import dataclasses
import faulthandler
import inspect
import io
import json
import math
import os
import random
import re
import resource
import shutil
import signal
import sqlite3
import sys
import tempfile
import threading
import time
import traceback
import warnings
from collections import Counter, defaultdict
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.cli.learn import KILL_LINE

CLASSES = ("ok", "bad-input", "failed", "stopped", "INTERNAL")
API_CLASSES = ("ok", "refused", "stopped", "INTERNAL")

# Hints that keep valid work cheap, applied only to commands that have the option and only when
# the campaign did not draw it (unavoidable names: nothing in the parser says what is expensive).
CHEAP = {"--dims": "2", "--flips": "1", "--max-rate-deg-s": "800", "--iterations": "1", "--trials": "2",
         "--vehicles": "1", "--seeds": "1", "--workers": "1", "--rates-deg-s": "800", "--methods": "paper",
         "--plant": "nominal"}
# Valid values drawn for these options are capped: more workers than cores would only oversubscribe.
CAPS = {"--workers": 2}
# Valid examples for required options whose help gives none.
EXAMPLES = {"--to": ["1,1", "2,-1", "0.5,0"], "--y": ["1:1:1", "0:1:2"], "--z": ["1:1:1", "-1:0:2"]}

NUMERIC_EXTREMES = ["0", "-1", "nan", "inf", "-inf", "1e308", str(2**63), "1e23", "abc", "", "1.5", " 3 ", "+2",
                    "0x1f", "1_0", "\u0663", "1e-320", "-0", "-1e308", str(-(2**63)), "١٢", "NaN", "Infinity", "--"]
REFS = ["0", "-1", "last", str(10**12), "abc", "1", "2", "LAST", " 1 ", str(2**63), "99999", "", "1.0", "+1"]
GENERIC_TEXT = ["", " ", "abc", "nan", "inf", "-1", "0", "1e308", str(2**63), "é" * 300, "a,b", ",", ":", "1:2",
                "1:2:3", "1,2", "\t", "x" * 5000, "1,2,3", "::", "0:0:0", "1e308,1e308", "nan,nan", "-0,-0",
                "\udcff\udcfe", "paper", "last", "+", "tsvd+isc", "1:1e9:3", "1,,2", "--", "--", ""]


# ====================================================================== environment


class Fixtures:
    """Files to point commands at, re-created before every invocation (commands may overwrite them)."""

    def __init__(self, root: Path, rng: random.Random) -> None:
        from aerobat import hummingbird, save_vehicle
        from aerobat.plants.arena.params import ArenaParams, save_arena

        self.root = root
        self.dir = root / "fx"
        self.dir.mkdir()
        self.store = root / "store.sqlite"
        self.backup = root / "store.backup"
        self.counter = 0
        examples = Path(__file__).resolve().parents[1] / "src" / "aerobat" / "examples"
        self.contents: dict[Path, bytes] = {}
        self.kinds: dict[str, list[Path]] = defaultdict(list)

        def keep(name: str, data: bytes, *kinds: str) -> Path:
            path = self.dir / name
            self.contents[path] = data
            for kind in kinds:
                self.kinds[kind].append(path)
            return path

        for source in sorted(examples.glob("*.toml")):
            keep(source.name, source.read_bytes(), "program", "toml", "valid")
        for source in sorted((examples / "maneuvers").glob("*.toml")):
            keep("maneuver_" + source.name, source.read_bytes(), "maneuver", "toml", "valid")
        keep("custom_maneuver.py", (examples / "custom_maneuver.py").read_bytes(), "maneuver", "valid")
        scratch = root / "scratch"
        scratch.mkdir()
        save_vehicle(hummingbird(), scratch / "v.toml")
        save_arena(ArenaParams(), scratch / "a.toml")
        keep("vehicle.toml", (scratch / "v.toml").read_bytes(), "vehicle", "toml", "valid")
        keep("arena.toml", (scratch / "a.toml").read_bytes(), "arena", "toml", "valid")
        shutil.rmtree(scratch)
        keep("plain.txt", b"x\n", "existing")
        keep("garbage.toml", bytes(rng.randrange(256) for _ in range(3000)), "garbage", "toml")
        keep("wrong.toml", b'[vehicle]\nmass_kg = "heavy"\nzz = 1\n', "garbage", "toml")
        keep("deep.toml", b"a = " + b"[" * 5000 + b"]" * 5000 + b"\n", "garbage", "toml")
        keep("empty.toml", b"", "garbage", "toml")
        keep("nonfinite.toml", b"x = nan\ny = inf\n", "garbage", "toml")
        keep("bom.toml", b"\xef\xbb\xbf" + self.contents[self.dir / "single_flip.toml"], "garbage", "toml")
        # valid files with one number replaced by an extreme
        valid_toml = [p for p in self.kinds["toml"] if p in self.kinds["valid"]]
        for k in range(14):
            base = rng.choice(valid_toml)
            text = self.contents[base].decode()
            numbers = list(re.finditer(r"(?<![\w.])-?\d+(\.\d+)?([eE][-+]?\d+)?(?![\w.])", text))
            if not numbers:
                continue
            hit = rng.choice(numbers)
            extreme = rng.choice(["1e300", "-1e300", "nan", "inf", "-inf", "0", "-1", "1e-300", "123456789012",
                                  "9223372036854775807", "-9223372036854775808", "0.0"])
            mutant = text[:hit.start()] + extreme + text[hit.end():]
            kind = next(k for k in ("program", "maneuver", "vehicle", "arena") if base in self.kinds[k])
            keep(f"mutant{k}_{base.name}", mutant.encode(), kind, "toml", "mutant")
        keep("ro.toml", self.contents[self.dir / "vehicle.toml"], "vehicle", "readonly")
        keep("飞行.toml", self.contents[self.dir / "single_flip.toml"], "program", "unicode")
        keep("with space.toml", self.contents[self.dir / "hover.toml"], "program")
        keep("random.sqlite", bytes((k * 131 + 7) % 256 for k in range(5000)), "db", "garbage")
        self.adir = self.dir / "adir"
        self.rodir = self.dir / "rodir"
        self.readonly = [self.dir / "ro.toml"]
        self.restore()
        foreign = self.dir / "foreign.sqlite"
        conn = sqlite3.connect(foreign)
        conn.execute("CREATE TABLE t (x)")
        conn.commit()
        conn.close()
        self.contents[foreign] = foreign.read_bytes()
        self.kinds["db"].append(foreign)

    def restore(self) -> None:
        """Put every fixture back as it was (commands may write over them, legitimately or not)."""
        for path in (self.adir, self.rodir):
            if path.exists() and not path.is_dir():
                path.unlink()
            path.mkdir(exist_ok=True)
        self.rodir.chmod(0o555)
        for path, data in self.contents.items():
            try:
                if path.is_dir() and not path.is_symlink():
                    shutil.rmtree(path)
                if not path.exists() or path.read_bytes() != data:
                    if path.exists():
                        path.chmod(0o644)
                    path.write_bytes(data)
            except OSError:
                continue
        for path in self.readonly:
            path.chmod(0o444)

    def fresh(self, suffix: str = "") -> Path:
        self.counter += 1
        return self.root / "new" / f"n{self.counter}{suffix}"

    def path_pool(self, rng: random.Random, kinds: set[str]) -> str:
        """A path: of the kinds asked for (half the time), else of any kind."""
        preferred = [p for k in kinds for p in self.kinds.get(k, [])]
        if preferred and rng.random() < 0.5:
            return str(rng.choice(preferred))
        choice = rng.randrange(19)
        return str([
            lambda: self.dir / "missing" / "none.toml",
            lambda: self.dir / "none.toml",
            lambda: self.adir,
            lambda: Path("/dev/null"),
            lambda: self.dir / "ro.toml",
            lambda: self.rodir / "x.out",
            lambda: self.store,
            lambda: self.dir / "plain.txt",
            lambda: rng.choice(self.kinds["garbage"]),
            lambda: self.dir / ("飞" * 100 + ".toml"),  # 300 bytes: too long for a file name
            lambda: self.dir / ("é" * 60 + ".png"),
            lambda: self.fresh(rng.choice(["", ".png", ".toml", ".csv", ".json", ".sqlite", ".svg", ".pdf"])),
            lambda: self.dir / "plain.txt" / "sub",
            lambda: self.dir / "\udcff\udcfe.toml",
            lambda: self.dir / "new\nline.toml",
            lambda: rng.choice(self.kinds["valid"]),
            lambda: Path("/proc/version"),
            lambda: Path("/proc/nope/x.sqlite"),
            lambda: Path(rng.choice(["", ".", "..", "~", "-", "out", "aerobat.sqlite"])),
        ][choice]())

    def store_ok(self, *, deleted_one: bool = False) -> str | None:
        """None if the store still opens and holds its sessions, else what is wrong.

        ``deleted_one``: a successful ``aerobat delete --yes`` ran, so one of them may be gone (by design).
        """
        from aerobat.store import Store

        try:
            with Store(self.store, create=False) as store:
                ids = [s.id for s in store.list_sessions()]
                if len({1, 2} - set(ids)) > (1 if deleted_one else 0):
                    return f"sessions 1 and 2 are gone (ids {ids[:5]})"
        except Exception as exc:  # noqa: BLE001 - any failure to open it is the finding
            return f"{type(exc).__name__}: {exc}"
        return None

    def backup_store(self) -> None:
        shutil.copyfile(self.store, self.backup)

    def restore_store(self) -> None:
        for suffix in ("-wal", "-shm", "-journal"):
            Path(f"{self.store}{suffix}").unlink(missing_ok=True)
        if self.store.is_dir():
            shutil.rmtree(self.store)
        shutil.copyfile(self.backup, self.store)


class Alarm:
    """After the budget, SIGALRM sends SIGINT (Ctrl-C) to this process; a hard watchdog ends calls that hang."""

    def __init__(self) -> None:
        self.armed = False
        self.fired = 0
        self.previous = signal.signal(signal.SIGALRM, self._handle)
        # started in the background by a shell without job control, the process inherits SIGINT ignored (and
        # Python then installs no KeyboardInterrupt): the budget's Ctrl-C would do nothing and every command
        # that waits for one (browse, a long learn) would look hung
        if threading.current_thread() is threading.main_thread():
            self.previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)

    def _handle(self, signum: int, frame: Any) -> None:
        if not self.armed:
            return
        self.fired += 1
        signal.setitimer(signal.ITIMER_REAL, 30.0)  # a command that does not stop gets a second Ctrl-C in 30 s
        os.kill(os.getpid(), signal.SIGINT)  # what Ctrl-C does: the command's own SIGINT handling is exercised

    @contextlib.contextmanager
    def budget(self, seconds: float, on_hang: Callable[[], None]) -> Iterator[None]:
        self.fired = 0
        watchdog = threading.Timer(seconds + 180.0, on_hang)
        watchdog.daemon = True
        watchdog.start()
        self.armed = True
        signal.setitimer(signal.ITIMER_REAL, seconds)
        try:
            yield
        finally:
            self.armed = False
            signal.setitimer(signal.ITIMER_REAL, 0)
            watchdog.cancel()

    def close(self) -> None:
        signal.signal(signal.SIGALRM, self.previous)
        if hasattr(self, "previous_int"):
            signal.signal(signal.SIGINT, self.previous_int)


@contextlib.contextmanager
def captured_fds() -> Iterator[dict[str, str]]:
    """File descriptors 1 and 2 into files (what C code, numba or a solver prints bypasses sys.stdout)."""
    result: dict[str, str] = {}
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    files = {fd: tempfile.TemporaryFile() for fd in (1, 2)}
    try:
        for fd, handle in files.items():
            os.dup2(handle.fileno(), fd)
        yield result
    finally:
        for fd in (1, 2):
            os.dup2(saved[fd], fd)
            os.close(saved[fd])
            files[fd].seek(0)
            result["out" if fd == 1 else "err"] = files[fd].read().decode("utf-8", "replace")
            files[fd].close()


# ====================================================================== the command line, introspected


@dataclasses.dataclass
class Option:
    names: list[str]  # option strings; empty for a positional
    dest: str
    action: argparse.Action

    @property
    def positional(self) -> bool:
        return not self.names

    @property
    def label(self) -> str:
        return self.names[-1] if self.names else self.dest

    @property
    def flag(self) -> bool:
        return self.action.nargs == 0

    @property
    def required(self) -> bool:
        return bool(self.action.required) if self.names else self.action.nargs not in ("?", "*")

    @property
    def arity(self) -> int:
        """How many values the option takes after its name (``nargs=2`` options such as --window-s take two)."""
        return self.action.nargs if isinstance(self.action.nargs, int) and self.action.nargs > 1 else 1

    def mentions(self) -> list[str]:
        """What an error message about this option may call it."""
        out = list(self.names) + [self.dest]
        if self.action.metavar:
            out.append(str(self.action.metavar))
        return out

    def refuses(self, text: str) -> bool:
        """Would the parser refuse this value (``--`` or empty for an option, its type raises, or it is not
        among the choices)?"""
        if text in ("--", "") and not self.positional and not self.flag:
            return True  # issue 31 S4/I5: `--output=--`, `--output ''` are bad input, never stdout or ignored
        value: Any = text
        if self.action.type is not None:
            try:
                value = self.action.type(text)
            except (argparse.ArgumentTypeError, TypeError, ValueError):
                return True
        return self.action.choices is not None and value not in self.action.choices

    def bounds(self) -> tuple[float, float] | None:
        if self.action.type is None:
            return None
        try:
            names = inspect.getclosurevars(self.action.type).nonlocals
        except (TypeError, ValueError):
            return None
        low, high = names.get("low"), names.get("high")
        if isinstance(low, int | float) and isinstance(high, int | float):
            return low, high
        return None

    def is_ref(self) -> bool:
        return self.action.type is not None and not self.refuses("last") and self.refuses("lastx")

    def words(self) -> str:
        return " ".join([*self.names, self.dest, str(self.action.metavar or ""), self.action.help or ""]).lower()

    def path_kinds(self) -> set[str] | None:
        """The kinds of files this option takes, or None if it does not look like it takes a file."""
        words = self.words()
        if not re.search(r"file|folder|\bdir\b|path|toml|\bdb\b|\bstore\b|\bout\b|output|plot|where to", words):
            return None
        kinds = {k for k in ("program", "maneuver", "vehicle", "arena") if k in words}
        if re.search(r"\bdb\b|\bstore\b|database", words):
            kinds.add("db")
        return kinds

    def examples(self) -> list[str]:
        """Valid-looking values from the default and the help text ("default 5,5", "e.g. 1,2,3,4")."""
        found: list[str] = []
        if isinstance(self.action.default, str) and self.action.default:
            found.append(self.action.default)
        for match in re.finditer(r"(?:default|e\.g\.)[: ]+([^\s;)]+)", self.action.help or ""):
            word = match.group(1).rstrip(".,")
            if word and word not in ("none", "all", "off", "the", "a", "an") and not word.startswith("$"):
                found.append(word)
        return found + [e for name in self.names for e in EXAMPLES.get(name, [])]


@dataclasses.dataclass
class Command:
    path: tuple[str, ...]
    parser: argparse.ArgumentParser
    group: bool = False

    @property
    def name(self) -> str:
        return " ".join(self.path)

    @property
    def options(self) -> list[Option]:
        out = []
        for action in self.parser._actions:  # noqa: SLF001 - argparse has no public list of its actions
            if isinstance(action, argparse._HelpAction | argparse._VersionAction | argparse._SubParsersAction):  # noqa: SLF001
                continue
            out.append(Option(list(action.option_strings), action.dest, action))
        return out


def commands(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> list[Command]:
    """Every command the parser knows, nested groups (``benchmark``, ``study``) included."""
    groups = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]  # noqa: SLF001
    if not groups:
        return [Command(path, parser)]
    out = [Command(path, parser, group=True)] if path else []
    seen: set[int] = set()
    for group in groups:
        for name, sub in group.choices.items():
            if id(sub) not in seen:
                seen.add(id(sub))
                out += commands(sub, (*path, name))
    return out


def mutate_text(rng: random.Random, text: str) -> str:
    numbers = list(re.finditer(r"-?\d+(\.\d+)?", text))
    choice = rng.randrange(8)
    if numbers and choice < 4:
        hit = rng.choice(numbers)
        extreme = rng.choice(["nan", "inf", "-inf", "1e308", "0", "-1", str(2**63), "abc", "", "1e23", "-0", "1e-320",
                              "1000000"])
        return text[:hit.start()] + extreme + text[hit.end():]
    return [lambda: text.replace(",", ";").replace(":", ";"), lambda: text + ",", lambda: "," + text,
            lambda: ",".join([text] * rng.randint(2, 40)), lambda: text.upper(), lambda: text + ":" + text,
            lambda: text[: len(text) // 2], lambda: text.replace(",", ",,")][rng.randrange(8)]()


def draw_value(rng: random.Random, opt: Option, fx: Fixtures) -> str:
    """A value for ``opt``: valid, at or past its bounds, of the wrong kind, or a path of any kind."""
    action = opt.action
    kinds = opt.path_kinds()
    if opt.is_ref():
        return rng.choice(REFS)
    if action.type is not None or action.choices is not None:
        values = list(NUMERIC_EXTREMES) if action.type is not None else ["abc", "", "é", "1", "none"]
        bounds = opt.bounds()
        if bounds is not None:
            low, high = bounds
            if opt.refuses("1.5"):
                values += [str(int(low) - 1), str(int(low)), str(int(high)), str(int(high) + 1),
                           str((int(low) + int(high)) // 2), str(int(low) + 1)] * 2
            else:
                step = max(abs(low), abs(high), 1.0) * 1e-6
                values += [repr(low - step), repr(low), repr(high), repr(high + step), repr((low + high) / 2),
                           repr(math.nextafter(low, -math.inf)), repr(math.nextafter(high, math.inf))] * 2
        if action.choices is not None:
            choices = [str(c) for c in action.choices]
            values += choices * 3 + [c.upper() for c in choices] + [c + " " for c in choices] + [choices[0][:-1]]
        return rng.choice(values)
    examples = opt.examples()
    roll = rng.random()
    if kinds is not None and roll < 0.75:
        return fx.path_pool(rng, kinds)
    if kinds is None and roll < 0.2:
        return fx.path_pool(rng, set())
    if examples and rng.random() < 0.6:
        example = rng.choice(examples)
        return example if rng.random() < 0.4 else mutate_text(rng, example)
    return rng.choice(GENERIC_TEXT)


def valid_value(rng: random.Random, opt: Option, fx: Fixtures) -> str | None:
    """A value argparse accepts (and that names a sensible file), or None if none is known."""
    action = opt.action
    if opt.is_ref():
        return rng.choice(["1", "2", "last"])
    if action.choices is not None:
        return str(rng.choice(list(action.choices)))
    bounds = opt.bounds()
    if bounds is not None:
        low, high = bounds
        if opt.refuses("1.5"):
            return str(rng.choice([int(low), int(low) + 1, min(int(high), int(low) + rng.randint(0, 5))]))
        return repr(low + (high - low) * rng.random() ** 3)
    kinds = opt.path_kinds()
    if kinds and "db" in kinds:
        return str(rng.choice([fx.store, fx.store, fx.fresh(".sqlite")]))
    if kinds:
        matching = [p for k in kinds for p in fx.kinds.get(k, []) if p in fx.kinds["valid"]]
        if matching:
            return str(rng.choice(matching))
    if kinds is not None and rng.random() < 0.7:
        return str(fx.fresh(rng.choice(["", "", ".png", ".svg", ".pdf", ".toml", ".csv", ".json"])))
    examples = [e for e in opt.examples() if not opt.refuses(e)]
    return rng.choice(examples) if examples else None


def negative_rewritten(value: str) -> bool:
    """``aerobat.cli.app`` turns ``--opt -2,4`` into ``--opt=-2,4`` when the value looks like a number."""
    return len(value) > 1 and value[0] == "-" and (value[1].isdigit() or value[1] == ".")


def read_as_option(value: str) -> bool:
    """Would argparse take this word for an option rather than a value? ("-", "-1" and "- x" are values.)"""
    if len(value) < 2 or value[0] != "-" or " " in value:
        return False
    return not re.fullmatch(r"-\d+|-\d*\.\d+", value)


@dataclasses.dataclass
class Invocation:
    argv: list[str]
    command: str
    bad: list[str]  # what makes it bad input by construction (names an error message may use)
    why_bad: str = ""


def draw_invocation(rng: random.Random, cmd: Command, fx: Fixtures, all_cmds: list[Command]) -> Invocation:
    if cmd.group:  # a command group without its subcommand, or with an unknown one
        if rng.random() < 0.5:
            return Invocation(list(cmd.path), cmd.name, ["COMMAND", "BENCHMARK", "STUDY", *cmd.path],
                              "no subcommand")
        word = rng.choice(["zz", "", "MAP", "help", "-x"])
        return Invocation([*cmd.path, word], cmd.name, [word or "''", "invalid choice", "required", *cmd.path],
                          "unknown subcommand")
    options = cmd.options
    fuzzable = [o for o in options if not (o.positional and o.required)]
    chosen: list[Option] = rng.sample(fuzzable, min(len(fuzzable), rng.choice([1, 1, 2, 2, 3, 4])))
    tokens: list[list[str]] = []
    positional_tokens: list[str] = []
    bad: list[str] = []
    why: list[str] = []

    def add_value(opt: Option, value: str) -> None:
        if opt.positional:
            positional_tokens.append(value)
            if opt.refuses(value):
                bad.extend(opt.mentions())
                why.append(f"{opt.label} {value!r}")
            return
        if opt.flag:
            tokens.append([opt.names[-1]])
            return
        name = rng.choice(opt.names)
        if opt.arity > 1:  # `--window-s A B`: the same value n times; one value alone is refused, naming the option
            if read_as_option(value) or rng.random() < 0.1:
                tokens.append([f"{name}={value}"])
                bad.extend(opt.mentions())
                why.append(f"{name} {value!r} (one value of {opt.arity})")
                return
            tokens.append([name, *([value] * opt.arity)])
            if opt.refuses(value):
                bad.extend(opt.mentions())
                why.append(f"{name} {value!r}")
            return
        as_option = read_as_option(value) and not negative_rewritten(value)
        if as_option and rng.random() < 0.5:
            tokens.append([f"{name}={value}"])
        elif as_option:
            tokens.append([name, value])  # argparse reads it as an option: "expected one argument"
            bad.extend(opt.mentions())
            why.append(f"{name} {value!r} (looks like an option)")
            return
        else:
            tokens.append([f"{name}={value}"] if rng.random() < 0.25 else [name, value])
        if opt.refuses(value):
            bad.extend(opt.mentions())
            why.append(f"{name} {value!r}")

    mostly_valid = rng.random() < 0.35  # one odd value among valid ones reaches deeper than many
    for opt in options:  # required (and most optional) positionals and required options: valid most of the time
        wanted = opt.required or (opt.positional and rng.random() < 0.8)
        if not wanted or opt in chosen:
            continue
        if rng.random() < 0.85:
            value = valid_value(rng, opt, fx)
            if value is not None:
                add_value(opt, value)
                continue
        if rng.random() < 0.3:  # left out (argparse says so if it is required)
            if opt.required:
                bad.extend(opt.mentions())
                why.append(f"{opt.label} missing")
            continue
        chosen.append(opt)
    odd = rng.randrange(len(chosen)) if chosen else -1
    for index, opt in enumerate(chosen):
        if opt.positional:
            value = valid_value(rng, opt, fx) if rng.random() < 0.6 else draw_value(rng, opt, fx)
            if value is None or read_as_option(value):
                continue  # argparse would read it as an option; not a value for this positional
            add_value(opt, value)
            continue
        value = "" if opt.flag else None
        if value is None and rng.random() < (0.9 if mostly_valid and index != odd else 0.4):
            value = valid_value(rng, opt, fx)
        if value is None:
            value = draw_value(rng, opt, fx)
        if opt.label in CAPS and not opt.refuses(value):
            with contextlib.suppress(ValueError):
                value = str(min(int(value), CAPS[opt.label]))
        add_value(opt, value)
        if rng.random() < 0.04:  # the same option twice: the last one counts
            add_value(opt, "" if opt.flag else draw_value(rng, opt, fx))
    if rng.random() < 0.85:  # keep valid work small
        given = {t.split("=")[0] for chunk in tokens for t in chunk[:1]}
        for opt in options:
            hint = next((CHEAP[n] for n in opt.names if n in CHEAP), None)
            if hint is None or any(n in given for n in opt.names) or opt.refuses(hint):
                continue
            if opt.label == "--plant" and rng.random() < 0.4:
                continue
            tokens.append([opt.names[-1], hint])
    if rng.random() < 0.03:  # an option no command has
        word = rng.choice(["--zz", "--jsonn", "-q", "--db2"])
        tokens.append([word])
        bad.append(word)
        why.append(f"{word} unknown")
    rng.shuffle(tokens)
    flat = [t for chunk in tokens for t in chunk]
    at = rng.choice([0, len(flat)])
    argv = [*cmd.path, *flat[:at], *positional_tokens, *flat[at:]]
    return Invocation(argv, cmd.name, bad, "; ".join(why))


# ====================================================================== running and judging


@dataclasses.dataclass
class Outcome:
    klass: str
    reason: str
    code: int | None
    out: str
    err: str
    seconds: float


def run_cli(argv: list[str], alarm: Alarm, budget_s: float, on_hang: Callable[[], None]) -> tuple[Any, ...]:
    from aerobat.cli import main

    out_bytes, err_bytes = io.BytesIO(), io.BytesIO()
    # what the real streams do: stdout is strict UTF-8, stderr escapes what it cannot encode
    out = io.TextIOWrapper(out_bytes, encoding="utf-8", errors="strict", write_through=True)
    err = io.TextIOWrapper(err_bytes, encoding="utf-8", errors="backslashreplace", write_through=True)
    how, code, escaped = "returned", None, ""
    start = time.perf_counter()
    with captured_fds() as fds:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                with alarm.budget(budget_s, on_hang):
                    try:
                        code = main(argv)
                    except KeyboardInterrupt:
                        how = "stopped"
            except KeyboardInterrupt:
                how = "stopped"
            except SystemExit as exc:
                how, code = "SystemExit", exc.code if isinstance(exc.code, int) else None
                escaped = f"SystemExit({exc.code!r}) escaped main()"
            except BaseException as exc:  # noqa: BLE001 - anything escaping main() is the finding
                how = "raised"
                escaped = "".join(traceback.format_exception(exc))[-3000:]
        fired = alarm.fired
    seconds = time.perf_counter() - start
    stdout = out_bytes.getvalue().decode("utf-8", "replace") + fds.get("out", "")
    stderr = err_bytes.getvalue().decode("utf-8", "replace") + fds.get("err", "")
    return how, code, stdout, stderr, escaped, fired, seconds


def judge(inv: Invocation, how: str, code: int | None, out: str, err: str, escaped: str, fired: int) -> tuple[str, str]:
    """(class, reason) of one invocation."""
    if "Traceback" in out or "Traceback" in err:
        return "INTERNAL", "a traceback was printed"
    if how == "raised":
        return "INTERNAL", "an exception escaped main()"
    if how == "SystemExit":
        return "INTERNAL", escaped
    if how == "stopped" or (fired and code is not None and code >= 128):
        if inv.bad:
            return "INTERNAL", f"bad input ({inv.why_bad}) was not refused before running (stopped by the budget)"
        return "stopped", "time budget"
    if code == 0:
        if inv.bad:
            return "INTERNAL", f"bad input ({inv.why_bad}) accepted with exit 0"
        return "ok", ""
    if code in (1, 2):
        lines = err.splitlines()
        # the budget's Ctrl-C was the flight controller's kill: its line at once (written to the descriptor, so the
        # capture may put it second), then the session's
        others = [line for line in lines if line != KILL_LINE]
        if fired and code == 1 and len(lines) == 2 and len(others) == 1 and \
                others[0].startswith("aerobat: failed: stopped: "):
            return "stopped", "time budget (the flight controller's kill)"
        prefix = "aerobat: error: " if code == 2 else "aerobat: failed: "
        if len(lines) != 1:
            return "INTERNAL", f"exit {code} with {len(lines)} lines on stderr (expected one)"
        if not lines[0].startswith(prefix):
            return "INTERNAL", f"exit {code}: the message does not start with {prefix.strip()!r}"
        if inv.bad and code != 2:
            return "INTERNAL", f"bad input ({inv.why_bad}) gave exit {code}, not 2"
        if inv.bad and not any(name and name in lines[0] for name in inv.bad):
            return "INTERNAL", f"bad input ({inv.why_bad}): the message names none of {sorted(set(inv.bad))}"
        return ("bad-input" if code == 2 else "failed"), ""
    if code == 70:
        return "INTERNAL", "exit 70 (internal error)"
    return "INTERNAL", f"exit status {code}"


class Campaign:
    def __init__(self, *, seed: int, budget_s: float, root: Path, progress: Callable[[str], None]) -> None:
        self.seed = seed
        self.budget_s = budget_s
        self.root = root
        self.say = progress
        self.rng = random.Random(seed)
        self.started = time.perf_counter()
        self.current: dict[str, Any] = {}
        self.report: dict[str, Any] = {
            "seed": seed, "budget_s": budget_s, "seeding": [],
            "cli": {"requested": 0, "counts": Counter(), "by_command": defaultdict(Counter), "internal": [],
                    "store_restored": 0},
            "api": {"requested": 0, "counts": Counter(), "by_target": defaultdict(Counter), "internal": [],
                    "warned": 0},
        }
        self.report_path: Path | None = None
        self.alarm = Alarm()

    def on_hang(self) -> None:
        """A call could not be stopped: write what is known, name the call, and end the process."""
        self.report["hung"] = self.current
        self.report["wall_s"] = round(time.perf_counter() - self.started, 1)
        self.write_report()
        os.write(self.say_fd, f"fuzz: a call did not stop within its budget: {self.current}\n".encode())
        os.write(self.say_fd, b"fuzz: where every thread was:\n")
        faulthandler.dump_traceback(self.say_fd, all_threads=True)
        os._exit(3)

    say_fd = 2

    def write_report(self) -> None:
        if self.report_path is None:
            return
        self.report_path.parent.mkdir(parents=True, exist_ok=True)
        self.report_path.write_text(json.dumps(self.report, indent=1, default=str, ensure_ascii=True,
                                               sort_keys=False))

    # ------------------------------------------------------------------ setup

    def seed_store(self, fx: Fixtures) -> None:
        """Two real sessions and a study in the store, and everything compiled once (without a budget)."""
        db = str(fx.store)
        small = ["flip", "--dims", "2", "--flips", "1", "--max-rate-deg-s", "800"]
        hover = str(fx.dir / "hover.toml")
        for argv in (["learn", *small, "--plant", "nominal", "--iterations", "2", "--db", db],
                     ["learn", *small, "--plant", "arena", "--seed", "1", "--iterations", "2", "--db", db],
                     ["benchmark", "map", "--y", "1:1:1", "--z", "1:1:1", "--workers", "1", "--db", db],
                     ["simulate", hover, "--mode", "sampled"], ["design", "translation"], ["plot", "1", "--db", db],
                     ["replay", "2", "--db", db], ["fly", hover, "--plant", "rotorpy"]):
            how, code, _, err, _, _, seconds = run_cli(argv, self.alarm, 600.0, self.on_hang)
            self.report["seeding"].append({"argv": argv, "exit": code, "how": how, "seconds": round(seconds, 2),
                                           "stderr": err[-500:]})
            self.say(f"fuzz: seed `aerobat {' '.join(argv)}` → {code if how == 'returned' else how} "
                     f"({seconds:.1f} s)")

    # ------------------------------------------------------------------ the command line

    def run_cli_phase(self, n: int, fx: Fixtures) -> None:
        from aerobat.cli.app import build_parser

        cmds = commands(build_parser())
        weights = [0.3 if c.group else 1.0 for c in cmds]
        report = self.report["cli"]
        report["requested"] = n
        report["commands"] = [c.name for c in cmds]
        for k in range(n):
            cmd = self.rng.choices(cmds, weights)[0]
            inv = draw_invocation(self.rng, cmd, fx, cmds)
            fx.restore()
            self.current = {"phase": "cli", "index": k, "argv": inv.argv}
            how, code, out, err, escaped, fired, seconds = run_cli(inv.argv, self.alarm, self.budget_s, self.on_hang)
            klass, reason = judge(inv, how, code, out, err, escaped, fired)
            deleted = inv.command == "delete" and code == 0 and "--yes" in inv.argv
            damage = fx.store_ok(deleted_one=deleted)
            if deleted and damage is None:
                fx.restore_store()  # the deletion was asked for; the next invocations get both sessions back
            if damage is not None:
                report["store_restored"] += 1
                fx.restore_store()
                if klass != "INTERNAL":
                    klass, reason = "INTERNAL", f"the store no longer opens afterwards: {damage}"
            report["counts"][klass] += 1
            report["by_command"][inv.command][klass] += 1
            if klass == "INTERNAL":
                report["internal"].append({"index": k, "argv": inv.argv, "exit": code, "how": how, "reason": reason,
                                           "bad": inv.why_bad, "stderr": err[-3000:], "stdout": out[-800:],
                                           "escaped": escaped, "seconds": round(seconds, 2)})
                shown = " ".join(repr(a) if len(a) < 80 else repr(a[:60]) + f"…({len(a)})" for a in inv.argv)
                self.say(f"fuzz: INTERNAL cli #{k}: {reason}: aerobat {shown}\n  "
                         + (err.strip().splitlines() or [""])[-1][:400])
            if (k + 1) % 50 == 0 or k + 1 == n:
                self.progress("cli", k + 1, n, report["counts"])

    # ------------------------------------------------------------------ the library

    def run_api_phase(self, n: int, fx: Fixtures) -> None:
        from aerobat.errors import AerobatError

        ctx = ApiContext(fx, self.root)
        targets = api_targets(ctx)
        report = self.report["api"]
        report["requested"] = n
        report["targets"] = [t.name for t in targets]
        order: list[ApiTarget] = []
        for k in range(n):
            if not order:
                order = list(targets)
                self.rng.shuffle(order)
            target = order.pop()
            kwargs, changed = target.draw(self.rng, ctx)
            shown = {key: _short(kwargs[key]) for key in changed}
            self.current = {"phase": "api", "index": k, "target": target.name, "changed": shown}
            klass, reason, detail = "ok", "", ""
            with warnings.catch_warnings(record=True) as caught, contextlib.ExitStack() as stack:
                warnings.simplefilter("always")
                stack.callback(ctx.cleanup, kwargs)
                try:
                    with self.alarm.budget(self.budget_s, self.on_hang):
                        try:
                            result = target.fn(**kwargs)
                            ctx.cleanup(result)
                        except KeyboardInterrupt:
                            klass, reason = "stopped", "time budget"
                except KeyboardInterrupt:
                    klass, reason = "stopped", "time budget"
                except AerobatError as exc:
                    klass, reason = "refused", f"{type(exc).__name__}: {exc}"[:300]
                except BaseException as exc:  # noqa: BLE001 - anything else is the finding
                    klass, reason = "INTERNAL", f"{type(exc).__name__}: {exc}"[:600]
                    detail = "".join(traceback.format_exception(exc)[-6:])[-4000:]
                if caught:
                    report["warned"] += 1
            report["counts"][klass] += 1
            report["by_target"][target.name][klass] += 1
            if klass == "INTERNAL":
                report["internal"].append({"index": k, "target": target.name, "changed": shown, "error": reason,
                                           "traceback": detail})
                self.say(f"fuzz: INTERNAL api #{k}: {target.name}({shown}): {reason[:300]}")
            if (k + 1) % 50 == 0 or k + 1 == n:
                self.progress("api", k + 1, n, report["counts"], API_CLASSES)

    def progress(self, phase: str, done: int, total: int, counts: Counter,
                 classes: tuple[str, ...] = CLASSES) -> None:
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024
        self.say(f"fuzz: {phase} {done}/{total}  elapsed {time.perf_counter() - self.started:.0f} s  "
                 + "  ".join(f"{c}={counts.get(c, 0)}" for c in classes) + f"  (max rss {rss} MB)")


def _short(value: Any) -> str:
    try:
        text = repr(value)
    except Exception as exc:  # noqa: BLE001 - a value whose repr fails is still reported
        text = f"<{type(value).__name__}: repr failed: {exc}>"
    return text if len(text) <= 200 else text[:200] + f"… ({len(text)} chars)"


# ====================================================================== the library's entry points


class ApiContext:
    """Valid objects to start every call from, built once."""

    def __init__(self, fx: Fixtures, root: Path) -> None:
        import aerobat as A
        from aerobat.quadrotor.maneuvers import load_maneuver_file

        self.fx = fx
        self.root = root
        self.config = A.hummingbird()
        self.flip = A.MultiFlip(vehicle=self.config.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
        self.translation = A.translation_maneuver(self.config, (1.0, 1.0))
        self.design = A.design(self.flip, A.NominalModel(self.config))
        self.program = A.load_program(fx.dir / "single_flip.toml")
        self.db = root / "api.sqlite"
        shutil.copyfile(fx.store, self.db)
        staged = load_maneuver_file(fx.dir / "maneuver_flip_sideways.toml", self.config.vehicle)
        self.specs = [self.flip.spec(), self.translation.spec(), staged.spec()]
        from aerobat.experiments.reports import session_json
        from aerobat.store import Store

        with Store(self.db, create=False) as store:
            self.session_json = json.loads(json.dumps(session_json(store, 1, full=True), default=str))
        self.stores: list[Any] = []

    def store(self) -> Any:
        from aerobat.store import Store

        store = Store(self.db)
        self.stores.append(store)
        return store

    def cleanup(self, value: Any) -> None:
        from aerobat.store import Store

        values = value.values() if isinstance(value, dict) else [value]
        for v in values:
            for candidate in (v, getattr(v, "store", None)):
                if isinstance(candidate, Store):
                    with contextlib.suppress(Exception):
                        candidate.close()
        for store in self.stores:
            with contextlib.suppress(Exception):
                store.close()
        self.stores.clear()


class _Opaque:
    def __repr__(self) -> str:
        return "<object>"


GENERIC_API: list[Any] = [None, True, False, 0, -1, 1, 2**63, 10**400, -(10**400), math.nan, math.inf, -math.inf,
                          1e308, -1e308, 5e-324, "abc", "", "1", [], [1.0], (1, 2), {}, {"a": 1}, b"x",
                          complex(1, 2), np.float64(math.nan), np.int64(-(2**62)), np.array([]), np.zeros((2, 2)),
                          np.full(5, math.nan), _Opaque(), Path("/nonexistent/x.toml")]


def mutants(value: Any, ctx: ApiContext, rng: random.Random) -> list[Any]:
    """Values of the wrong type, shape or size, close to ``value`` or not."""
    out: list[Any] = list(GENERIC_API) + [ctx.config, ctx.flip, ctx.program, ctx.design]
    if isinstance(value, bool):
        out += [not value, 1, "true", np.bool_(value)]
    elif isinstance(value, int):
        out += [value + 1, value - 1, -value, value * 10**6, 2**31, 2**64, -(2**63), 10**400, float(value),
                np.int64(value), np.uint8(255), str(value)]
    elif isinstance(value, float):
        out += [value * 1e6, -value, value * 1e-9, value + 1e-12, math.nextafter(value, math.inf), value * 1e300,
                np.float32(value), np.float64(value), int(value), str(value), -0.0, 1e-300]
    elif isinstance(value, str):
        out += ["", value.upper(), value + "x", " " + value, value * 50, "é" * 300, "\udcff", "\x00", value[:-1]]
    elif isinstance(value, tuple | list):
        out += [(), value[:-1], tuple(value) + tuple(value), tuple(reversed(value)), list(value),
                tuple("a" for _ in value), tuple(math.nan for _ in value), (value,), tuple(1e308 for _ in value),
                tuple(None for _ in value)]
    elif isinstance(value, np.ndarray):
        out += [value[:-1], np.append(value, 0.0), value.reshape(1, -1), value.astype(np.float32),
                np.full(value.shape, math.nan), np.full(value.shape, math.inf), value * 1e300, value.tolist(),
                value.astype(object), value.astype(complex), np.zeros(0), value[..., None], -value,
                np.zeros(value.shape, dtype=int)]
    elif isinstance(value, Path):
        out += [ctx.fx.path_pool(rng, set()) for _ in range(6)] + [Path(ctx.fx.path_pool(rng, set()))]
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        out += [dataclasses.replace(value)]
    return out


def mutate_nested(rng: random.Random, doc: Any, ctx: ApiContext) -> Any:
    """A deep copy of ``doc`` with one leaf replaced, a key removed or an unknown key added."""
    doc = copy.deepcopy(doc)
    paths: list[tuple] = []

    def walk(node: Any, path: tuple) -> None:
        if isinstance(node, dict):
            paths.append(path)
            for key, value in node.items():
                walk(value, (*path, key))
        elif isinstance(node, list):
            paths.append(path)
            for index, value in enumerate(node):
                walk(value, (*path, index))
        else:
            paths.append(path)

    walk(doc, ())
    path = rng.choice(paths)
    if not path:
        return rng.choice(mutants(doc, ctx, rng))
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    key = path[-1]
    choice = rng.randrange(6)
    if choice == 0 and isinstance(parent, dict):
        del parent[key]
    elif choice == 1 and isinstance(parent, dict):
        parent["zz_unknown"] = rng.choice(GENERIC_API)
    else:
        parent[key] = rng.choice(mutants(parent[key], ctx, rng))
    return doc


@dataclasses.dataclass
class ApiTarget:
    name: str
    fn: Callable[..., Any]
    base: Callable[[], dict[str, Any]]
    nested: tuple[str, ...] = ()  # arguments mutated inside (dicts, specs) rather than replaced

    def draw(self, rng: random.Random, ctx: ApiContext) -> tuple[dict[str, Any], list[str]]:
        kwargs = self.base()
        if not kwargs or rng.random() < 0.08:
            return kwargs, []
        keys = rng.sample(list(kwargs), min(len(kwargs), rng.choice([1, 1, 1, 2])))
        for key in keys:
            if key in self.nested and rng.random() < 0.7:
                kwargs[key] = mutate_nested(rng, kwargs[key], ctx)
            else:
                kwargs[key] = rng.choice(mutants(kwargs[key], ctx, rng))
        return kwargs, keys


def _fields(obj: Any) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.init}


def api_targets(ctx: ApiContext) -> list[ApiTarget]:
    import aerobat as A
    from aerobat.experiments.reports import load_session, session_from_json
    from aerobat.experiments.studies import load_ranges
    from aerobat.plants.arena.params import load_arena
    from aerobat.quadrotor.maneuvers import load_maneuver_file

    cfg, fx = ctx.config, ctx.fx
    rules = ["paper", "tsvd", "damped", "kalman", "broyden", "paper+isc", "tsvd+isc", "kalman+isc"]
    out = [
        ApiTarget("VehicleParams", A.VehicleParams, lambda: _fields(cfg.vehicle)),
        ApiTarget("ControllerParams", A.ControllerParams, lambda: _fields(cfg.controller)),
        ApiTarget("VehicleConfig", A.VehicleConfig, lambda: _fields(cfg)),
        ApiTarget("VehicleConfig.with_mass", lambda mass_kg: cfg.with_mass(mass_kg), lambda: {"mass_kg": 0.5}),
        ApiTarget("MultiFlip", A.MultiFlip, lambda: _fields(ctx.flip)),
        ApiTarget("Translation", A.Translation, lambda: _fields(ctx.translation)),
        ApiTarget("translation_maneuver", A.translation_maneuver,
                  lambda: {"config": cfg, "target_yz": (1.0, 1.0), "final_angle_rad": 0.0, "ramp_s": 0.1}),
        ApiTarget("design", A.design, lambda: {
            "maneuver": ctx.flip, "model": A.NominalModel(cfg), "p_guess": np.array(ctx.flip.guess(), dtype=float),
            "tolerance": 1e-6, "correction": "tsvd", "tsvd_rtol": 1e-3, "damping": 1e-3, "max_iterations": 30,
            "raise_on_failure": False}),
        ApiTarget("NominalModel", A.NominalModel, lambda: {"config": cfg, "max_step_s": 5e-4}),
        ApiTarget("NominalModel.final_states", lambda programs, initial_states: A.NominalModel(cfg).final_states(
            programs, initial_states), lambda: {"programs": [ctx.program], "initial_states": None}),
        ApiTarget("NominalPlant", A.NominalPlant, lambda: {"config": cfg, "max_step_s": 5e-4, "sample_rate_hz": 200.0}),
        ApiTarget("NominalPlant.fly", lambda program: A.NominalPlant(cfg).fly(program),
                  lambda: {"program": ctx.program}),
        ApiTarget("Arena", A.Arena, lambda: {"config": cfg, "params": A.ArenaParams(), "seed": 0}),
        ApiTarget("Arena.fly", lambda program, seed: A.Arena(cfg, seed=seed).fly(program),
                  lambda: {"program": ctx.program, "seed": 1}),
        ApiTarget("ArenaParams", A.ArenaParams, lambda: _fields(A.ArenaParams())),
        ApiTarget("PlantChoice", A.PlantChoice, lambda: {"kind": "nominal", "settings": None, "seed": 0}),
        ApiTarget("PlantChoice.from_file", A.PlantChoice.from_file,
                  lambda: {"kind": "arena", "path": fx.dir / "arena.toml", "seed": 0}),
        ApiTarget("PlantChoice.build", lambda kind, seed, config: A.PlantChoice(kind, seed=seed).build(config),
                  lambda: {"kind": "nominal", "seed": 0, "config": cfg}),
        ApiTarget("RuleChoice.parse", A.RuleChoice.parse,
                  lambda: {"text": random.Random(len(ctx.stores)).choice(rules), "schedule": None, "source": "--rule"}),
        ApiTarget("RuleChoice", A.RuleChoice, lambda: {"name": "paper", "isc": False, "schedule": None}),
        ApiTarget("make_rule", A.make_rule, lambda: {"choice": "paper", "design": ctx.design}),
        ApiTarget("Store", A.Store, lambda: {"path": ctx.db, "create": False, "synchronous": "normal",
                                             "busy_timeout_s": 5.0}),
        ApiTarget("Store.resolve_session", lambda ref: ctx.store().resolve_session(ref), lambda: {"ref": "last"}),
        ApiTarget("Store.list_sessions", lambda limit, newest_first: ctx.store().list_sessions(
            limit=limit, newest_first=newest_first), lambda: {"limit": 3, "newest_first": True}),
        ApiTarget("start_session", A.start_session, lambda: {
            "store": ctx.store(), "maneuver": ctx.flip, "model": cfg, "plant": A.PlantChoice("nominal"),
            "rule": A.RuleChoice(), "iterations": 1, "design_result": ctx.design, "correction": "tsvd",
            "start_params": None, "warm_start_from": None, "force": False, "command": (), "study_id": None}),
        ApiTarget("resume_session", A.resume_session,
                  lambda: {"store": ctx.store(), "ref": "last", "iterations": None, "take_over": False}),
        ApiTarget("load_session", lambda session_id: load_session(ctx.store(), session_id), lambda: {"session_id": 1}),
        ApiTarget("session_from_json", session_from_json, lambda: {"data": copy.deepcopy(ctx.session_json)},
                  nested=("data",)),
        ApiTarget("load_vehicle", A.load_vehicle, lambda: {"path": fx.dir / "vehicle.toml"}),
        ApiTarget("load_program", A.load_program, lambda: {"path": fx.dir / "single_flip.toml"}),
        ApiTarget("load_arena", load_arena, lambda: {"path": fx.dir / "arena.toml"}),
        ApiTarget("load_ranges", load_ranges, lambda: {"path": fx.dir / "arena.toml"}),
        ApiTarget("load_maneuver_file", load_maneuver_file,
                  lambda: {"path": fx.dir / "maneuver_flip_sideways.toml", "vehicle": cfg.vehicle}),
        ApiTarget("save_program", A.save_program, lambda: {"program": ctx.program, "path": fx.fresh(".toml")}),
        ApiTarget("save_vehicle", A.save_vehicle, lambda: {"config": cfg, "path": fx.fresh(".toml")}),
        ApiTarget("simulate", A.simulate, lambda: {
            "program": ctx.program, "config": cfg, "initial_state": None, "mode": "continuous", "max_step_s": 5e-4,
            "tick_s": 1.25e-3, "substeps": 1, "plant": None, "record": True}),
        ApiTarget("simulate_batch", A.simulate_batch, lambda: {
            "programs": [ctx.program], "configs": cfg, "initial_states": None, "plants": None, "max_step_s": 5e-4}),
        ApiTarget("Program", A.Program, lambda: _fields(ctx.program)),
        ApiTarget("Switch", A.Switch, lambda: _fields(ctx.program.switches[0])),
        ApiTarget("RampDown", A.RampDown, lambda: _fields(ctx.program.ramp_down)),
        ApiTarget("Maneuver.program", lambda params: ctx.flip.program(params),
                  lambda: {"params": np.array(ctx.flip.guess(), dtype=float)}),
        ApiTarget("learn", A.learn, lambda: {
            "maneuver": ctx.flip, "design": ctx.design, "plant": A.NominalPlant(cfg), "iterations": 1, "rule": None,
            "start_params": None, "max_attempts": None}),
        ApiTarget("from_spec", A.from_spec, lambda: {"spec": copy.deepcopy(ctx.specs[len(ctx.stores) % 3]),
                                                     "source": "spec"}, nested=("spec",)),
        ApiTarget("solve_translation", A.solve_translation, lambda: {
            "target_y_m": 1.0, "target_z_m": 1.0, "final_angle_rad": 0.0, "limits": None, "intervals": 20,
            "ipopt_max_iter": 200}),
        ApiTarget("hummingbird", A.hummingbird, lambda: {}),
    ]
    return out


# ====================================================================== main


def phase_module(name: str) -> Any:
    """``scripts/fuzz_<name>.py`` (a phase), loaded from next to this file however this one was loaded, once."""
    import importlib.util

    module_name = f"fuzz_{name}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    spec = importlib.util.spec_from_file_location(module_name, Path(__file__).with_name(f"{module_name}.py"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    spec.loader.exec_module(module)
    return module


def files_module() -> Any:
    """``scripts/fuzz_files.py`` (the files phase)."""
    return phase_module("files")


PHASES = ("files", "tunes", "logs", "exports", "server")
"""The phases beside the command line's and the library's, each ``scripts/fuzz_<phase>.py``'s ``run_<phase>_phase``."""


def _tally(report: dict[str, Any]) -> None:
    """The campaign's totals over every phase: internal errors, hangs, data loss, non-JSON, over the memory bound."""
    parts = [report[phase] for phase in PHASES if isinstance(report.get(phase), dict)]
    report["internal"] = (report["cli"]["counts"]["INTERNAL"] + report["api"]["counts"]["INTERNAL"]
                          + sum(len(part.get("internal", [])) for part in parts))
    report["hangs"] = sum(len(part.get("hangs", [])) for part in parts)
    report["data_loss"] = sum(len(part.get("data_loss", [])) for part in parts)
    logs = report.get("logs", {})
    report["non_json"] = len(logs.get("non_json", []))
    report["over_memory_bound"] = len(logs.get("peak_memory", {}).get("over_bound", []))
    report["cases"] = (sum(report["cli"]["counts"].values()) + sum(report["api"]["counts"].values())
                       + sum(int(part.get("cases", 0)) for part in parts))
    report["peak_memory_mb"] = {
        "campaign": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "log_commands_worst": logs.get("peak_memory", {}).get("worst_mb"),
        "log_commands_bound_at_worst": logs.get("peak_memory", {}).get("bound_mb")}


def run_campaign(*, cli: int, api: int, seed: int, budget_s: float, report: Path | None,
                 progress: Callable[[str], None], keep: bool = False, files: int = 0,
                 files_kinds: tuple[str, ...] | None = None, tunes: int = 0, logs: int = 0, exports: int = 0,
                 server: int = 0) -> dict[str, Any]:
    """Run the campaign in a scratch folder; returns the report (also written to ``report``).

    ``files``, ``tunes``, ``logs``, ``exports``, ``server``: the phases of ``scripts/fuzz_<phase>.py``:
    -1 every case, N a seeded sample, 0 none; ``files_kinds`` limits the files phase to some kinds of case.
    """
    root = Path(tempfile.mkdtemp(prefix="aerobat-fuzz-"))
    saved_cwd, saved_env = os.getcwd(), dict(os.environ)
    campaign = Campaign(seed=seed, budget_s=budget_s, root=root, progress=progress)
    campaign.report_path = report
    try:
        rng = random.Random(seed)
        fx = Fixtures(root, rng)
        (root / "work").mkdir()
        os.chdir(root / "work")
        os.environ["AEROBAT_DB"] = str(fx.store)
        os.environ.pop("DASK_SCHEDULER_ADDRESS", None)
        os.environ["MPLBACKEND"] = "Agg"
        campaign.seed_store(fx)
        fx.backup_store()
        if cli:
            campaign.run_cli_phase(cli, fx)
        if api:
            campaign.run_api_phase(api, fx)
        me = sys.modules[__name__]
        if files:
            files_module().run_files_phase(me, campaign, fx, files, kinds=files_kinds)
        for phase, n in (("tunes", tunes), ("logs", logs), ("exports", exports), ("server", server)):
            if n:
                fx.restore_store()  # each phase starts from the seeded store (the cli phase may delete by design)
                getattr(phase_module(phase), f"run_{phase}_phase")(me, campaign, fx, n)
                problem = fx.store_ok()  # what a phase did to the store and did not see itself is data loss too
                if problem:
                    campaign.report[phase].setdefault("data_loss", []).append(
                        {"case": f"the store after the {phase} phase", "reason": problem})
                    fx.restore_store()
    finally:
        os.chdir(saved_cwd)
        os.environ.clear()
        os.environ.update(saved_env)
        campaign.alarm.close()
        if not keep:
            for path in root.rglob("*"):
                with contextlib.suppress(OSError):
                    if path.is_dir() and not path.is_symlink():
                        path.chmod(0o755)
            shutil.rmtree(root, ignore_errors=True)
    campaign.report["wall_s"] = round(time.perf_counter() - campaign.started, 1)
    _tally(campaign.report)
    campaign.write_report()
    return campaign.report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--cli", type=int, default=2000, help="command-line invocations")
    parser.add_argument("--api", type=int, default=500, help="library calls")
    parser.add_argument("--seed", type=int, default=0, help="seed of every draw")
    parser.add_argument("--budget-s", type=float, default=6.0, help="time budget of one invocation or call [s]")
    parser.add_argument("--report", type=Path, default=None, help="write the JSON report here")
    parser.add_argument("--memory-gb", type=float, default=12.0,
                        help="address-space limit, so an absurd allocation fails instead of swapping")
    parser.add_argument("--files", type=int, default=-1,
                        help="cases of the files phase (scripts/fuzz_files.py): -1 all, N a seeded sample, 0 none")
    parser.add_argument("--files-kinds", default=None,
                        help="only these kinds of file case, comma-separated (empty, dashdash, special-input, "
                             "special-output, store-link); default all")
    for phase in PHASES[1:]:
        parser.add_argument(f"--{phase}", type=int, default=-1,
                            help=f"cases of the {phase} phase (scripts/fuzz_{phase}.py): -1 all, N a sample, 0 none")
    parser.add_argument("--keep", action="store_true", help="keep the scratch folder (the reproductions use it)")
    parser.add_argument("--list", action="store_true", help="list the commands and options found, and stop")
    args = parser.parse_args(argv)
    if args.list:
        from aerobat.cli.app import build_parser

        for cmd in commands(build_parser()):
            print(cmd.name + (" (group)" if cmd.group else ""))
            for opt in cmd.options if not cmd.group else []:
                print(f"    {opt.label:22s} required={opt.required!s:5s} flag={opt.flag!s:5s} ref={opt.is_ref()!s:5s} "
                      f"bounds={opt.bounds()} choices={opt.action.choices} paths={opt.path_kinds()} "
                      f"examples={opt.examples()}")
        return 0
    if args.memory_gb > 0:
        limit = int(args.memory_gb * 2**30)
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    real_err = os.dup(2)
    Campaign.say_fd = real_err

    def say(text: str) -> None:
        os.write(real_err, (text + "\n").encode("utf-8", "backslashreplace"))

    with open(os.devnull) as devnull:
        os.dup2(devnull.fileno(), 0)
    kinds = tuple(k.strip() for k in args.files_kinds.split(",") if k.strip()) if args.files_kinds else None
    report = run_campaign(cli=args.cli, api=args.api, seed=args.seed, budget_s=args.budget_s, report=args.report,
                          progress=say, keep=args.keep, files=args.files, files_kinds=kinds, tunes=args.tunes,
                          logs=args.logs, exports=args.exports, server=args.server)
    cli, api = report["cli"], report["api"]
    say(f"fuzz: done in {report['wall_s']:.0f} s: cli {sum(cli['counts'].values())} invocations "
        + " ".join(f"{c}={cli['counts'].get(c, 0)}" for c in CLASSES)
        + f"; api {sum(api['counts'].values())} calls "
        + " ".join(f"{c}={api['counts'].get(c, 0)}" for c in API_CLASSES)
        + "".join(f"; {phase} {sum(report[phase]['counts'].values())} cases " + " ".join(
            f"{c}={v}" for c, v in sorted(report[phase]["counts"].items())) for phase in PHASES if phase in report)
        + f"; {report['cases']} cases in all: internal errors {report['internal']}, hangs {report['hangs']}, "
          f"data loss {report['data_loss']}, non-JSON {report['non_json']}, over the memory bound "
          f"{report['over_memory_bound']}; peak memory: campaign {report['peak_memory_mb']['campaign']:.0f} MB, "
          f"a log command {report['peak_memory_mb']['log_commands_worst'] or 0:.0f} MB"
        + (f"; report {args.report}" if args.report else ""))
    bad = ("internal", "hangs", "data_loss", "non_json", "over_memory_bound")
    return 1 if any(report[key] for key in bad) else 0


if __name__ == "__main__":
    sys.exit(main())
