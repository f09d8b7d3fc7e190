"""The exports phase of the fuzz campaign (issue 45): every file an export writes, with a link or a full disk there.

``run_exports_phase(fz, campaign, fx, n)`` (the conventions of ``scripts/fuzz_files.py``: all cases
with ``n`` < 0, a seeded sample of ``n`` spread over the kinds otherwise) runs, in-process:

- ``browse-link``: ``browse --export DIR --compare A,B`` with one name the export writes (learned from
  a first, clean export) made a link: symbolic (absolute, relative, a chain) or hard, to the store,
  to its ``-wal`` or ``-shm`` (the store is held open meanwhile, as while ``learn`` runs, so they
  exist), to another file, dangling, to a folder, to the store's folder;
- ``browse-folder``: each subfolder the export writes (``session-1/``, ``compare/``…) made a link to
  a folder, to the store's folder, to the store, a dangling link, or a file;
- ``output-link``: ``export --format csv|json|mcap [--trajectories] --output FILE`` with FILE each
  of those links, with and without ``--force``;
- ``full-disk``: each format and ``browse --export`` on a small tmpfs filled up to a few bytes, a
  page or megabytes short of room, over an earlier export (skipped, with the reason in the report,
  where no tmpfs can be mounted).

What must happen: a link to the store, its ``-wal``/``-shm``, a dangling link or a folder where a
file goes is refused with exit 2 and one line naming it, before anything is written (the folder
is as it was); any other file or link is replaced (by ``export`` only with ``--force``) by a
regular file, whole; a full disk is exit 1 (``aerobat: failed: … disk is full``), the earlier
file whole, no temporary file left, every file either whole or absent. After every case the
store opens with all its sessions and every link's target is byte-identical (a ``-shm``'s
header and hash tables: readers write their read marks between them); anything else is *data
loss*. Findings carry ``reproduce`` (shell lines). ``python scripts/fuzz_exports.py`` runs this
phase and ``scripts/fuzz_server.py``'s alone.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import hashlib
import importlib.util
import json
import os
import random
import shlex
import shutil
import sqlite3
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
KINDS = ("browse-link", "browse-folder", "output-link", "full-disk")
STORE_LINKS = ("symlink-store", "symlink-store-relative", "symlink-store-chain", "hardlink-store", "symlink-wal",
               "hardlink-wal", "symlink-shm", "hardlink-shm")
LINKS = (*STORE_LINKS, "symlink-other", "hardlink-other", "dangling", "symlink-folder", "symlink-store-folder")
FOLDER_LINKS = ("symlink-folder", "symlink-store-folder", "symlink-store", "dangling", "file")
FORMATS = (("csv",), ("json",), ("json", "--trajectories"), ("mcap",))
ROOM = (0, 100, 4096, 12_000, 40_000, 120_000, 400_000, 1_500_000)  # bytes left free on the full disk
BROWSE_BUDGET_S = 120.0  # a whole export draws figures and replays: more than one call's usual budget
EARLIER = b"an earlier export: must stay whole unless replaced whole\n"


def load(name: str) -> Any:
    """A module from next to this file (``fuzz_files``) or from ``tests/`` (``full_disk``), by path."""
    path = HERE / f"{name}.py" if (HERE / f"{name}.py").exists() else HERE.parent / "tests" / f"{name}.py"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@dataclasses.dataclass
class Case:
    kind: str
    how: str  # the link kind, or the room left on the full disk
    name: str  # the name the link is put at (relative to the case folder), or the format
    argv: list[str]
    setup: list[str]  # shell lines, for the report
    refused: bool  # must be refused (exit 2 naming ``name``) before anything is written


def digest(path: Path, *, shm: bool = False) -> str:
    """A file's SHA-256 (a ``-shm``'s without the read marks readers write: bytes 96-135)."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        return f"unreadable: {exc.strerror or exc}"
    return hashlib.sha256(data[:96] + data[136:] if shm else data).hexdigest() + f":{len(data)}"


def listing(folder: Path) -> dict[str, str]:
    """Every entry under ``folder`` (links not followed): files by content, links by target."""
    out: dict[str, str] = {}
    if not folder.is_dir():
        return out
    for entry in sorted(folder.rglob("*")):
        name = entry.relative_to(folder).as_posix()
        out[name] = (f"-> {os.readlink(entry)}" if entry.is_symlink() else "folder" if entry.is_dir()
                     else digest(entry))
    return out


