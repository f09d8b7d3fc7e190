"""Serving the pages: the standard library's ``ThreadingHTTPServer``, on 127.0.0.1 by default, GET only.

The server answers GET and HEAD with a :class:`~aerobat.browse.site.Site`'s pages; nothing it
serves writes the store (the page has no form that changes anything: tags and notes are
written by the CLI). :func:`start` runs it in a thread and returns a :class:`Browser` whose
:meth:`Browser.close` always stops it.

What a client cannot do to it:

* **hold a connection**: each connection is served by its own thread; every read and write on
  it has a timeout (:data:`TIMEOUT_S`), the request line and headers must arrive within
  :data:`REQUEST_S` (a client that sends a byte now and then is dropped too), and a page is
  sent in pieces of :data:`CHUNK_BYTES` that each must leave within the timeout;
* **print tracebacks**: a client that leaves mid-answer, resets the connection or times out
  is a normal end of its connection and prints nothing; anything else unexpected is answered
  500 and written as one line on stderr;
* **reach it under another name** (DNS rebinding: a web page whose own host name resolves to
  this machine reading the pages through the visitor's browser): a request whose ``Host``
  header is not one of this server's names, with its port, is answered 421. The names are
  ``localhost`` and the loopback addresses (``127.0.0.1``, ``[::1]``), the ``--host`` given and
  the address bound, the address the connection arrived at, and, when bound beyond the loopback
  interface, this machine's host names. A request without a ``Host`` header (no browser sends
  one) is answered.
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import socket
import sys
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl, urlsplit

from aerobat.browse.site import NotFound, Site
from aerobat.errors import AerobatError, ConfigError

__all__ = ["CHUNK_BYTES", "REQUEST_S", "TIMEOUT_S", "Browser", "start"]

TIMEOUT_S = 5.0
"""Seconds any one read or write on a connection may wait for the client."""
REQUEST_S = 15.0
"""Seconds a client has to send its whole request line and headers."""
CHUNK_BYTES = 64 * 1024
"""A page is sent in pieces of this size, each within :data:`TIMEOUT_S` (a slow but reading client is served)."""

_GONE = (ConnectionError, TimeoutError)  # the client left, reset the connection or stopped reading
_GONE_ERRNOS = (errno.ENOTCONN, errno.EBADF, errno.ESHUTDOWN)  # … or its deadline shut the connection


def _gone(exc: BaseException | None) -> bool:
    """Whether ``exc`` only says that the client's connection ended (nothing to report)."""
    return isinstance(exc, _GONE) or (isinstance(exc, OSError) and exc.errno in _GONE_ERRNOS)


def _one_line(exc: BaseException) -> str:
    return ascii(" ".join(f"{type(exc).__name__}: {exc}".split())[:500])[1:-1]


