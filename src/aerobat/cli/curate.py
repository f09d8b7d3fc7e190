"""Curating the store: ``tag``, ``note``, ``compare`` and ``delete`` (``sessions`` lists and filters)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import Any

from aerobat.cli.common import HelpFormatter, add_db_option, open_store, session_ref
from aerobat.errors import ConfigError

__all__ = ["register", "table"]


def table(rows: Sequence[tuple[str, ...]], right: set[int]) -> str:
    """Rows of text as aligned columns, a rule under the first (the header)."""
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]))]
    lines = ["  ".join(cell.rjust(w) if k in right else cell.ljust(w)
                       for k, (cell, w) in enumerate(zip(row, widths, strict=True))).rstrip() for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines) + "\n"


def _cmd_tag(args: argparse.Namespace) -> int:
    with open_store(args) as store:
        session_id = store.resolve_session(args.session)
        tags = store.tag_session(session_id, args.tag, remove=args.remove)
    if args.json:
        print(json.dumps({"session": session_id, "tags": list(tags)}))
    else:
        print(f"session {session_id}: tags {', '.join(tags) or 'none'}")
    return 0


def _cmd_note(args: argparse.Namespace) -> int:
    with open_store(args) as store:
        session_id = store.resolve_session(args.session)
        count = store.note_session(session_id, args.text)
    if args.json:
        print(json.dumps({"session": session_id, "notes": count}))
    else:
        print(f"session {session_id}: note {count} stored (`aerobat show {session_id}` lists its notes)")
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    with open_store(args, create=False) as store:
        a, b = store.resolve_session(args.a), store.resolve_session(args.b)
        comparison = store.compare_sessions(a, b)
    if args.json:
        print(json.dumps(comparison.to_table()))
        return 0
    rows = [("", f"session {a}", f"session {b}", "")] + [
        (name, x, y, "" if x == y else "differs") for name, x, y in comparison.rows]
    sys.stdout.write(table(rows, set()))
    if comparison.parameters:
        print()
        rows = [("parameter (learned)", f"session {a}", f"session {b}", "b − a")] + [
            (f"{name} [{unit}]", f"{x:.6g}", f"{y:.6g}", f"{y - x:+.3g}") for name, unit, x, y in comparison.parameters]
        sys.stdout.write(table(rows, {1, 2, 3}))
    else:
        print("\nthe two sessions fly different parameters: no parameter table")
    return 0


def _cmd_delete(args: argparse.Namespace) -> int:
    with open_store(args) as store:
        session_id = store.resolve_session(args.session)
        rec = store.session(session_id)
        what = (f"session {session_id} ({rec.maneuver_name} on {rec.plant_kind}, {rec.n_records} stored "
                f"iterations, {rec.display_state})")
        if not args.yes:
            raise ConfigError(f"delete: would delete {what} and nothing else; pass --yes to delete it")
        deleted = store.delete_session(session_id)
    if args.json:
        print(json.dumps({"session": session_id, "deleted_iterations": deleted}))
    else:
        print(f"deleted {what}; its design, maneuver, plant and vehicle rows stay in {args.db or 'the store'}")
    return 0


def register(sub: Any) -> None:
    fmt = HelpFormatter
    tag = sub.add_parser("tag", help="tag a stored session (`aerobat sessions --tag TAG` finds it)",
                         formatter_class=fmt)
    tag.add_argument("session", type=session_ref, help="session id or 'last' (required)")
    tag.add_argument("tag", help="the tag: up to 64 characters, no spaces or commas (required)")
    tag.add_argument("--remove", action="store_true", help="remove the tag instead of adding it")
    tag.add_argument("--json", action="store_true", help="print one JSON object: the session's tags")
    add_db_option(tag)
    tag.set_defaults(func=_cmd_tag)

    note = sub.add_parser("note", help="add a note to a stored session (`aerobat show` prints its notes)",
                          formatter_class=fmt)
    note.add_argument("session", type=session_ref, help="session id or 'last' (required)")
    note.add_argument("text", help="the note, up to 4000 characters (required)")
    note.add_argument("--json", action="store_true", help="print one JSON object")
    add_db_option(note)
    note.set_defaults(func=_cmd_note)

    compare = sub.add_parser("compare", help="two stored sessions side by side", formatter_class=fmt)
    compare.add_argument("a", type=session_ref, help="first session id or 'last' (required)")
    compare.add_argument("b", type=session_ref, help="second session id or 'last' (required)")
    compare.add_argument("--json", action="store_true", help="print one JSON object")
    add_db_option(compare)
    compare.set_defaults(func=_cmd_compare)

    delete = sub.add_parser("delete", help="delete a stored session and its iterations (needs --yes)",
                            formatter_class=fmt)
    delete.add_argument("session", type=session_ref, help="session id or 'last' (required)")
    delete.add_argument("--yes", action="store_true",
                        help="really delete it (without it, say what would be deleted and exit 2)")
    delete.add_argument("--json", action="store_true", help="print one JSON object")
    add_db_option(delete)
    delete.set_defaults(func=_cmd_delete)
