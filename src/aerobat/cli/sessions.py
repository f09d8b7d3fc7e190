"""The store's commands: ``sessions``, ``show``, ``plot``, ``export`` and ``studies``."""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from pathlib import Path
from typing import Any

from aerobat.cli import curate
from aerobat.cli.common import (
    HelpFormatter,
    add_db_option,
    bounded_int,
    check_outputs,
    console,
    open_store,
    output_dir,
    refuse_overwrite,
    session_folder,
    session_ref,
)
from aerobat.cli.curate import table
from aerobat.cli.show import print_stored_session
from aerobat.errors import ConfigError, OutputError
from aerobat.fileio import check_output, write_output
from aerobat.store.query import SHOWN_STATES, SessionQuery
from aerobat.store.records import JobStatus

__all__ = ["register"]


def _cmd_sessions(args: argparse.Namespace) -> int:
    with open_store(args, create=False) as store:
        filters = {"plant": args.plant, "maneuver": args.maneuver, "vehicle": args.vehicle,
                   "feedback": args.feedback, "status": args.status, "study": args.study, "tag": args.tag,
                   "rule": args.rule, "text": args.search, "since": args.since, "until": args.until}
        study = None if args.study is None else store.resolve_study(args.study)
        found = store.query_sessions(SessionQuery(**{**filters, "study": study}, include_studies=args.all,
                                                  descending=args.limit is not None, limit=args.limit))
        rows = list(reversed(found.rows)) if args.limit is not None else list(found.rows)  # oldest first
        hidden = found.hidden
        if args.json:
            print(json.dumps([{
                "id": r.id, "maneuver": r.maneuver_name, "plant": r.plant_kind, "vehicle": r.vehicle,
                "plant_vehicle": r.plant_vehicle, "feedback": r.feedback, "seed": r.seed,
                "rule": r.rule, "iterations": r.n_measured, "trials": r.n_records, "target": r.target_iterations,
                "last_position_error_m": _last_error(r), "state": r.display_state, "study": r.study_id,
                "tags": list(r.tags), "started_at": r.started_at, "updated_at": r.updated_at} for r in rows]))
            return 0
        more = f" ({hidden} study sessions hidden: --all shows them)" if hidden else ""
        if not rows:
            print(f"no sessions in {store.path}{' match' if any(v is not None for v in filters.values()) else ''}"
                  f"{more}")
            return 0
        header = ("id", "maneuver", "plant", "vehicle", "feedback", "rule", "seed", "iter.", "last err [m]", "state",
                  "started (UTC)", "tags")
        rows_text = [header] + [(
            str(r.id), r.maneuver_name, r.plant_kind,
            r.vehicle if r.plant_vehicle in ("", r.vehicle) else f"{r.vehicle} (flown: {r.plant_vehicle})",
            r.feedback, r.rule or "—", "—" if r.seed is None else str(r.seed), f"{r.n_measured}/{r.target_iterations}",
            "—" if _last_error(r) is None else f"{_last_error(r):.4f}",
            r.display_state if r.study_id is None else f"{r.display_state} (study {r.study_id})",
            r.started_at[:16].replace("T", " "), ",".join(r.tags)) for r in rows]
        sys.stdout.write(table(rows_text, {0, 6, 7, 8}))
        if more:
            print(more.strip(" ()"))
    return 0