def whole(path: Path) -> bool:
    """A page, figure or export written to its end; an earlier export's file as it was."""
    try:
        data = path.read_bytes()
    except OSError:
        return False
    if data == EARLIER:
        return True
    if path.suffix == ".png":
        return data.startswith(b"\x89PNG") and data.endswith(b"IEND\xaeB`\x82")
    if path.suffix == ".html":
        return data.rstrip().endswith(b"</html>")
    if path.suffix == ".mcap":
        return data.startswith(b"\x89MCAP0\r\n") and data.endswith(b"\x89MCAP0\r\n")
    if path.suffix == ".json":
        with contextlib.suppress(ValueError):
            return isinstance(json.loads(data), dict)
        return False
    return data.startswith(b"session,") and data.endswith(b"\n")


class Held:
    """The store held open by another connection (as while ``learn`` runs): its ``-wal`` and ``-shm`` exist."""

    def __init__(self, store: Path) -> None:
        self.store = store
        self.conn: sqlite3.Connection | None = None

    def open(self) -> None:
        self.close()
        with contextlib.suppress(sqlite3.Error):
            self.conn = sqlite3.connect(self.store)
            self.conn.execute("SELECT count(*) FROM sessions").fetchone()

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None


def _link(how: str, store: Path, at: Path, case: Path) -> list[str]:
    """Shell lines making ``at`` the link (or file) ``how``; what it points to is made under ``case``."""
    q = shlex.quote
    other, folder = case / "other.txt", case / "a-folder"
    lines = [f"mkdir -p {q(str(at.parent))} {q(str(folder))}", f"printf 'somebody else' > {q(str(other))}"]
    targets = {"store": store, "wal": Path(f"{store}-wal"), "shm": Path(f"{store}-shm"), "other": other,
               "folder": folder, "store-folder": store.parent}
    if how == "symlink-store-relative":
        lines.append(f"ln -s {q(os.path.relpath(store, at.parent))} {q(str(at))}")
    elif how == "symlink-store-chain":
        lines += [f"ln -s {q(str(store))} {q(str(case / 'hop'))}", f"ln -s {q(str(case / 'hop'))} {q(str(at))}"]
    elif how == "dangling":
        lines.append(f"ln -s {q(str(case / 'nothing-here'))} {q(str(at))}")
    elif how == "file":
        lines.append(f"printf 'x' > {q(str(at))}")
    elif how.startswith("symlink-"):
        lines.append(f"ln -s {q(str(targets[how.removeprefix('symlink-')]))} {q(str(at))}")
    else:
        lines.append(f"ln {q(str(targets[how.removeprefix('hardlink-')]))} {q(str(at))}")
    return lines


def apply(setup: list[str]) -> None:
    """Run a case's setup lines (written as shell for the report, done here in Python)."""
    for line in setup:
        words = shlex.split(line)
        if words[0] == "mkdir":
            for folder in words[2:]:
                Path(folder).mkdir(parents=True, exist_ok=True)
        elif words[0] == "printf":
            Path(words[-1]).write_text(words[1])
        elif words[:2] == ["ln", "-s"]:
            os.symlink(words[2], words[3])
        elif words[0] == "ln":
            os.link(words[1], words[2])


def build_cases(store: Path, root: Path, pages: list[str], compare: list[str], session: str,
                disk: bool) -> list[Case]:
    cases: list[Case] = []
    counter = 0

    def folder() -> Path:
        nonlocal counter
        counter += 1
        return root / f"c{counter}"

    for name in pages:
        for how in LINKS:
            case = folder()
            site = case / "site"
            argv = ["browse", "--db", str(store), "--export", str(site), *compare]
            cases.append(Case("browse-link", how, name, argv, _link(how, store, site / name, case),
                              refused=how not in ("symlink-other", "hardlink-other")))
    for sub in sorted({str(Path(p).parent) for p in pages} - {"."}):
        for how in FOLDER_LINKS:
            case = folder()
            site = case / "site"
            argv = ["browse", "--db", str(store), "--export", str(site), *compare]
            cases.append(Case("browse-folder", how, sub, argv, _link(how, store, site / sub, case), refused=True))
    for fmt in FORMATS:
        for how in LINKS:
            for force in (False, True):
                case = folder()
                output = case / f"out.{fmt[0]}"
                argv = ["export", session, "--db", str(store), "--format", *fmt, "--output", str(output),
                        *(["--force"] if force else [])]
                cases.append(Case("output-link", how, output.name, argv, _link(how, store, output, case),
                                  refused=not force or how not in ("symlink-other", "hardlink-other")))
    if disk:
        for room in ROOM:
            for fmt in [*FORMATS, ("browse",)]:
                if fmt == ("browse",):
                    argv = ["browse", "--db", str(store), "--export", "{disk}/site", *compare]
                else:
                    argv = ["export", session, "--db", str(store), "--format", *fmt, "--output",
                            f"{{disk}}/out.{fmt[0]}", "--force"]
                cases.append(Case("full-disk", str(room), " ".join(fmt), argv, [], refused=False))
    return cases


