"""``aerobat browse``: the store as a local, read-only web page, or as static files (``--export DIR``)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from aerobat.cli.common import HelpFormatter, add_db_option, bounded_int, output_dir
from aerobat.errors import ConfigError

__all__ = ["register"]


def _ids(text: str | None) -> list[int]:
    """``--compare``'s sessions: two to MAX_COMPARED different ids, in the order given."""
    from aerobat.browse.site import MAX_COMPARED, MAX_ID

    if text is None:
        return []
    words = [v.strip() for v in text.split(",") if v.strip()]
    shown = repr(text if len(text) <= 60 else text[:60] + "…")
    if not all(v.isascii() and v.isdigit() and len(v) <= len(str(MAX_ID)) for v in words):
        raise ConfigError(f"--compare {shown}: expected two or more session ids, e.g. 1,2")
    ids = list(dict.fromkeys(int(v) for v in words))
    if not 2 <= len(ids) <= MAX_COMPARED:
        raise ConfigError(f"--compare {shown}: expected two to {MAX_COMPARED} different session ids, e.g. 1,2")
    return ids


def _cmd_browse(args: argparse.Namespace) -> int:
    from aerobat.browse import Site, start
    from aerobat.store import default_path

    db = default_path() if args.db is None else args.db
    compare = _ids(args.compare)
    if compare and args.export is None:
        raise ConfigError("--compare: only with --export (served pages compare any sessions you check)")
    if args.export is not None:
        started = time.perf_counter()
        with Site(db, static=True, study_figures=args.study_figures) as site:
            for sid in compare:
                site.store.resolve_session(sid)
            folder = output_dir(args.export, "--export")
            written = site.export(folder, compare=compare, stores=(db,))
        seconds = time.perf_counter() - started
        if args.json:
            print(json.dumps({"folder": str(folder), "files": len(written), "seconds": round(seconds, 3)}))
        else:
            print(f"{len(written)} files written to {folder}/ in {seconds:.1f} s: open {folder / 'index.html'}")
        return 0
    browser = start(db, host=args.host, port=args.port)
    if browser.exposed:
        print(f"aerobat browse: warning: listening on {browser.address}, beyond this machine: anyone who can reach "
              f"it can read every page of {browser.site.store.path} (there is no password); --host 127.0.0.1 "
              f"keeps it on this machine", file=sys.stderr, flush=True)
    try:
        if args.json:
            print(json.dumps({"url": browser.url, "db": str(browser.site.store.path)}), flush=True)
        else:
            print(f"aerobat browse: {browser.site.store.path} at {browser.url} (read-only; Ctrl-C stops it)",
                  flush=True)
        if args.seconds is not None:
            time.sleep(args.seconds)
        else:
            browser.wait()
    except KeyboardInterrupt:
        print("aerobat browse: stopped", file=sys.stderr)
    finally:
        browser.close()
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("browse", help="the store as a local read-only web page (or static files with --export)",
                       formatter_class=HelpFormatter)
    add_db_option(p)
    p.add_argument("--host", default="127.0.0.1",
                   help="address to serve on; anything but a loopback address (127.0.0.1, ::1, localhost) lets other "
                        "machines read the pages, and is warned about (default: 127.0.0.1, this machine only)")
    p.add_argument("--port", type=bounded_int(0, 65535), default=8765,
                   help="port to serve on; 0 picks a free one (default: 8765)")
    p.add_argument("--export", metavar="DIR", type=Path, default=None,
                   help="write the pages as static files into DIR instead of serving (default: serve)")
    p.add_argument("--compare", metavar="IDS", default=None,
                   help="with --export: also write compare.html for these session ids, e.g. 1,2 (default: none)")
    p.add_argument("--study-figures", action="store_true",
                   help="with --export: also draw the figures of every study session (default: plain sessions only)")
    p.add_argument("--seconds", type=bounded_int(1, 10**7), default=None,
                   help="stop serving after N seconds (default: serve until Ctrl-C)")
    p.add_argument("--json", action="store_true", help="print one JSON object: the address, or what was written")
    p.set_defaults(func=_cmd_browse)
