"""The files phase of the fuzz campaign (issue 31): enumerated, not drawn, so every case is covered.

Imported by ``scripts/fuzz_campaign.py`` (``--files N``: all cases with -1, a seeded sample of N
otherwise, 0 to skip). For every command the parser knows:

- ``empty``: every option given an empty value (``--opt=``);
- ``dashdash``: every option given ``--`` (``--opt=--``); a value the option's type refuses must be
  refused with exit 2 naming it, and a value the parser silently drops (the option keeps its
  default although ``--`` was given) is a finding;
- ``special-input``: every input file (program, maneuver, vehicle, settings, ranges, tune, store)
  given a FIFO, ``/dev/zero`` and ``/dev/urandom``: refused with exit 2 at once — a call the time
  budget had to stop is a *hang*;
- ``special-output``: every output given a FIFO (refused) and ``/dev/null`` (anything but an
  internal error);
- ``store-link``: every output file given the store itself, a symbolic link and a hard link to it,
  and its ``-wal`` name; every output folder (``--out``, ``examples FOLDER``) filled with symbolic
  (then hard) links to the store under the names commands write there.

After every case the store must still open, hold its sessions and pass ``PRAGMA quick_check``,
with no fewer sessions or iterations than before: anything else is *data loss*. Each finding in
the report carries ``reproduce``: the shell lines that set the case up and the command.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import random
import shlex
import shutil
import sqlite3
from collections import Counter
from pathlib import Path
from typing import Any

# The names commands write into their folders (docs/cli.md); a link under any of them must never reach the store.
WRITTEN = ("session.json", "learning.png", "side_views.png", "replay.html", "benchmark_map.csv", "benchmark_map.png",
           "trajectory.png", "simulation.json", "trials.png", "trials.json", "translation.png", "translation.json",
           "robustness.json", "trials_to_tolerance.png", "success_vs_property.png", "envelope.json",
           "envelope_feasible.png", "rules.csv", "rules.png", "feedback.csv", "feedback.png", "hover.toml",
           "single_flip.toml", "triple_flip_1800.toml", "custom_maneuver.py")
FILE_OUTPUTS = ("--output", "--plot", "--figure", "--airframe")
NOT_FILES = ("--name",)  # options whose help mentions files without taking one
KINDS = ("empty", "dashdash", "special-input", "special-output", "store-link")


@dataclasses.dataclass
class Case:
    kind: str
    argv: list[str]
    setup: list[str]  # shell lines that make the files the case needs
    bad: list[str]  # names a refusal may use; empty: any clean outcome is fine
    why: str
    dropped: tuple[str, str] | None = None  # (dest, value): the parser must not silently drop this value
    hang_is_finding: bool = False


def _is_output(cmd: Any, opt: Any) -> bool:
    if opt.label in (*FILE_OUTPUTS, "--out"):
        return True
    if opt.label == "--program" and cmd.name in ("design", "export"):
        return True
    return cmd.name == "examples" and opt.dest == "folder"


def _is_folder(cmd: Any, opt: Any) -> bool:
    return (opt.label == "--out" and cmd.name != "identify") or (cmd.name == "examples" and opt.dest == "folder")


SMALL = ["--flips", "1", "--dims", "2", "--max-rate-deg-s", "800"]
# A cheap valid command line of each command ({program}: a valid program file; {tune}: a valid Betaflight diff;
# {new}: a file or folder that does not exist yet). Positionals by dest, then options; the option under test
# replaces its own entry. A command with no entry here is reported as not covered (the log commands need a real
# flight log).
BASES: dict[str, tuple[dict[str, str], list[str]]] = {
    "simulate": ({"program": "{program}"}, []),
    "fly": ({"program": "{program}"}, ["--plant", "nominal", "--trials", "1"]),
    "design": ({"maneuver": "flip"}, SMALL),
    "learn": ({"maneuver": "flip"}, [*SMALL, "--plant", "nominal", "--iterations", "1"]),
    "sessions": ({}, []), "show": ({"session": "1"}, []), "plot": ({"session": "1"}, []),
    "export": ({"session": "1"}, []), "replay": ({"session": "1"}, []), "studies": ({}, []),
    "examples": ({"folder": "{new}"}, []),
    "benchmark translation": ({}, ["--to-m", "1,0"]),
    "benchmark map": ({}, ["--y-m", "1:1:1", "--z-m", "1:1:1", "--workers", "1"]),
    "study robustness": ({"maneuver": "flip"}, [*SMALL, "--vehicles", "1", "--iterations", "1", "--plant", "arena",
                                                "--workers", "1"]),
    "study rules": ({"maneuver": "flip"}, [*SMALL, "--methods", "paper", "--seeds", "1", "--trials", "2", "--plant",
                                           "arena", "--workers", "1"]),
    "study feedback": ({"maneuver": "flip"}, [*SMALL, "--seeds", "1", "--trials", "2", "--plant", "arena",
                                              "--workers", "1"]),
    "study envelope": ({}, ["--flips", "1", "--rates-deg-s", "800", "--workers", "1"]),
    "identify": ({}, ["--plant", "nominal", "--output", "{new}.toml", "--max-flights", "2"]),
    "vehicles": ({}, ["--flip-counts", "1", "--rates-deg-s", "800"]),
    "tag": ({"session": "1", "tag": "t"}, []), "note": ({"session": "1", "text": "n"}, []),
    "compare": ({"a": "1", "b": "1"}, []), "delete": ({"session": "1"}, []),  # no --yes: refused, nothing deleted
    "browse": ({}, ["--export", "{new}"]),  # static pages: served pages would run until the budget stops them
    "setup": ({}, ["--check"]),  # only looks
    "tune": ({"file": "{tune}"}, []),  # reads and translates a tune; nothing flies
}


def base_argv(cmd: Any, opt: Any, value: str, fill: Any) -> list[str] | None:
    """The command's base line with ``opt`` given ``value``; None if the command has no base line."""
    if cmd.name not in BASES:
        return None
    positionals, options = BASES[cmd.name]
    head = []
    for o in cmd.options:
        if o.positional:
            if o.dest == opt.dest:
                head.append(value)
            elif o.dest in positionals:
                head.append(fill(positionals[o.dest]))
    tail, k = [], 0
    names = {n for o in cmd.options if o.dest == opt.dest for n in o.names}
    while k < len(options):
        word = options[k]
        takes = k + 1 < len(options) and not options[k + 1].startswith("--")
        if word not in names:
            tail += [fill(word)] + ([fill(options[k + 1])] if takes else [])
        k += 2 if takes else 1
    if not opt.positional:
        tail.append(f"{opt.names[-1]}={value}")
    return [*cmd.path, *head, *tail]


