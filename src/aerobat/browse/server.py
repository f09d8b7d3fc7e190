"""Serving the pages: the standard library's ``ThreadingHTTPServer`` on 127.0.0.1, GET only.

The server answers GET and HEAD with a :class:`~aerobat.browse.site.Site`'s pages; nothing it
serves writes the store (the page has no form that changes anything: tags and notes are
written by the CLI). :func:`start` runs it in a thread and returns a :class:`Browser` whose
:meth:`Browser.close` always stops it.
"""

from __future__ import annotations

import errno
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import parse_qsl, urlsplit

from aerobat.browse.site import NotFound, Site
from aerobat.errors import AerobatError, ConfigError

__all__ = ["Browser", "start"]


class _Handler(BaseHTTPRequestHandler):
    site: Site
    server_version = "aerobat-browse"

    def log_message(self, format: str, *args: object) -> None:  # noqa: A002 - the base class's name
        pass  # quiet: the command prints its address, not every request

    def do_HEAD(self) -> None:  # noqa: N802 - http.server's name
        self._answer(body=False)

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        self._answer(body=True)

    def _answer(self, *, body: bool) -> None:
        url = urlsplit(self.path)
        try:
            kind, data = self.site.get(url.path, dict(parse_qsl(url.query)))
            status = 200
        except NotFound as exc:
            status, kind, data = 404, "text/plain", f"not found: {exc}\n".encode()
        except ConfigError as exc:
            status, kind, data = 400, "text/plain", f"bad request: {exc}\n".encode()
        except AerobatError as exc:
            status, kind, data = 500, "text/plain", f"aerobat: {exc}\n".encode()
        self.send_response(status)
        self.send_header("Content-Type", kind + ("; charset=utf-8" if kind.startswith("text") or "json" in kind
                                                 else ""))
        self.send_header("Content-Length", str(len(data)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        if body:
            self.wfile.write(data)


class Browser:
    """A running ``aerobat browse`` server (its :attr:`url`); :meth:`close` stops it and closes the store."""

    def __init__(self, site: Site, server: ThreadingHTTPServer) -> None:
        self.site = site
        self.server = server
        host, port = server.server_address[:2]
        self.url = f"http://{host if isinstance(host, str) else host.decode()}:{port}/"
        self._thread = threading.Thread(target=server.serve_forever, name="aerobat-browse", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()
        self._thread.join(timeout=10)
        self.site.close()

    def wait(self) -> None:
        """Block until the server stops (Ctrl-C in the command)."""
        self._thread.join()

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def start(db: str | Path, *, host: str = "127.0.0.1", port: int = 8765) -> Browser:
    """Serve the store's pages on ``host:port`` (``port=0``: any free port) in a background thread."""
    site = Site(db)
    handler = type("Handler", (_Handler,), {"site": site})
    try:
        server = ThreadingHTTPServer((host, port), handler)
    except OSError as exc:
        site.close()
        if exc.errno == errno.EADDRINUSE:
            raise ConfigError(f"--port {port}: already in use on {host}; choose another port (0: any free one)") \
                from None
        raise ConfigError(f"--host {host} --port {port}: cannot serve there: {exc.strerror or exc}") from None
    server.daemon_threads = True
    return Browser(site, server)
