"""The store's commands: ``sessions``, ``show``, ``plot``, ``export`` and ``studies``."""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import sys
from pathlib import Path
from typing import Any

from aerobat.cli.common import HelpFormatter, add_db_option, bounded_int, console, open_store, output_dir, session_ref
from aerobat.cli.show import print_stored_session
from aerobat.errors import ConfigError, OutputError

__all__ = ["refuse_overwrite", "register"]


def refuse_overwrite(path: Path, *, store_path: Path | None, force: bool, option: str) -> None:
    """Refuse to write over the store itself (ever) or over an existing file (unless ``force``)."""
    if store_path is not None and path.exists() and store_path.exists():
        for candidate in (store_path, Path(f"{store_path}-wal"), Path(f"{store_path}-shm")):
            if candidate.exists() and os.path.samefile(path, candidate):
                raise ConfigError(f"{option} {path}: that is the experiment store; choose another file")
    if path.exists() and not force:
        raise ConfigError(f"{option} {path}: the file exists; choose another name or pass --force to replace it")
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a folder, expected a file")


def _table(rows: list[tuple[str, ...]], right: set[int]) -> str:
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]))]
    lines = ["  ".join(cell.rjust(w) if k in right else cell.ljust(w)
                       for k, (cell, w) in enumerate(zip(row, widths, strict=True))).rstrip() for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines) + "\n"