def sample(cases: list[Case], n: int, rng: random.Random) -> list[Case]:
    """All cases (``n`` < 0), or ``n`` of them drawn in turn from each kind."""
    if n < 0 or n >= len(cases):
        return cases
    by_kind = {k: [c for c in cases if c.kind == k] for k in KINDS}
    picked: list[Case] = []
    while len(picked) < n:
        for kind in KINDS:
            if by_kind[kind] and len(picked) < n:
                picked.append(by_kind[kind].pop(rng.randrange(len(by_kind[kind]))))
    return picked


@contextlib.contextmanager
def full_disk(root: Path) -> Iterator[tuple[Path | None, str | None]]:
    """A tmpfs of 8 MiB to fill up (``tests/full_disk.py``), or None and the reason there is none."""
    helper = load("full_disk")
    folder = root / "full-disk"
    folder.mkdir(exist_ok=True)
    reason = helper.mount_tmpfs(folder, "8m")
    try:
        yield (None, reason) if reason else (folder, None)
    finally:
        if reason is None:
            helper.unmount(folder)


def _prepare_disk(case: Case, disk: Path) -> list[str]:
    """Empty the tmpfs, put an earlier export there, fill it up to ``case.how`` bytes free; the shell lines."""
    for entry in disk.iterdir():
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry)
        else:
            entry.unlink()
    earlier = [disk / "site" / "index.html", disk / "site" / "session-1.html"] if case.name == "browse" \
        else [disk / f"out.{case.name.split()[0]}"]
    for path in earlier:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(EARLIER)
    free = load("full_disk").fill_up(disk, leave=int(case.how))
    q = shlex.quote
    return [f"mount -t tmpfs -o size=8m tmpfs {q(str(disk))}",
            *(f"mkdir -p {q(str(p.parent))}; printf {q(EARLIER.decode())} > {q(str(p))}" for p in earlier),
            f"fallocate -l $(( $(stat -f -c '%a*%S' {q(str(disk))}) - {free} )) {q(str(disk / '.filler'))}"]


def judge_case(case: Case, code: int | None, err: str, before: dict[str, str], after: dict[str, str],
                at: Path, disk: Path | None) -> str | None:
    """What went wrong with a case that ran (beyond what ``fz.judge`` saw), or None."""
    if case.kind == "full-disk":
        assert disk is not None
        if code == 1 and "disk is full" not in err:
            return "exit 1 without saying the disk is full"
        if code not in (0, 1):
            return f"exit {code} on a full disk (expected 1, or 0 when it fitted)"
        broken = [p for p in disk.rglob("*") if p.is_file() and p.name != ".filler"
                  and (p.name.endswith(".tmp") or not whole(p))]
        if broken:
            return f"half-written or temporary files left: {[str(p.relative_to(disk)) for p in broken][:5]}"
        earlier = disk / "site" / "index.html" if case.name == "browse" else disk / f"out.{case.name.split()[0]}"
        if code == 1 and earlier.read_bytes() != EARLIER:  # browse --export writes its index last
            return f"{earlier.name} was changed by an export that failed"
        return None
    if case.refused:
        if code != 2:
            return f"exit {code}: expected a refusal (exit 2) before anything was written"
        if before != after:
            changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
            return f"refused, but only after writing: {changed[:5]}"
        return None
    if code != 0:
        return f"exit {code}: a file or link there should have been replaced"
    if at.is_symlink() or not at.is_file() or at.stat().st_nlink != 1 or not whole(at):
        return "the link there was not replaced by a whole file of its own"
    return None


