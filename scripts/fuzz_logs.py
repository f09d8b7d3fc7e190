"""The logs phase of the fuzz campaign (issue 45): crafted flight logs, each read by one command in its own process.

Called by ``scripts/fuzz_campaign.py`` as ``run_logs_phase(fz, campaign, fx, n)`` (``n`` < 0: every case, else a
seeded sample of ``n`` spread over the kinds); ``python scripts/fuzz_logs.py`` runs this phase alone.
The cases (``scripts/fuzz_log_cases.py``: ``bb-*`` Betaflight blackbox, ``cf-*`` Crazyflie, ``ulog``) are made
from the real logs in ../shared/data/flight-logs, not only mutated at random: every numeric header field at 0,
-1, huge, text, empty and nan; 0 to 10,000 fields; names twice; encodings and predictors out of range; cuts at
every section boundary; memory and time bombs; Crazyflie names twice, ``t`` and ``id``, bad types, every
timestamp bit flipped; damaged ULogs.

Each case runs one command (``log info --json`` mostly; ``log export``, ``log plot``, ``identify --log``) as a
fresh ``python -m aerobat`` process, and is judged as the campaign judges (``fz.judge``: exit 0, 2 with one
``aerobat: error:`` line that names the header field where the case is bad by construction, or 1; anything else,
a traceback or exit 70 is *internal*). Besides:

- *hangs*: not finished within its budget (it is then sent SIGINT, as Ctrl-C would; one that ignores it too is
  killed after 10 s);
- *non_json*: a ``--json`` output that ``json.loads`` with ``parse_constant`` refusing NaN and Infinity does not
  read, or a CSV on standard output that does not start with its header line;
- *data_loss*: the input file changed; a file cut later read with fewer samples than one cut earlier; a Crazyflie
  file with one damaged timestamp losing more than one record, or cut after whole records losing one of them;
- *peak_memory*: each process's peak resident memory (``os.wait4``'s ``ru_maxrss``, taken by a small launcher
  between the campaign and the command) against 300 MB + 20 times the file's size; the worst case and every case
  over it.

Each finding carries ``reproduce``: the command that rebuilds its file (kept with ``--keep``) and runs it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.util
import json
import os
import random
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

BUDGET_S = {"info": 30.0, "export": 30.0, "export-stdout": 30.0, "plot": 60.0, "identify": 120.0}
MEMORY_MB, MEMORY_PER_BYTE = 300.0, 20.0


def _cases_module() -> Any:
    """``scripts/fuzz_log_cases.py``, loaded from next to this file however this one was loaded."""
    spec = importlib.util.spec_from_file_location("fuzz_log_cases", Path(__file__).with_name("fuzz_log_cases.py"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_log_cases"] = module
    spec.loader.exec_module(module)
    return module


CASES = _cases_module()
DATA, KINDS, LogCase, build_cases = CASES.DATA, CASES.KINDS, CASES.LogCase, CASES.build_cases


def _no_constant(text: str) -> Any:
    raise ValueError(f"{text} is not JSON")


def _argv(case: LogCase, path: Path, work: Path) -> list[str]:
    file = str(path)
    index = ["--index", case.log] if case.log and case.command != "identify" else []
    return {"info": ["log", "info", file, *index, "--json"],
            "export": ["log", "export", file, *index, "--out", str(work / "csv"), "--json"],
            "export-stdout": ["log", "export", file, *index],
            "plot": ["log", "plot", file, *index, "--out", str(work / "figures"), "--json"],
            "identify": ["identify", "--log", file + case.log, "--output", str(work / "v.toml"), "--json"],
            }[case.command]


# Runs one command and writes its pid, then its exit status and peak memory [kB]. A process's peak counts what it
# held before exec, and a forked child holds its parent's pages: this small process (python -S) stands between
# the campaign's (hundreds of MB) and the command measured.
LAUNCHER = """
import os, sys
pid = os.posix_spawn(sys.argv[2], sys.argv[2:], os.environ)
with open(sys.argv[1], "w") as f:
    f.write(f"{pid}\\n")