def _cmd_sessions(args: argparse.Namespace) -> int:
    with open_store(args, create=False) as store:
        rows = store.list_sessions(limit=args.limit, newest_first=args.limit is not None)
        if args.limit is not None:
            rows.reverse()
        if args.study is not None:
            study_id = store.resolve_study(args.study)
            rows = [r for r in rows if r.study_id == study_id]
        if args.json:
            print(json.dumps([{
                "id": r.id, "maneuver": r.maneuver_name, "plant": r.plant_kind, "seed": r.seed,
                "iterations": r.n_measured, "trials": r.n_records, "target": r.target_iterations,
                "last_position_error_m": r.last_position_error_m, "state": r.display_state, "study": r.study_id,
                "started_at": r.started_at, "updated_at": r.updated_at} for r in rows]))
            return 0
        if not rows:
            print(f"no sessions in {store.path}")
            return 0
        header = ("id", "maneuver", "plant", "seed", "iter.", "last err [m]", "state", "started (UTC)")
        table = [header] + [(
            str(r.id), r.maneuver_name, r.plant_kind, "—" if r.seed is None else str(r.seed),
            f"{r.n_measured}/{r.target_iterations}",
            "—" if r.last_position_error_m is None else f"{r.last_position_error_m:.4f}",
            r.display_state if r.study_id is None else f"{r.display_state} (study {r.study_id})",
            r.started_at[:16].replace("T", " ")) for r in rows]
        sys.stdout.write(_table(table, {0, 3, 4, 5}))
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from aerobat.experiments.reports import session_json

    with open_store(args, create=False) as store:
        session_id = store.resolve_session(args.session)
        if args.json:
            print(json.dumps(session_json(store, session_id, full=True)))
        else:
            print_stored_session(store, session_id, iterations=True, header=True, full=args.full)
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    from aerobat.experiments.reports import session_figures

    with open_store(args, create=False) as store:
        session_id = store.resolve_session(args.session)
        out = output_dir(args.out if args.out is not None else f"out/session-{session_id}")
        notes = session_figures(store, session_id, out)
    for note in notes:
        print(note)
    print(f"figures of session {session_id} in {out}/")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from aerobat.experiments.reports import finite_or_none, session_json

    if args.trajectories and args.format != "json":
        raise ConfigError("--trajectories: only with --format json")
    with open_store(args, create=False) as store:
        session_id = store.resolve_session(args.session)
        output = Path(args.output) if args.output else None
        if output is not None:
            refuse_overwrite(output, store_path=store.path, force=args.force, option="--output")
        if args.format == "json":
            text = json.dumps(session_json(store, session_id, trajectories=args.trajectories, full=True),
                              indent=1) + "\n"
        else:
            rec = store.session(session_id)
            mrec = store.maneuver(rec.maneuver_id)
            buffer = io.StringIO()
            writer = csv.writer(buffer, lineterminator="\n")
            units = list(zip(mrec.parameter_names, mrec.parameter_units, strict=True))
            writer.writerow(["session", "i", "correction", "status", "gamma", "scale",
                             *(f"{n} [{u}]" for n, u in units), *(f"next {n} [{u}]" for n, u in units),
                             *(f"error {n} [{u}]" for n, u in zip(mrec.error_names, mrec.error_units, strict=True)),
                             "message", "recorded_at"])
            for it in store.iterations(session_id):
                writer.writerow([session_id, it.index, it.correction, it.status, repr(it.gamma), repr(it.scale),
                                 *(repr(float(v)) for v in it.params), *(repr(float(v)) for v in it.next_params),
                                 *("" if v is None else repr(v) for v in finite_or_none(it.error)),
                                 it.message, it.recorded_at])
            text = buffer.getvalue()
    if output is not None:
        try:
            output.write_text(text)
        except OSError as exc:
            raise OutputError(f"--output {output}: cannot write: {exc.strerror or exc}") from None
        print(f"session {session_id} written to {output}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0


def _cmd_studies(args: argparse.Namespace) -> int:
    with open_store(args, create=False) as store:
        if args.study is not None:
            return _show_study(store, args)
        studies = store.list_studies()
        if args.json:
            print(json.dumps([{"id": s.id, "kind": s.kind, "created_at": s.created_at, "jobs_done": s.jobs_done,
                               "jobs_failed": s.jobs_failed, "out_dir": s.out_dir} for s in studies]))
            return 0
        if not studies:
            print(f"no studies in {store.path}")
            return 0
        rows = [("id", "kind", "jobs done", "failed", "created (UTC)", "output")] + [
            (str(s.id), s.kind, str(s.jobs_done), str(s.jobs_failed), s.created_at[:16].replace("T", " "),
             s.out_dir or "—") for s in studies]
        sys.stdout.write(_table(rows, {0, 2, 3}))
    return 0


def _show_study(store: Any, args: argparse.Namespace) -> int:
    study_id = store.resolve_study(args.study)
    study = store.study(study_id)
    jobs = store.study_jobs(study_id)
    sessions = store.study_sessions(study_id)
    if args.json:
        print(json.dumps({"id": study.id, "kind": study.kind, "spec": study.spec, "created_at": study.created_at,
                          "command": list(study.command), "out_dir": study.out_dir,
                          "jobs": [{"key": j.key, "status": j.status, "error": j.error, "attempts": j.attempts,
                                    "session": j.session_id} for j in jobs]}))
        return 0
    out = console()
    out.print(f"study {study.id}: {study.kind}, created {study.created_at[:19].replace('T', ' ')} UTC")
    if study.command:
        out.print(f"  command: aerobat {' '.join(study.command)}")
    out.print(f"  jobs: {study.jobs_done} done, {study.jobs_failed} failed; {len(sessions)} sessions in the store")
    if study.out_dir:
        out.print(f"  report and figures: {study.out_dir}")
    for job in jobs:
        if job.status == "failed":
            out.print(f"  failed: {job.key} (attempt {job.attempts}): {job.error}")
    if sessions:
        shown = ", ".join(str(s.id) for s in sessions[:20]) + (" …" if len(sessions) > 20 else "")
        out.print(f"  sessions: {shown} (`aerobat sessions --study {study.id}`)")
    return 0


def register(sub: Any) -> None:
    fmt = HelpFormatter
    ses = sub.add_parser("sessions", help="list the stored learning sessions", formatter_class=fmt)
    ses.add_argument("--limit", type=bounded_int(1, 10**9), default=None,
                     help="only the newest N sessions (default: all)")
    ses.add_argument("--study", type=session_ref, default=None,
                     help="only the sessions of this study (default: all)")
    ses.add_argument("--json", action="store_true", help="print one JSON array")
    add_db_option(ses)
    ses.set_defaults(func=_cmd_sessions)

    show = sub.add_parser("show", help="a stored session: summary and per-iteration table", formatter_class=fmt)
    show.add_argument("session", type=session_ref, help="session id or 'last' (required)")
    show.add_argument("--full", action="store_true", help="one column per error component (wide)")
    show.add_argument("--json", action="store_true", help="print everything stored (no trajectories) as JSON")
    add_db_option(show)
    show.set_defaults(func=_cmd_show)

    plot = sub.add_parser("plot", help="learning figures of a stored session, from stored data alone",
                          formatter_class=fmt)
    plot.add_argument("session", type=session_ref, help="session id or 'last' (required)")
    plot.add_argument("--out", default=None, metavar="DIR",
                      help="folder for learning.png, side_views.png (default: out/session-ID)")
    add_db_option(plot)
    plot.set_defaults(func=_cmd_plot)

    export = sub.add_parser("export", help="a stored session as CSV (one row per iteration) or JSON",
                            formatter_class=fmt)
    export.add_argument("session", type=session_ref, help="session id or 'last' (required)")
    export.add_argument("--format", choices=("csv", "json"), default="csv", help="output format")
    export.add_argument("--output", metavar="FILE", help="write to FILE (default: standard output)")
    export.add_argument("--force", action="store_true", help="replace --output if it exists (never the store)")
    export.add_argument("--trajectories", action="store_true", help="include measured trajectories (json)")
    add_db_option(export)
    export.set_defaults(func=_cmd_export)

    studies = sub.add_parser("studies", help="list the stored studies, or show one", formatter_class=fmt)
    studies.add_argument("study", nargs="?", type=session_ref, default=None,
                         help="a study id or 'last' to show (default: list all)")
    studies.add_argument("--json", action="store_true", help="print JSON")
    add_db_option(studies)
    studies.set_defaults(func=_cmd_studies)