def run_exports_phase(fz: Any, campaign: Any, fx: Any, n: int) -> None:
    """Run the export cases (all if ``n`` < 0, else a seeded sample of ``n`` spread over the kinds)."""
    rng = random.Random(campaign.seed + 45)
    root = campaign.root / "exports"
    report: dict[str, Any] = {"requested": n, "cases": 0, "counts": Counter(), "by_kind": {}, "internal": [],
                              "hangs": [], "data_loss": [], "not_covered": [], "full_disk": {}}
    campaign.report["exports"] = report
    if n == 0:
        return
    started = time.perf_counter()
    store = Path(fx.store).resolve()
    with contextlib.closing(sqlite3.connect(f"file:{store}?mode=ro", uri=True)) as conn:
        ids = [str(r[0]) for r in conn.execute("SELECT id FROM sessions ORDER BY id LIMIT 2")]
    compare = ["--compare", ",".join(ids)] if len(ids) == 2 else []
    reference = root / "reference"
    how, code, _, err, _, _, seconds = fz.run_cli(["browse", "--db", str(store), "--export", str(reference),
                                                   *compare], campaign.alarm, BROWSE_BUDGET_S, campaign.on_hang)
    pages = sorted(p.relative_to(reference).as_posix() for p in reference.rglob("*") if p.is_file())
    report["reference"] = {"exit": code, "pages": pages, "seconds": round(seconds, 2)}
    if code != 0 or not pages:
        report["internal"].append({"kind": "reference", "exit": code, "how": how, "stderr": err[-1500:],
                                   "reason": "a clean browse --export failed", "reproduce":
                                   f"aerobat browse --db {shlex.quote(str(store))} --export {reference}"})
        return
    held = Held(store)
    work = Path.cwd()
    with full_disk(root) as (disk, reason):
        report["full_disk"] = {"skipped": reason} if reason else {"tmpfs": "8m", "room": list(ROOM)}
        cases = sample(build_cases(store, root / "cases", pages, compare, ids[0] if ids else "1", disk is not None),
                       n, rng)
        report["cases"] = len(cases)
        for k, case in enumerate(cases):
            _run_case(fz, campaign, fx, report, k, case, held, disk, root, work)
            if (k + 1) % 50 == 0 or k + 1 == len(cases):
                campaign.say(f"fuzz: exports {k + 1}/{len(cases)}: "
                             + " ".join(f"{c}={v}" for c, v in sorted(report["counts"].items())))
        held.close()
        shutil.rmtree(root / "cases", ignore_errors=True)
    shutil.rmtree(root, ignore_errors=True)
    report["wall_s"] = round(time.perf_counter() - started, 1)


def link_targets(store: Path, cases: Path, at: Path) -> dict[Path, str]:
    """What a case's links may reach, by content: the store's files and every file its setup made (but the link)."""
    made = [p for p in cases.rglob("*") if p.is_file() and not p.is_symlink() and p != at
            and "site" not in p.relative_to(cases).parts[1:2]] if cases.is_dir() else []
    return {p: digest(p, shm=p.name.endswith("-shm"))
            for p in (store, Path(f"{store}-wal"), Path(f"{store}-shm"), *made) if p.exists()}


def _run_case(fz: Any, campaign: Any, fx: Any, report: dict[str, Any], k: int, case: Case, held: Held,
              disk: Path | None, root: Path, work: Path) -> None:
    files = load("fuzz_files")
    store = Path(fx.store).resolve()
    shutil.rmtree(root / "cases", ignore_errors=True)
    fx.restore()
    held.open()
    argv = [a.replace("{disk}", str(disk)) for a in case.argv]
    if case.kind == "full-disk":
        assert disk is not None
        setup = _prepare_disk(case, disk)
    else:
        setup = case.setup
        try:
            apply(setup)
        except OSError as exc:  # a hard link to a -wal that is not there, say
            report["not_covered"].append(f"{case.kind} {case.how} {case.name}: {exc.strerror or exc}")
            held.close()
            return
    output = "--output" in argv
    named = Path(argv[argv.index("--output" if output else "--export") + 1])
    at = named if output else named / case.name
    folder = named.parent if output else named
    targets = link_targets(store, root / "cases", at)
    before, counts = listing(folder), files.store_counts(store)
    campaign.current = {"phase": "exports", "index": k, "argv": argv, "setup": setup}
    inv = fz.Invocation(argv, argv[0], [str(at), case.name] if case.refused else [],
                        f"{case.how} at {case.name}" if case.refused else "")
    budget = BROWSE_BUDGET_S if argv[0] == "browse" else max(campaign.budget_s, 30.0)
    how, code, out, err, escaped, fired, seconds = fz.run_cli(argv, campaign.alarm, budget, campaign.on_hang)
    klass, reason = fz.judge(inv, how, code, out, err, escaped, fired)
    if klass not in ("INTERNAL", "stopped"):
        reason = judge_case(case, code, err, before, listing(folder), at, disk) or ""
        klass = "INTERNAL" if reason else klass
    lost = [str(p) for p, d in targets.items() if digest(p, shm=p.name.endswith("-shm")) != d]  # before the close
    held.close()  # (the last connection's close removes the -wal and -shm)
    after = files.store_counts(store)
    if after != counts:
        lost.insert(0, f"the store: {counts} → {after}")
    broken = fx.store_ok()
    entry = {"index": k, "kind": case.kind, "how": case.how, "name": case.name, "argv": argv, "exit": code,
             "reason": reason, "stderr": err[-1500:], "seconds": round(seconds, 2),
             "reproduce": "; ".join([f"cd {shlex.quote(str(work))}", *setup, "aerobat " + shlex.join(argv)])}
    if lost or broken is not None:
        klass, entry["reason"] = "DATA-LOSS", f"changed: {lost[:5] or [broken]}"
        report["data_loss"].append(entry)
        fx.restore_store()
    elif how == "stopped" or fired:
        klass, entry["reason"] = "HANG", f"stopped by the {budget:g} s budget"
        report["hangs"].append(entry)
    elif klass == "INTERNAL":
        report["internal"].append(entry)
    report["counts"][klass] += 1
    report["by_kind"].setdefault(case.kind, Counter())[klass] += 1
    if klass in ("INTERNAL", "HANG", "DATA-LOSS"):
        campaign.say(f"fuzz: {klass} exports #{k} ({case.kind} {case.how} {case.name}): {entry['reason']}\n"
                     f"  reproduce: {entry['reproduce']}")