def _address(text: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    """The IP address ``text`` names (an IPv4 address mapped into IPv6 as itself), or None for a name."""
    try:
        address = ipaddress.ip_address(text.split("%")[0])
    except ValueError:
        return None
    mapped = getattr(address, "ipv4_mapped", None)
    return mapped if mapped is not None else address


def _host_and_port(value: str) -> tuple[str, int | None] | None:
    """``("example.org", 8765)`` of a ``Host`` value (``[::1]:8765`` for IPv6); None if it is malformed."""
    value = value.strip()
    if value.startswith("["):
        end = value.find("]")
        if end < 0 or (value[end + 1:] and not value[end + 1:].startswith(":")):
            return None
        host, port = value[1:end], value[end + 2:] if value[end + 1:] else None
    elif value.count(":") > 1:  # an IPv6 address must be in brackets
        return None
    else:
        host, _, port = value.partition(":") if ":" in value else (value, "", None)
    if not host or (port is not None and not (port.isdigit() and len(port) <= 5)):
        return None
    return host.lower(), None if port is None else int(port)


class _Names:
    """The names a request's ``Host`` may give for this server (see the module's description)."""

    def __init__(self, given: str, bound: str, port: int) -> None:
        self.port = port
        self.bound = _address(bound)
        self.wide = self.bound is None or not self.bound.is_loopback
        self.names = {"localhost", given.lower()}
        if self.wide:
            self.names |= {socket.gethostname().lower(), socket.getfqdn().lower()}

    def allows(self, value: str, local: str) -> bool:
        """Whether the ``Host`` value ``value`` names this server, reached at the local address ``local``."""
        parsed = _host_and_port(value)
        if parsed is None:
            return False
        host, port = parsed
        if (port if port is not None else 80) != self.port:
            return False
        address = _address(host)
        if address is None:
            return host in self.names
        return address.is_loopback or address in (self.bound, _address(local))


class _Handler(BaseHTTPRequestHandler):
    site: Site
    names: _Names
    server_version = "aerobat-browse"
    timeout = TIMEOUT_S  # StreamRequestHandler sets it on the socket: every read and write waits at most this

    def log_message(self, format: str, *args: object) -> None:  # noqa: A002 - the base class's name
        pass  # quiet: the command prints its address, not every request

    def handle(self) -> None:
        """Serve the connection; a client that has not sent its request within :data:`REQUEST_S` is cut off."""
        self._late = False
        self._deadline = threading.Timer(REQUEST_S, self._cut_off)
        self._deadline.daemon = True
        self._deadline.start()
        try:
            super().handle()
        finally:
            self._deadline.cancel()

    def _cut_off(self) -> None:
        self._late = True
        with contextlib.suppress(OSError):
            self.connection.shutdown(socket.SHUT_RDWR)  # the blocked read returns: the thread ends

    def do_HEAD(self) -> None:  # noqa: N802 - http.server's name
        self._answer(body=False)

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        self._answer(body=True)

    def _answer(self, *, body: bool) -> None:
        self._deadline.cancel()  # the request is in; from here only the writes' timeout applies
        if self._late:
            return
        url = urlsplit(self.path)
        given = self.headers.get_all("Host", [])
        hosts = [*given, *([url.netloc] if url.netloc else [])]  # an absolute request names its host itself
        local = str(self.connection.getsockname()[0])
        if len(given) > 1 or not all(self.names.allows(h, local) for h in hosts):
            shown = ", ".join(ascii(h[:100]) for h in hosts)
            self._send(421, "text/plain", f"misdirected request: {shown} is not a name of this server; "
                                          f"open it at localhost:{self.names.port}\n".encode(), body)
            return
        if getattr(self.server, "stopping", False):
            self._send(503, "text/plain", b"the server is stopping\n", body)
            return
        try:
            kind, data = self.site.get(url.path, dict(parse_qsl(url.query)))
            status = 200
        except NotFound as exc:
            status, kind, data = 404, "text/plain", f"not found: {exc}\n".encode()
        except ConfigError as exc:
            status, kind, data = 400, "text/plain", f"bad request: {exc}\n".encode()
        except AerobatError as exc:
            status, kind, data = 500, "text/plain", f"aerobat: {exc}\n".encode()
        except Exception as exc:  # noqa: BLE001 - a bug: answered, and one line for whoever runs the server
            print(f"aerobat browse: internal error answering {self.command} {ascii(self.path[:200])}: "
                  f"{_one_line(exc)}", file=sys.stderr, flush=True)
            status, kind, data = 500, "text/plain", f"internal error: {_one_line(exc)}\n".encode()
        self._send(status, kind, data, body)

    def _send(self, status: int, kind: str, data: bytes, body: bool) -> None:
        self.send_response(status)
        self.send_header("Content-Type", kind + ("; charset=utf-8" if kind.startswith("text") or "json" in kind
                                                 else ""))
        self.send_header("Content-Length", str(len(data)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        if body:
            view = memoryview(data)
            for start in range(0, len(view), CHUNK_BYTES):
                self.wfile.write(view[start:start + CHUNK_BYTES])


class _Server(ThreadingHTTPServer):
    daemon_threads = True  # a connection still open does not keep the command from ending
    request_queue_size = 1024  # the listen backlog (socketserver's 5 turns a burst of connections into SYN retries)
    stopping = False  # set by Browser.close: requests still arriving are answered 503

    def handle_error(self, request: Any, client_address: Any) -> None:
        """A client that left or stalled ends its connection silently; anything else is one line on stderr."""
        exc = sys.exc_info()[1]
        if exc is None or _gone(exc):
            return
        print(f"aerobat browse: internal error serving {client_address[0]}: {_one_line(exc)}", file=sys.stderr,
              flush=True)


class Browser:
    """A running ``aerobat browse`` server (its :attr:`url`); :meth:`close` stops it and closes the store.

    :attr:`exposed` is True when it listens beyond the loopback interface (other machines may read the pages).
    """

    def __init__(self, site: Site, server: _Server, names: _Names) -> None:
        self.site = site
        self.server = server
        self.exposed = names.wide
        host, port = server.server_address[:2]
        host = host if isinstance(host, str) else host.decode()
        self.address = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
        self.url = f"http://{self.address}/"
        self._thread = threading.Thread(target=server.serve_forever, name="aerobat-browse", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop serving and close the store (after the page being drawn, if any; later requests get 503)."""
        self.server.stopping = True
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


def _bind(host: str, port: int, handler: type[_Handler]) -> _Server:
    """A server on the first address ``host`` resolves to that can be bound (IPv4 or IPv6)."""
    try:
        found = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (socket.gaierror, UnicodeError) as exc:
        raise ConfigError(f"--host {host}: not an address this machine can serve on ({exc})") from None
    failure: OSError | None = None
    for family, _, _, _, address in dict.fromkeys(found):  # the first address first, each once
        server_class = type("Server", (_Server,), {"address_family": family})
        try:
            return server_class(address, handler)
        except OSError as exc:
            failure = exc if failure is None or exc.errno == errno.EADDRINUSE else failure
    assert failure is not None  # getaddrinfo gives at least one address or raises
    if failure.errno == errno.EADDRINUSE:
        raise ConfigError(f"--port {port}: already in use on {host}; choose another port (0: any free one)")
    raise ConfigError(f"--host {host} --port {port}: cannot serve there: {failure.strerror or failure}")


def start(db: str | Path, *, host: str = "127.0.0.1", port: int = 8765) -> Browser:
    """Serve the store's pages on ``host:port`` (``port=0``: any free port) in a background thread.

    ``host`` is an address or a name (``127.0.0.1``, ``::1``, ``localhost``, ``0.0.0.0`` for every
    interface); :attr:`Browser.exposed` says whether that reaches beyond this machine.
    """
    if not isinstance(host, str) or not host.strip():
        raise ConfigError("--host: empty; give an address to serve on, e.g. 127.0.0.1")
    site = Site(db)
    try:
        handler: type[_Handler] = type("Handler", (_Handler,), {"site": site})
        server = _bind(host, port, handler)
    except BaseException:
        site.close()
        raise
    bound, actual = server.server_address[:2]
    handler.names = _Names(host, bound if isinstance(bound, str) else bound.decode(), actual)
    return Browser(site, server, handler.names)