def build_cases(cmds: list[Any], fx: Any, root: Path, uncovered: list[str]) -> list[Case]:
    (root / "fresh").mkdir(exist_ok=True)
    fifo = root / "special" / "fifo.toml"
    fifo.parent.mkdir(parents=True, exist_ok=True)
    if not fifo.exists():
        os.mkfifo(fifo)
    make_fifo = f"mkfifo {shlex.quote(str(fifo))}"
    tune = fifo.with_name("tune.txt")
    tune.write_text("# Betaflight / STM32F7X2 (S7X2) 4.3.1 Jul 13 2022 / 03:32:52 (8d4f005) MSP API: 1.44\n"
                    "set p_roll = 50\n")
    store = str(fx.store)
    cases: list[Case] = []
    counter = 0

    def fresh_dir() -> Path:
        nonlocal counter
        counter += 1
        return root / "cases" / f"c{counter}"

    def fill(word: str) -> str:
        if "{program}" in word:
            return word.replace("{program}", str(fx.dir / "single_flip.toml"))
        if "{tune}" in word:
            return word.replace("{tune}", str(tune))
        if "{new}" in word:
            nonlocal counter
            counter += 1
            return word.replace("{new}", str(root / "fresh" / f"f{counter}"))
        return word

    for cmd in cmds:
        if cmd.group:
            continue
        if cmd.name not in BASES:
            uncovered.append(cmd.name)
            continue
        for opt in cmd.options:
            if opt.flag:
                continue
            label = opt.label
            # a typed option, a choice or a name takes no file
            takes_file = opt.action.type is None and opt.action.choices is None and label not in NOT_FILES
            kinds = opt.path_kinds() if takes_file else None
            output = _is_output(cmd, opt)

            def argv_with(value: str, opt: Any = opt, cmd: Any = cmd) -> list[str]:
                argv = base_argv(cmd, opt, value, fill)
                assert argv is not None
                return argv

            if not opt.positional:
                must = opt.refuses("") or kinds is not None
                cases.append(Case("empty", argv_with(""), [], opt.mentions() if must else [],
                                  f"{label} ''" if must else ""))
                must = opt.refuses("--")
                cases.append(Case("dashdash", argv_with("--"), [], opt.mentions() if must else [],
                                  f"{label} '--'" if must else "", dropped=(opt.dest, "--")))
            if kinds is None:
                continue
            if not output:
                for special in (str(fifo), "/dev/zero", "/dev/urandom"):
                    cases.append(Case("special-input", argv_with(special), [make_fifo] if special == str(fifo) else [],
                                      [*opt.mentions(), special], f"{label} {special} (not a regular file)",
                                      hang_is_finding=True))
                continue
            cases.append(Case("special-output", argv_with(str(fifo)), [make_fifo], [*opt.mentions(), str(fifo)],
                              f"{label} a FIFO", hang_is_finding=True))
            if not _is_folder(cmd, opt):
                cases.append(Case("special-output", argv_with("/dev/null"), [], [], ""))
                for how in ("store", "symlink", "hardlink", "wal"):
                    folder = fresh_dir()
                    target = {"store": store, "wal": f"{folder}/x.sqlite-wal"}.get(how, f"{folder}/link.png")
                    setup = [f"mkdir -p {shlex.quote(str(folder))}"]
                    if how == "symlink":
                        setup.append(f"ln -s {shlex.quote(store)} {shlex.quote(target)}")
                    elif how == "hardlink":
                        setup.append(f"ln {shlex.quote(store)} {shlex.quote(target)}")
                    cases.append(Case("store-link", argv_with(target), setup, [*opt.mentions(), target],
                                      f"{label} is the store ({how})"))
                continue
            for how in ("symlink", "hardlink"):
                folder = fresh_dir()
                flag = "-s " if how == "symlink" else ""
                setup = [f"mkdir -p {shlex.quote(str(folder))}"] + [
                    f"ln {flag}{shlex.quote(store)} {shlex.quote(str(folder / name))}" for name in WRITTEN]
                argv = argv_with(str(folder))
                if cmd.name in ("examples", "identify"):
                    argv.append("--force")
                cases.append(Case("store-link", argv, setup, [], ""))
    return cases