# ====================================================================== running this phase alone


def standalone(argv: list[str] | None, *, exports: int, server: int, description: str) -> int:
    """A scratch campaign (the fuzz campaign's store and fixtures) running only the exports and server phases."""
    parser = argparse.ArgumentParser(description=description, formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--exports", type=int, default=exports, help="export cases: -1 all, N a sample, 0 none")
    parser.add_argument("--server", type=int, default=server, help="server cases: -1 all, N a sample, 0 none")
    parser.add_argument("--seed", type=int, default=0, help="seed of the samples")
    parser.add_argument("--budget-s", type=float, default=6.0, help="time budget of one export command [s]")
    parser.add_argument("--report", type=Path, default=None, help="write the JSON report here")
    parser.add_argument("--keep", action="store_true", help="keep the scratch folder (the reproductions use it)")
    args = parser.parse_args(argv)
    fz = load("fuzz_campaign")
    root = Path(tempfile.mkdtemp(prefix="aerobat-fuzz-exports-"))
    saved_cwd, saved_env = os.getcwd(), dict(os.environ)
    real_err = os.dup(2)

    def say(text: str) -> None:
        os.write(real_err, (text + "\n").encode("utf-8", "backslashreplace"))

    fz.Campaign.say_fd = real_err
    campaign = fz.Campaign(seed=args.seed, budget_s=args.budget_s, root=root, progress=say)
    campaign.report_path = args.report
    try:
        fx = fz.Fixtures(root, random.Random(args.seed))
        (root / "work").mkdir()
        os.chdir(root / "work")
        os.environ.update({"AEROBAT_DB": str(fx.store), "MPLBACKEND": "Agg"})
        campaign.seed_store(fx)
        fx.backup_store()
        run_exports_phase(fz, campaign, fx, args.exports)
        load("fuzz_server").run_server_phase(fz, campaign, fx, args.server)
    finally:
        os.chdir(saved_cwd)
        os.environ.clear()
        os.environ.update(saved_env)
        campaign.alarm.close()
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)
    report = campaign.report
    report["wall_s"] = round(time.perf_counter() - campaign.started, 1)
    findings = {key: sum(len(report.get(phase, {}).get(key, [])) for phase in ("exports", "server"))
                for key in ("internal", "hangs", "data_loss")}
    report.update(findings)
    campaign.write_report()
    for phase in ("exports", "server"):
        part = report.get(phase, {})
        say(f"fuzz: {phase}: {sum(part.get('counts', {}).values())} cases in {part.get('wall_s', 0):.0f} s "
            + " ".join(f"{c}={v}" for c, v in sorted(part.get("counts", {}).items()))
            + (f"; full disk skipped: {part['full_disk']['skipped']}" if part.get("full_disk", {}).get("skipped")
               else ""))
    say(f"fuzz: done in {report['wall_s']:.0f} s: internal errors {findings['internal']}, hangs {findings['hangs']}, "
        f"data loss {findings['data_loss']}" + (f"; report {args.report}" if args.report else ""))
    return 1 if any(findings.values()) else 0


def main(argv: list[str] | None = None) -> int:
    """Only this file's phases: every export case and every server case (``--exports N --server N`` to sample)."""
    return standalone(argv, exports=-1, server=-1, description=__doc__.split("\n\n")[0])


if __name__ == "__main__":
    raise SystemExit(main())