_, status, usage = os.wait4(pid, 0)
with open(sys.argv[1], "a") as f:
    f.write(f"{os.waitstatus_to_exitcode(status)} {usage.ru_maxrss}\\n")
"""


@dataclasses.dataclass
class Running:
    case: LogCase
    index: int
    path: Path
    work: Path
    argv: list[str]
    process: subprocess.Popen[bytes]
    started: float
    digest: str
    interrupted: float = 0.0
    killed: bool = False


def _launch(case: LogCase, index: int, root: Path, env: dict[str, str]) -> Running:
    work = root / f"c{index}"
    work.mkdir(parents=True, exist_ok=True)
    path = work / ("log.ulg" if case.kind == "ulog" else "log" if case.kind.startswith("cf") else "log.bbl")
    data = case.make()
    path.write_bytes(data)
    argv = _argv(case, path, work)
    with open(work / "out", "wb") as out, open(work / "err", "wb") as err:
        process = subprocess.Popen([sys.executable, "-S", "-c", LAUNCHER, str(work / "status"), sys.executable, "-m",
                                    "aerobat", *argv], stdout=out, stderr=err, stdin=subprocess.DEVNULL, cwd=work,
                                   env=env, start_new_session=True)
    return Running(case, index, path, work, argv, process, time.perf_counter(), hashlib.sha256(data).hexdigest())


def _samples(document: Any) -> int:
    """Gyro (else any) samples over the logs of a ``log info --json`` document."""
    total = 0
    for log in document.get("logs", []):
        signals = log.get("signals", {})
        series = signals.get("gyro") or next(iter(signals.values()), {"samples": 0})
        total += int(series["samples"])
    return total


def run_logs_phase(fz: Any, campaign: Any, fx: Any, n: int, *, workers: int = 2, only: str | None = None,
                   keep: bool = False) -> None:
    """Run the crafted-log cases (all if ``n`` < 0, else a seeded sample of ``n`` spread over the kinds), ``workers``
    processes at a time, into ``campaign.report["logs"]``.

    ``fx`` (the campaign's fixtures) is not needed: no log command opens the store. ``only``: the cases whose
    label holds it (or one of its comma-separated parts); ``keep``: leave each case's folder (its file, outputs
    and streams) under ``campaign.root / "logs"``.
    """
    import aerobat

    report: dict[str, Any] = {"requested": n, "kinds": list(KINDS), "cases": 0, "counts": Counter(), "by_kind": {},
                              "internal": [], "hangs": [], "data_loss": [], "non_json": [],
                              "peak_memory": {"worst_mb": 0.0, "bound_mb": 0.0, "worst_fraction_of_bound": 0.0,
                                              "case": None, "over_bound": [], "highest": []}}
    campaign.report["logs"] = report
    if not DATA.is_dir():
        report["skipped"] = f"the real flight logs are not here ({DATA} is absent)"
        campaign.say(f"fuzz: logs phase skipped: {report['skipped']}")
        return
    started = time.perf_counter()
    cases = [c for c in build_cases() if only is None or any(part in c.label for part in only.split(","))]
    if 0 <= n < len(cases):
        rng = random.Random(campaign.seed + 45)
        by_kind = {k: [c for c in cases if c.kind == k] for k in KINDS}
        picked: list[LogCase] = []
        while len(picked) < n:
            for kind in KINDS:
                if by_kind[kind] and len(picked) < n:
                    picked.append(by_kind[kind].pop(rng.randrange(len(by_kind[kind]))))
        cases = picked
    report["cases"] = len(cases)
    root = campaign.root / "logs"
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": os.pathsep.join(
        [str(Path(aerobat.__file__).resolve().parents[1]), *filter(None, [os.environ.get("PYTHONPATH")])])}
    cuts: dict[str, list[tuple[int, int, str]]] = {}
    pending, running, done = list(enumerate(cases)), [], 0
    while pending or running:
        while pending and len(running) < max(workers, 1):
            index, case = pending.pop(0)
            campaign.current = {"phase": "logs", "index": index, "case": case.label}
            running.append(_launch(case, index, root, env))
        time.sleep(0.02)
        for run in list(running):
            elapsed = time.perf_counter() - run.started
            if run.process.poll() is None:
                lines = (run.work / "status").read_text().split() if (run.work / "status").exists() else []
                if not run.interrupted and elapsed > BUDGET_S[run.case.command] and lines:
                    os.kill(int(lines[0]), signal.SIGINT)  # Ctrl-C, to the command
                    run.interrupted = elapsed
                elif run.interrupted and elapsed > run.interrupted + 10.0 and not run.killed:
                    os.killpg(run.process.pid, signal.SIGKILL)  # the launcher and the command
                    run.killed = True
                continue
            running.remove(run)
            status = (run.work / "status").read_text().split()
            code, peak_kb = (int(status[1]), int(status[2])) if len(status) == 3 else (-9, 0)
            judge_case(fz, run, code, peak_kb / 1024.0, elapsed, report, cuts, campaign, keep)
            done += 1
            if done % 50 == 0 or done == len(cases):
                memory = report["peak_memory"]
                campaign.say(f"fuzz: logs {done}/{len(cases)}: " + " ".join(
                    f"{c}={v}" for c, v in sorted(report["counts"].items())) + f"  worst memory "
                    f"{memory['worst_mb']:.0f} MB ({memory['worst_fraction_of_bound']:.2f} of its bound)")
    for group, points in cuts.items():  # a file cut later keeps at least what one cut earlier kept
        points.sort()
        for (p0, s0, l0), (p1, s1, l1) in zip(points, points[1:], strict=False):
            if s1 < s0:
                report["data_loss"].append({"case": l1, "reason": f"{group}: cut at byte {p1} read {s1} samples, "
                                            f"fewer than the {s0} of the cut at byte {p0} ({l0})",
                                            "reproduce": _reproduce(l1)})
    report["wall_s"] = round(time.perf_counter() - started, 1)
    if not keep:
        shutil.rmtree(root, ignore_errors=True)


def _reproduce(label: str) -> str:
    return f"python scripts/fuzz_logs.py --case {shlex.quote(label)} --keep"


def judge_case(fz: Any, run: Running, code: int, peak_mb: float, seconds: float, report: dict[str, Any],
           cuts: dict[str, list[tuple[int, int, str]]], campaign: Any, keep: bool) -> None:
    case = run.case
    out = (run.work / "out").read_bytes()[:4_000_000].decode("utf-8", "replace")
    err = (run.work / "err").read_bytes()[-20_000:].decode("utf-8", "replace")
    entry = {"index": run.index, "kind": case.kind, "case": case.label, "argv": run.argv, "exit": code,
             "seconds": round(seconds, 2), "peak_mb": round(peak_mb, 1), "stderr": err[-1500:],
             "reproduce": _reproduce(case.label)}
    inv = fz.Invocation(run.argv, case.command, case.bad, case.why)
    if run.interrupted:
        klass = "HANG"
        entry["reason"] = (f"not finished within {BUDGET_S[case.command]:g} s; "
                           + ("it ignored Ctrl-C and was killed" if run.killed else f"Ctrl-C stopped it (exit {code})"))
        report["hangs"].append(entry)
    else:
        klass, entry["reason"] = fz.judge(inv, "returned", code, out, err, "", 0)
        if klass == "INTERNAL":
            report["internal"].append(entry)
    size = run.path.stat().st_size if run.path.exists() else 0
    bound = MEMORY_MB + MEMORY_PER_BYTE * size / 2**20
    memory = report["peak_memory"]
    if peak_mb / bound > memory["worst_fraction_of_bound"]:
        memory.update(worst_mb=round(peak_mb, 1), bound_mb=round(bound, 1),
                      worst_fraction_of_bound=round(peak_mb / bound, 3), case=case.label)
    if peak_mb > bound:
        memory["over_bound"].append({**entry, "bound_mb": round(bound, 1)})
    memory["highest"] = sorted([*memory["highest"], [round(peak_mb / bound, 3), round(peak_mb, 1), round(bound, 1),
                                                     case.label, case.command]], reverse=True)[:10]
    document = None
    if "--json" in run.argv and out.strip():
        try:
            document = json.loads(out, parse_constant=_no_constant)
        except ValueError as exc:
            report["non_json"].append({**entry, "reason": f"--json printed what is not JSON: {exc}"[:300],
                                       "stdout": out[:500]})
    elif case.command == "export-stdout" and code == 0 and not re.match(r"(time_s|signal),", out):
        report["non_json"].append({**entry, "reason": "the CSV on standard output does not start with its header",
                                   "stdout": out[:500]})
    lost = None
    if not run.path.exists() or hashlib.sha256(run.path.read_bytes()).hexdigest() != run.digest:
        lost = "the input file was changed"
    samples = _samples(document) if code == 0 and case.command == "info" and isinstance(document, dict) else 0
    if case.group and case.command == "info" and not run.interrupted and klass != "INTERNAL":
        cuts.setdefault(case.group, []).append((case.position, samples, case.label))
    if case.records >= 0 and case.command == "info" and samples < case.records:
        lost = f"read {samples} records where {case.records} are whole and in time order (exit {code})"
    if lost is not None:
        report["data_loss"].append({**entry, "reason": lost})
    report["counts"][klass] += 1
    report["by_kind"].setdefault(case.kind, Counter())[klass] += 1
    if klass in ("INTERNAL", "HANG") or lost is not None or peak_mb > bound:
        last = (err.strip().splitlines() or [""])[-1][:300]
        campaign.say(f"fuzz: logs {klass} {case.label}: {lost or entry['reason']} (peak {peak_mb:.0f} MB of "
                     f"{bound:.0f})\n  reproduce: {entry['reproduce']}\n  {last}")
    if not keep:
        shutil.rmtree(run.work, ignore_errors=True)


def findings(report: dict[str, Any]) -> int:
    """Internal errors, hangs, data loss, non-JSON outputs and cases over the memory bound, in all."""
    return (len(report["internal"]) + len(report["hangs"]) + len(report["data_loss"]) + len(report["non_json"])
            + len(report["peak_memory"]["over_bound"]))


def main(argv: list[str] | None = None) -> int:
    """Only the logs phase, in a scratch folder: ``python scripts/fuzz_logs.py [--logs N] [--report FILE]``."""
    import argparse
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--logs", type=int, default=-1, help="cases: -1 all, N a seeded sample spread over the kinds")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sample")
    parser.add_argument("--workers", type=int, default=2, help="cases run side by side")
    parser.add_argument("--case", default=None,
                        help="only the cases whose label holds this text (or one of these, comma-separated)")
    parser.add_argument("--report", type=Path, default=None, help="write the JSON report here")
    parser.add_argument("--keep", action="store_true", help="keep the scratch folder and the cases' files")
    args = parser.parse_args(argv)
    spec = importlib.util.spec_from_file_location("fuzz_campaign", Path(__file__).with_name("fuzz_campaign.py"))
    assert spec is not None and spec.loader is not None
    fz = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_campaign"] = fz
    spec.loader.exec_module(fz)
    root = Path(tempfile.mkdtemp(prefix="aerobat-fuzz-logs-"))
    campaign = fz.Campaign(seed=args.seed, budget_s=6.0, root=root, progress=lambda text: print(text, flush=True))
    campaign.report_path = args.report
    try:
        run_logs_phase(fz, campaign, None, args.logs, workers=args.workers, only=args.case, keep=args.keep)
    finally:
        campaign.alarm.close()
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)
    report = campaign.report["logs"]
    campaign.report["wall_s"] = report.get("wall_s", 0.0)
    campaign.write_report()
    memory = report["peak_memory"]
    print(f"fuzz: logs done in {report.get('wall_s', 0):.0f} s: {report['cases']} cases "
          + " ".join(f"{c}={v}" for c, v in sorted(report["counts"].items()))
          + f"; internal {len(report['internal'])}, hangs {len(report['hangs'])}, data loss "
          f"{len(report['data_loss'])}, non-JSON {len(report['non_json'])}; worst memory {memory['worst_mb']} MB "
          f"of {memory['bound_mb']} MB ({memory['case']}), {len(memory['over_bound'])} over"
          + (f"; kept in {root}" if args.keep else ""))
    return 1 if findings(report) else 0


if __name__ == "__main__":
    raise SystemExit(main())