def _apply(setup: list[str]) -> None:
    """Run the case's setup lines (mkdir, ln, ln -s, mkfifo: written as shell for the report, done here in Python)."""
    for line in setup:
        words = shlex.split(line)
        if words[:2] == ["mkdir", "-p"]:
            Path(words[2]).mkdir(parents=True, exist_ok=True)
        elif words[:2] == ["ln", "-s"]:
            with contextlib.suppress(FileExistsError):
                os.symlink(words[2], words[3])
        elif words[0] == "ln":
            with contextlib.suppress(FileExistsError):
                os.link(words[1], words[2])
        elif words[0] == "mkfifo" and not Path(words[1]).exists():
            os.mkfifo(words[1])


def store_counts(path: Path) -> tuple[int, int] | str:
    """(sessions, iterations) of the store, or what is wrong with it."""
    try:
        with open(path, "rb") as handle:
            if not handle.read(16).startswith(b"SQLite format 3\x00"):
                return "the store is no longer an SQLite file"
        with contextlib.closing(sqlite3.connect(f"file:{path}?mode=ro", uri=True)) as conn:
            check = conn.execute("PRAGMA quick_check").fetchone()[0]
            if check != "ok":
                return f"quick_check: {check}"
            return (conn.execute("SELECT count(*) FROM sessions").fetchone()[0],
                    conn.execute("SELECT count(*) FROM iterations").fetchone()[0])
    except (OSError, sqlite3.Error) as exc:
        return f"{type(exc).__name__}: {exc}"


def silently_dropped(argv: list[str], dest: str, value: str, parser: Any = None) -> bool:
    """Does the parser (default: aerobat's) accept ``argv`` and leave ``dest`` without ``value`` (as argparse
    does with ``--opt=--``, which it reads as an empty list)?"""
    import io
    from contextlib import redirect_stderr, redirect_stdout

    if parser is None:
        from aerobat.cli.app import build_parser

        parser = build_parser()
    try:
        with redirect_stderr(io.StringIO()), redirect_stdout(io.StringIO()):
            namespace = parser.parse_args(argv)
    except SystemExit:
        return False  # refused: not dropped
    got = getattr(namespace, dest, None)
    return not (got == value or (isinstance(got, list | tuple) and value in got))


def reproduce(fx: Any, work: Path, case: Case) -> str:
    lines = [f"cd {shlex.quote(str(work))}", f"export AEROBAT_DB={shlex.quote(str(fx.store))}", *case.setup,
             "aerobat " + shlex.join(case.argv)]
    return "; ".join(lines)