def _last_error(row: Any) -> float | None:
    """A session's last position error; None for an identification, whose flights have no target to miss."""
    return None if row.maneuver_name.startswith("identification (") else row.last_position_error_m


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
        out = session_folder(args, store, session_id)
        check_outputs({out / name: "--out" for name in ("learning.png", "side_views.png")}, stores=(store.path,))
        before = {p: p.stat().st_mtime_ns for p in out.glob("*.png") if p.is_file()}
        notes = session_figures(store, session_id, out)
    written = sorted(str(p) for p in out.glob("*.png") if before.get(p) != p.stat().st_mtime_ns)
    if args.json:
        print(json.dumps({"session": session_id, "folder": str(out), "figures": written, "notes": notes}))
        return 0
    for note in notes:
        print(note)
    print(f"figures of session {session_id} in {out}/")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from aerobat.experiments.reports import finite_or_none, session_json

    if args.trajectories and (args.format or ("json" if args.json else "csv")) != "json":
        raise ConfigError("--trajectories: only with --format json")
    if args.iteration is not None and args.program is None:
        raise ConfigError("--iteration: only with --program")
    if args.format == "mcap" and (args.output is None or args.program is not None):
        raise ConfigError("--format mcap: give --output FILE.mcap (an MCAP file is binary; not with --program)")
    if args.json and args.output is None and args.program is None:
        if args.format == "csv":
            raise ConfigError("--json with --format csv: --json prints JSON; give --output FILE for the CSV")
        args.format = "json"  # the export itself is the JSON
    args.format = args.format or "csv"
    with open_store(args, create=False) as store:
        session_id = store.resolve_session(args.session)
        store.verify_session(session_id)  # nothing is exported from a session with a damaged record
        if args.program is not None:
            return _export_program(store, session_id, args)
        if args.format == "mcap":
            return _export_mcap(store, session_id, args)
        if args.output is not None and not args.output.strip():  # Path("") is "."
            raise ConfigError("--output: empty file name")
        output = Path(args.output) if args.output is not None else None
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
        write_output(output, text, option="--output", stores=(store.path,))
        if args.json:
            print(json.dumps({"session": session_id, "written": str(output), "format": args.format}))
        else:
            print(f"session {session_id} written to {output}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0


def _export_mcap(store: Any, session_id: int, args: argparse.Namespace) -> int:
    """The session's trials as an MCAP file (Foxglove, PlotJuggler): poses, states, commands, errors."""
    from aerobat.export import write_session_mcap

    output = Path(args.output)
    refuse_overwrite(output, store_path=store.path, force=args.force, option="--output")
    summary = write_session_mcap(store, session_id, output)
    if args.json:
        print(json.dumps({"session": session_id, "written": str(output), "format": "mcap",
                          "trials": len(summary.trials), "messages": summary.messages,
                          "start_ns": summary.start_ns, "end_ns": summary.end_ns}))
    else:
        print(f"session {session_id}: {len(summary.trials)} trials, {sum(summary.messages.values())} messages "
              f"written to {output} (open it in Foxglove or PlotJuggler)", file=sys.stderr)
    return 0


def _export_program(store: Any, session_id: int, args: argparse.Namespace) -> int:
    """The program a session flew at an iteration (default: the learned parameters), as a file ``fly`` reads."""
    import dataclasses

    from aerobat import __version__
    from aerobat.core.registry import from_spec
    from aerobat.quadrotor.program import save_program

    path = Path(args.program)
    refuse_overwrite(path, store_path=store.path, force=args.force, option="--program")
    rec = store.session(session_id)
    maneuver = from_spec(store.maneuver(rec.maneuver_id).spec, source=f"{store.path}: session {session_id} maneuver")
    if args.iteration is None:
        params, what = rec.current_params, f"the learned parameters after iteration {rec.last_index}"
    else:
        found = store.iterations(session_id, indices=[args.iteration])
        if not found:
            raise ConfigError(f"--iteration {args.iteration}: session {session_id} has iterations 1 … "
                              f"{rec.last_index}")
        params, what = found[0].params, f"the parameters flown at iteration {args.iteration}"
    program = dataclasses.replace(maneuver.program(params), provenance=(
        f"aerobat {__version__}: session {session_id} of {store.path} ({rec.maneuver_name} on {rec.plant_kind}), "
        f"{what}"))
    try:
        save_program(program, path)
    except OSError as exc:
        raise OutputError(f"--program {path}: cannot write: {exc.strerror or exc}") from None
    if args.json:
        print(json.dumps({"session": session_id, "written": str(path), "program": what}))
    else:
        print(f"program of session {session_id} ({what}) written to {path}; fly it with `aerobat fly {path}`")
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
        sys.stdout.write(table(rows, {0, 2, 3}))
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
        if job.status is JobStatus.FAILED:
            out.print(f"  failed: {job.key} (attempt {job.attempts}): {job.error}")
    if sessions:
        shown = ", ".join(str(s.id) for s in sessions[:20]) + (" …" if len(sessions) > 20 else "")
        out.print(f"  sessions: {shown} (`aerobat sessions --study {study.id}`)")
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from aerobat.experiments.reports import replay_notes, session_replay

    iterations = None
    if args.iterations is not None:
        try:
            iterations = sorted({int(v) for v in args.iterations.split(",") if v.strip()})
        except ValueError:
            raise ConfigError(f"--iterations {args.iterations!r}: expected a comma list of iteration numbers") from None
    with open_store(args, create=False) as store:
        session_id = store.resolve_session(args.session)
        out = session_folder(args, store, session_id)
        check_outputs({out / "replay.html": "--out"}, stores=(store.path,))
        path = session_replay(store, session_id, out / "replay.html", iterations=iterations)
        notes = replay_notes(store, session_id, iterations)
        if str(args.session) == "last" and store.session(session_id).study_id is not None:
            notes.insert(0, f"last is session {session_id}, the newest session, which a study learned in "
                            f"(`aerobat sessions` lists the others)")
    if args.json:
        print(json.dumps({"session": session_id, "replay": str(path), "notes": notes}))
    else:
        for note in notes:
            print(f"note: {note}")
        print(f"3D replay of session {session_id} in {path} (open it in a browser; no server needed)")
    return 0


def _stores_of(args: argparse.Namespace) -> tuple[Any, ...]:
    """The store ``--db`` names (if the command has it); the default store is always protected."""
    db = getattr(args, "db", None)
    return (db,) if db is not None else ()


def _cmd_examples(args: argparse.Namespace) -> int:
    """Copy the shipped examples (programs, maneuver files, a Python maneuver) into a folder."""
    from importlib.resources import files

    source = files("aerobat") / "examples"
    target = output_dir(args.folder, "FOLDER")
    entries = [entry for entry in sorted(Path(str(source)).rglob("*")) if not entry.is_dir()
               and entry.suffix in (".toml", ".py") and "__pycache__" not in entry.parts]
    # every destination is checked before the first copy: never the store (whatever the links), never an
    # existing file without --force; each copy then replaces its name (a link there is replaced, not followed)
    for entry in entries:
        output_dir(target / entry.relative_to(Path(str(source))).parent)
        check_output(target / entry.relative_to(Path(str(source))), option=None, force=args.force,
                     stores=_stores_of(args))
    copied = []
    for entry in entries:
        relative = entry.relative_to(Path(str(source)))
        write_output(target / relative, entry.read_bytes(), stores=_stores_of(args))
        copied.append(str(relative))
    if args.json:
        print(json.dumps({"folder": str(target), "files": copied}))
    else:
        print(f"{len(copied)} examples copied to {target}/: {', '.join(copied)}")
    return 0


def _day(text: str) -> str:
    """A day, ``YYYY-MM-DD`` (argparse names the option in its refusal)."""
    import datetime

    try:
        return datetime.date.fromisoformat(text.strip()).isoformat()
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a day, YYYY-MM-DD") from None


def register(sub: Any) -> None:
    fmt = HelpFormatter
    ses = sub.add_parser("sessions", help="list the stored learning sessions", formatter_class=fmt)
    ses.add_argument("--limit", type=bounded_int(1, 10**9), default=None,
                     help="only the newest N sessions (default: all)")
    ses.add_argument("--study", type=session_ref, default=None,
                     help="only the sessions of this study, an id or 'last' (default: no study's)")
    ses.add_argument("--plant", default=None, help="only this plant: nominal, arena, rotorpy, … (default: any)")
    ses.add_argument("--maneuver", default=None, help="only this maneuver, by name (default: any)")
    ses.add_argument("--vehicle", default=None,
                     help="only this vehicle, the design model's or the flown one's name (default: any)")
    ses.add_argument("--feedback", default=None,
                     help="only this feedback scheme; none is the paper's open loop (default: any)")
    ses.add_argument("--status", choices=SHOWN_STATES, default=None, help="only sessions in this state (default: any)")
    ses.add_argument("--tag", default=None, help="only sessions with this tag (`aerobat tag`) (default: any)")
    ses.add_argument("--rule", default=None, help="only this update rule: paper, broyden, … (default: any)")
    ses.add_argument("--search", metavar="TEXT", default=None,
                     help="only sessions whose maneuver, plant, vehicle, feedback, rule, tags or notes contain TEXT "
                          "(default: no search)")
    ses.add_argument("--since", metavar="YYYY-MM-DD", type=_day, default=None,
                     help="only sessions started on this day (UTC) or later (default: any)")
    ses.add_argument("--until", metavar="YYYY-MM-DD", type=_day, default=None,
                     help="only sessions started on this day (UTC) or earlier (default: any)")
    ses.add_argument("--all", action="store_true",
                     help="also list the sessions studies learned in (default: hidden, a study stores hundreds)")
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
                      help="folder for learning.png, side_views.png "
                           "(default: out/STORE-HASH/session-ID, one per store and session)")
    plot.add_argument("--json", action="store_true", help="print one JSON object: the figures written")
    add_db_option(plot)
    plot.set_defaults(func=_cmd_plot)

    export = sub.add_parser("export", help="a stored session as CSV (one row per iteration), JSON or MCAP",
                            formatter_class=fmt)
    export.add_argument("session", type=session_ref, help="session id or 'last' (required)")
    export.add_argument("--format", choices=("csv", "json", "mcap"), default=None,
                        help="output format; mcap (Foxglove, PlotJuggler) needs --output (default: csv; json with "
                             "--json)")
    export.add_argument("--output", metavar="FILE", help="write to FILE (default: standard output)")
    export.add_argument("--force", action="store_true", help="replace --output if it exists (never the store)")
    export.add_argument("--trajectories", action="store_true", help="include measured trajectories (json)")
    export.add_argument("--program", metavar="FILE.toml", default=None,
                        help="write the session's learned program instead (default: no program)")
    export.add_argument("--iteration", type=bounded_int(1, 10**9), default=None,
                        help="with --program: the program flown at this iteration (default: the learned one)")
    export.add_argument("--json", action="store_true",
                        help="print JSON: the export itself, or with --output/--program what was written")
    add_db_option(export)
    export.set_defaults(func=_cmd_export)

    replay = sub.add_parser("replay", help="a stored session as an animated 3D scene in one HTML file",
                            formatter_class=fmt)
    replay.add_argument("session", type=session_ref, help="session id or 'last' (required)")
    replay.add_argument("--iterations", default=None,
                        help="comma list of iterations to show (default: the first and last measured)")
    replay.add_argument("--out", default=None, metavar="DIR", help="folder for replay.html "
                        "(default: out/STORE-HASH/session-ID, one per store and session)")
    replay.add_argument("--json", action="store_true", help="print one JSON object")
    add_db_option(replay)
    replay.set_defaults(func=_cmd_replay)

    examples = sub.add_parser("examples", help="copy the shipped example programs and maneuvers into a folder",
                              formatter_class=fmt)
    examples.add_argument("folder", help="where to copy them (required)")
    examples.add_argument("--force", action="store_true", help="replace files that exist")
    examples.add_argument("--json", action="store_true", help="print one JSON object: the files copied")
    examples.set_defaults(func=_cmd_examples)

    curate.register(sub)

    studies = sub.add_parser("studies", help="list the stored studies, or show one", formatter_class=fmt)
    studies.add_argument("study", nargs="?", type=session_ref, default=None,
                         help="a study id or 'last' to show (default: list all)")
    studies.add_argument("--json", action="store_true", help="print JSON")
    add_db_option(studies)
    studies.set_defaults(func=_cmd_studies)