def run_files_phase(fz: Any, campaign: Any, fx: Any, n: int, *, kinds: tuple[str, ...] | None = None) -> None:
    """Run the file cases (all if ``n`` < 0, else a seeded sample of ``n`` spread over the kinds)."""
    from aerobat.cli.app import build_parser

    rng = random.Random(campaign.seed + 31)
    root = campaign.root
    uncovered: list[str] = []
    cases = [c for c in build_cases(fz.commands(build_parser()), fx, root, uncovered)
             if kinds is None or c.kind in kinds]
    if 0 <= n < len(cases):
        by_kind = {k: [c for c in cases if c.kind == k] for k in KINDS}
        n = min(n, len(cases))
        picked: list[Case] = []
        while len(picked) < n:
            for kind in KINDS:
                if by_kind[kind] and len(picked) < n:
                    picked.append(by_kind[kind].pop(rng.randrange(len(by_kind[kind]))))
        cases = picked
    report: dict[str, Any] = {"requested": n, "kinds": list(kinds or KINDS), "cases": len(cases),
                              "counts": Counter(), "by_kind": {},
                              "internal": [], "hangs": [], "data_loss": [],
                              "not_covered": uncovered}
    campaign.report["files"] = report
    work = Path.cwd()
    for k, case in enumerate(cases):
        fx.restore()
        shutil.rmtree(root / "cases", ignore_errors=True)
        _apply(case.setup)
        before = store_counts(fx.store)
        campaign.current = {"phase": "files", "index": k, "argv": case.argv, "setup": case.setup}
        inv = fz.Invocation(case.argv, " ".join(case.argv[:2]), case.bad, case.why)
        how, code, out, err, escaped, fired, seconds = fz.run_cli(case.argv, campaign.alarm, campaign.budget_s,
                                                                  campaign.on_hang)
        klass, reason = fz.judge(inv, how, code, out, err, escaped, fired)
        if case.dropped is not None and klass != "INTERNAL" and silently_dropped(case.argv, *case.dropped):
            klass, reason = "INTERNAL", f"the value {case.dropped[1]!r} was silently dropped by the parser"
        after = store_counts(fx.store)
        lost = None
        if isinstance(after, str):
            lost = after
        elif isinstance(before, tuple) and (after[0] < before[0] or after[1] < before[1]):
            lost = f"sessions/iterations {before} → {after}"
        entry = {"index": k, "kind": case.kind, "argv": case.argv, "exit": code, "how": how, "reason": reason,
                 "stderr": err[-1500:], "seconds": round(seconds, 2), "reproduce": reproduce(fx, work, case)}
        if lost is not None:
            klass = "DATA-LOSS"
            entry["reason"] = f"the store was damaged: {lost}"
            report["data_loss"].append(entry)
            fx.restore_store()
        elif case.hang_is_finding and (how == "stopped" or fired):
            klass = "HANG"
            entry["reason"] = f"not refused at once: stopped by the {campaign.budget_s:g} s budget"
            report["hangs"].append(entry)
        elif klass == "INTERNAL":
            report["internal"].append(entry)
        elif fx.store_ok() is not None:
            fx.restore_store()
        report["counts"][klass] += 1
        report["by_kind"].setdefault(case.kind, Counter())[klass] += 1
        if klass in ("INTERNAL", "HANG", "DATA-LOSS"):
            campaign.say(f"fuzz: {klass} files #{k} ({case.kind}): {entry['reason']}\n  reproduce: {entry['reproduce']}"
                         + ("\n  " + (err.strip().splitlines() or [""])[-1][:300] if err.strip() else ""))
        if (k + 1) % 50 == 0 or k + 1 == len(cases):
            campaign.say(f"fuzz: files {k + 1}/{len(cases)}: "
                         + " ".join(f"{c}={v}" for c, v in sorted(report["counts"].items())))
    shutil.rmtree(root / "cases", ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    """Only the files phase: ``scripts/fuzz_campaign.py --cli 0 --api 0`` with the same options."""
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location("fuzz_campaign", Path(__file__).with_name("fuzz_campaign.py"))
    assert spec is not None and spec.loader is not None
    campaign = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_campaign"] = campaign
    spec.loader.exec_module(campaign)
    return int(campaign.main(["--cli", "0", "--api", "0", *(sys.argv[1:] if argv is None else argv)]))


if __name__ == "__main__":
    raise SystemExit(main())
