"""The server phase of the fuzz campaign (issue 45): ``aerobat browse`` served to hostile and broken clients.

``run_server_phase(fz, campaign, fx, n)`` (the conventions of ``scripts/fuzz_files.py``: every case
with ``n`` < 0, a seeded sample of ``n`` spread over the kinds otherwise) starts the real command,
``aerobat browse --db STORE --port 0 --json``, once on 127.0.0.1 and once with ``--host 0.0.0.0``
(which must warn, in one line), and talks to them over raw sockets:

- ``huge-id``: ids of 5,000, 4,301 and 20 digits, 2⁶³ and more, 0, on every route (pages, the api,
  figures, replays, comparisons): 404 with one line;
- ``bad-id``: negative, fractional, percent-encoded, hexadecimal, empty ids on every route: 400 or 404;
- ``valid``: the pages that exist, leading zeros and HEAD included: 200;
- ``host``: foreign, malformed, doubled ``Host`` headers and absolute request targets: 421; this
  server's own names: 200 (both servers; the wide one also under the machine's name and address);
- ``oversized``: a request line or a header line over 64 KiB (414, 431), 101 headers (431), many
  large headers within the limits (200);
- ``method``: POST, PUT, DELETE…, HTTP/2.0, garbage and a TLS hello: 400, 501 or 505;
- ``disconnect``: a client that resets or closes the connection mid-answer, before reading or
  half way through its request;
- ``slow``: clients that connect and send nothing, send half a request, send a byte every two
  seconds, or ask for megabytes and never read; all at once, while a normal request must still be
  answered within 3 s. Each must be dropped by the server: within its socket timeout, or within
  its deadline for the whole request.

After every case the server's stderr must have stayed empty (a traceback, or any line, is
*internal*), the status must be the expected one, and the server must answer a normal request
within 10 s (else a *hang*); at the end the store must be byte-identical (else *data loss*).
Findings carry ``reproduce``: the command and a Python line sending the same bytes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import random
import re
import select
import shlex
import socket
import sqlite3
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

KINDS = ("huge-id", "bad-id", "valid", "host", "oversized", "method", "disconnect", "slow")
ROUTES = ("session-{}.html", "study-{}.html", "api/session-{}.json", "session-{}/learning.png",
          "session-{}/side_views.png", "session-{}/replay-default.html", "session-1/replay-{}.html",
          "study-{}/figure.png", "compare/1-{}.png", "compare/{}-1.png", "compare.html?ids=1,{}")
HUGE = ("9" * 5000, "9" * 4301, "1" + "0" * 4300, "9" * 20, str(2**63), str(2**64), "0", str(2**63 - 1))
BAD = ("-1", "x", "1.5", "%31", "1e3", "%20", "0x1", "%D9%A1", "1%00", "")
TIMEOUT_S, REQUEST_S = 5.0, 15.0  # aerobat.browse.server's: what a stalled client is given
SETTLE_S = 1.0  # for the connections of earlier cases to end
ANSWER_S = 10.0  # a normal request must be answered within this, whatever else goes on


@dataclasses.dataclass
class Case:
    kind: str
    what: str
    request: bytes  # ``{port}`` is replaced by the server's port
    expect: tuple[int, ...]  # acceptable statuses (0: the server closed without answering)
    wide: bool = False  # sent to the server listening on 0.0.0.0
    mode: str = "ask"  # ask; disconnect: reset-after, close-after, reset-before, half-then-reset, close-at-once;
    # slow: silent, half, trickle, never-read
    address: str = "127.0.0.1"  # where to connect


def _get(path: str, host: str | None = "localhost:{port}", method: str = "GET", extra: str = "") -> bytes:
    header = f"Host: {host}\r\n" if host is not None else ""
    return f"{method} /{path} HTTP/1.1\r\n{header}{extra}\r\n".encode()


def build_cases(sessions: list[int], studies: list[int], outward: str | None) -> list[Case]:
    cases: list[Case] = []
    for route in ROUTES:
        for value in HUGE:
            cases.append(Case("huge-id", f"{route} with {len(value)} digits", _get(route.format(value)), (404,)))
        for value in BAD:
            cases.append(Case("bad-id", f"{route} with {value!r}", _get(route.format(value)), (400, 404)))
    first = sessions[0] if sessions else 1
    valid = ["", "index.html", f"session-{first}.html", f"session-000{first}.html", f"api/session-{first}.json"]
    valid += [f"study-{s}.html" for s in studies[:1]]
    valid += [f"compare.html?ids={sessions[0]},{sessions[1]}"] if len(sessions) > 1 else []
    cases += [Case("valid", f"GET /{p}", _get(p), (200,)) for p in valid]
    cases.append(Case("valid", "HEAD /", _get("", method="HEAD"), (200,)))
    cases.append(Case("valid", "HTTP/1.0 without Host", b"GET /index.html HTTP/1.0\r\n\r\n", (200,)))
    hostname = socket.gethostname()
    for wide in (False, True):
        for host in ("localhost:{port}", "127.0.0.1:{port}", "[::1]:{port}", "LOCALHOST:{port}", "127.0.0.2:{port}"):
            cases.append(Case("host", f"Host {host}", _get("index.html", host), (200,), wide))
        for host in ("evil.example:{port}", "localhost.evil.example:{port}", "localhost:1", "localhost",
                     "192.0.2.1:{port}", "", "a:b:{port}", "[::1:{port}", "localhost:{port}x", "::1:{port}",
                     "localhost:{port}, evil.example", "user@localhost:{port}"):
            cases.append(Case("host", f"Host {host!r}", _get("index.html", host), (421,), wide))
        cases.append(Case("host", f"Host {hostname}", _get("index.html", f"{hostname}:{{port}}"),
                          (200,) if wide else (421,), wide))
        cases.append(Case("host", "Host 0.0.0.0", _get("index.html", "0.0.0.0:{port}"), (200,) if wide else (421,),
                          wide))
        cases.append(Case("host", "two Host headers", _get("", extra="Host: evil.example:{port}\r\n"), (421,), wide))
        cases.append(Case("host", "absolute target", b"GET http://evil.example:{port}/ HTTP/1.1\r\n"
                          b"Host: localhost:{port}\r\n\r\n", (421,), wide))
    if outward is not None:
        cases.append(Case("host", f"Host {outward} at {outward}", _get("", f"{outward}:{{port}}"), (200,), True,
                          address=outward))
    cases += [
        Case("oversized", "a 70,000-byte request line", _get("a" * 70_000), (414,)),
        Case("oversized", "a 70,000-byte header", _get("", extra="X-Big: " + "a" * 70_000 + "\r\n"), (431,)),
        Case("oversized", "a 70,000-byte Host", _get("", "a" * 70_000), (431,)),
        Case("oversized", "100 headers", _get("", extra="X: a\r\n" * 99), (431,)),  # http.client: at most 99
        Case("oversized", "99 headers of 600 bytes", _get("", extra=("X: " + "a" * 600 + "\r\n") * 98), (200,)),
        Case("oversized", "a 60,000-byte path", _get("session-" + "9" * 60_000 + ".html"), (404,)),
        Case("oversized", "Content-Length 10^12 on a GET", _get("", extra="Content-Length: 1000000000000\r\n"),
             (200,)),
        Case("oversized", "an 8 KiB cookie", _get("", extra="Cookie: " + "c" * 8192 + "\r\n"), (200,)),
    ]
    for method in ("POST", "PUT", "DELETE", "OPTIONS", "PATCH", "TRACE"):
        cases.append(Case("method", method, _get("", method=method), (501,)))
    cases += [Case("method", "HTTP/2.0", b"GET / HTTP/2.0\r\nHost: localhost:{port}\r\n\r\n", (505,)),
              Case("method", "garbage", b"GARBAGE\r\n\r\n", (400,)),
              Case("method", "HTTP/0.9 POST", b"POST /\r\n\r\n", (400,)),
              Case("method", "HTTP/0.9 GET: the page, no status line", b"GET /\r\n\r\n", (0,)),
              Case("method", "a blank line", b"\r\n", (0,)),
              Case("method", "a TLS hello", bytes.fromhex("16030100a5010000a10303") + bytes(64), (0, 400))]
    big = f"session-{first}/replay-default.html"
    for page in (big, f"session-{first}/learning.png", "index.html"):
        for mode in ("reset-after", "close-after", "reset-before", "half-then-reset", "close-at-once"):
            for _ in range(2):
                cases.append(Case("disconnect", f"{mode} {page}", _get(page), (0, 200), mode=mode))
    for mode, count in (("silent", 30), ("half", 30), ("trickle", 10), ("never-read", 10)):
        cases += [Case("slow", mode, _get(big if mode == "never-read" else "index.html"), (0, 200), mode=mode)
                  for _ in range(count)]
    return cases


class Served:
    """``aerobat browse`` running in its own process; its stderr collected line by line."""

    def __init__(self, store: Path, host: str) -> None:
        import aerobat

        src = str(Path(aerobat.__file__).resolve().parents[1])
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}
        self.argv = ["browse", "--db", str(store), "--host", host, "--port", "0", "--json"]
        self.proc = subprocess.Popen([sys.executable, "-m", "aerobat", *self.argv], stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env=env)
        self.err: list[str] = []
        self.lock = threading.Lock()
        assert self.proc.stderr is not None and self.proc.stdout is not None
        threading.Thread(target=self._collect, args=(self.proc.stderr,), daemon=True).start()
        ready, _, _ = select.select([self.proc.stdout], [], [], 180)
        line = self.proc.stdout.readline() if ready else ""
        if not line:
            self.proc.kill()
            raise RuntimeError(f"aerobat {' '.join(self.argv)} did not start: {self.errors()[-5:]}")
        self.port = int(json.loads(line)["url"].rstrip("/").rsplit(":", 1)[1])
        self.seen = 0

    def _collect(self, stream: Any) -> None:
        for line in stream:
            with self.lock:
                self.err.append(line.rstrip("\n"))

    def errors(self) -> list[str]:
        with self.lock:
            return list(self.err)

    def new_errors(self) -> list[str]:
        """The stderr lines printed since the last call."""
        with self.lock:
            lines, self.seen = self.err[self.seen:], len(self.err)
        return lines

    def stop(self) -> tuple[int | None, list[str]]:
        """Ctrl-C: the exit status and what it printed on stderr since the last look."""
        with contextlib.suppress(OSError):
            self.proc.send_signal(2)
        try:
            code = self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            code = None
        time.sleep(0.2)
        return code, self.new_errors()


def exchange(port: int, data: bytes, *, address: str = "127.0.0.1", timeout: float = ANSWER_S) -> int | None:
    """Send ``data``, read the answer to its end: its status (0: closed without one), None if none came in time."""
    try:
        with socket.create_connection((address, port), timeout=timeout) as conn:
            conn.sendall(data)
            answer = b""
            while chunk := conn.recv(1 << 16):
                answer = (answer + chunk)[:4096]
            head, body = answer[:64], answer
    except TimeoutError:
        return None
    except ConnectionError:
        return 0
    if head.startswith(b"HTTP/") and len(head.split()) > 1:
        return int(head.split()[1])
    error = re.search(rb"Error code: (\d{3})", body)  # http.server's error page without a status line: a request
    return int(error.group(1)) if error else 0  # it could not read as HTTP/1.x is answered as HTTP/0.9


def disconnect(port: int, data: bytes, mode: str) -> None:
    """A client that leaves: after the first bytes of the answer, at once, or half way through its request."""
    conn = socket.create_connection(("127.0.0.1", port), timeout=ANSWER_S)
    with contextlib.suppress(OSError):
        if mode.startswith("reset") or mode == "half-then-reset":
            conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
        conn.sendall(data[: len(data) // 2] if mode == "half-then-reset" else data)
        if mode.endswith("-after"):
            conn.recv(100)
    conn.close()


def as_python(data: bytes) -> str:
    """``data`` as a short Python expression (runs of one byte as ``b"a" * 70000``)."""
    parts, k = [], 0
    while k < len(data):
        run = k
        while run < len(data) and data[run] == data[k]:
            run += 1
        if run - k >= 40:
            parts.append(f"{bytes([data[k]])!r} * {run - k}")
            k = run
        else:
            end = k
            while end < len(data) and not (end + 40 <= len(data) and len(set(data[end:end + 40])) == 1):
                end += 1
            parts.append(repr(data[k:end]))
            k = end
    return " + ".join(parts) or "b''"


def reproduce(served: Served, case: Case, data: bytes) -> str:
    script = (f"import socket; s = socket.create_connection(({case.address!r}, {served.port})); "
              f"s.sendall({as_python(data)}); print(s.recv(300))")
    return f"aerobat {shlex.join(served.argv[:-3])} --port {served.port} & sleep 5; python3 -c {shlex.quote(script)}"


def threads(pid: int) -> int | None:
    """How many threads process ``pid`` runs (Linux: /proc), or None where that cannot be read."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    return next((int(line.split()[1]) for line in status.splitlines() if line.startswith("Threads:")), None)


def _slow_batch(cases: list[tuple[int, Case]], served: Served) -> dict[int, str]:
    """Run the slow clients all at once; the reason each failed, by index (none: dropped in time).

    Silent, half and trickling clients must see the server close their connection. A client that
    never reads cannot see that (what the server had sent still sits in the kernel's buffers), so
    the server's threads are counted instead: back to what they were once every bound has passed.
    """
    failures: dict[int, str] = {}
    conns: dict[int, socket.socket] = {}
    stop = threading.Event()
    time.sleep(SETTLE_S + 0.5)  # the connections of earlier cases are closed
    baseline = threads(served.proc.pid)
    for k, case in cases:
        data = case.request.replace(b"{port}", str(served.port).encode())
        conns[k] = conn = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if case.mode == "never-read":
            conn.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        conn.settimeout(ANSWER_S)
        conn.connect(("127.0.0.1", served.port))
        if case.mode == "half":
            conn.sendall(data[:30])
        elif case.mode == "never-read":
            conn.sendall(data)
        elif case.mode == "trickle":
            def trickle(conn: socket.socket = conn, data: bytes = data) -> None:
                with contextlib.suppress(OSError):
                    for byte in data[:-2] + b"X-Slow: " + b"a" * 100:
                        conn.sendall(bytes([byte]))
                        if stop.wait(2.0):
                            return
            threading.Thread(target=trickle, daemon=True).start()
    started = time.monotonic()
    for when in (0.5, TIMEOUT_S / 2):  # others are served meanwhile
        time.sleep(max(0.0, started + when - time.monotonic()))
        asked = time.monotonic()
        status = exchange(served.port, _get("index.html").replace(b"{port}", str(served.port).encode()), timeout=3.0)
        if status != 200:
            failures[cases[0][0]] = f"a normal request was not answered within 3 s beside {len(cases)} slow clients " \
                                    f"(status {status}, {time.monotonic() - asked:.1f} s)"
    last = started
    for k, case in cases:
        bound = (REQUEST_S if case.mode == "trickle" else TIMEOUT_S) + 4.0
        last = max(last, started + bound)
        if case.mode == "never-read":
            continue
        conn = conns[k]
        conn.settimeout(max(0.1, started + bound - time.monotonic()))
        try:
            while conn.recv(1 << 16):
                pass
        except TimeoutError:
            failures.setdefault(k, f"{case.mode}: still held by the server after {bound:.0f} s")
        except OSError:
            pass  # reset by the server: dropped
    time.sleep(max(0.0, last + SETTLE_S - time.monotonic()))
    left = threads(served.proc.pid)
    if baseline is not None and left is not None and left > baseline:
        for k, case in cases:
            if case.mode == "never-read":
                failures.setdefault(k, f"{left - baseline} more threads in the server than before the slow clients, "
                                       f"after every bound passed")
    stop.set()
    for conn in conns.values():
        conn.close()
    return failures


def run_server_phase(fz: Any, campaign: Any, fx: Any, n: int) -> None:
    """Run the server cases (all if ``n`` < 0, else a seeded sample of ``n`` spread over the kinds)."""
    files = sys.modules.get("fuzz_files") or fz.files_module()
    rng = random.Random(campaign.seed + 46)
    report: dict[str, Any] = {"requested": n, "cases": 0, "counts": Counter(), "by_kind": {}, "internal": [],
                              "hangs": [], "data_loss": [], "not_covered": []}
    campaign.report["server"] = report
    if n == 0:
        return
    started = time.perf_counter()
    store = Path(fx.store).resolve()
    before = hashlib.sha256(store.read_bytes()).hexdigest()
    counts = files.store_counts(store)
    with contextlib.closing(sqlite3.connect(f"file:{store}?mode=ro", uri=True)) as conn:
        sessions = [r[0] for r in conn.execute("SELECT id FROM sessions ORDER BY id LIMIT 2")]
        studies = [r[0] for r in conn.execute("SELECT id FROM studies ORDER BY id LIMIT 1")]
    outward = next((a for a in {i[4][0] for i in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)}
                    if not a.startswith("127.")), None)
    cases = build_cases(sessions, studies, outward)
    if 0 <= n < len(cases):
        by_kind = {k: [c for c in cases if c.kind == k] for k in KINDS}
        picked: list[Case] = []
        while len(picked) < n:
            for kind in KINDS:
                if by_kind[kind] and len(picked) < n:
                    picked.append(by_kind[kind].pop(rng.randrange(len(by_kind[kind]))))
        cases = picked
    report["cases"] = len(cases)
    servers = {False: Served(store, "127.0.0.1"), True: Served(store, "0.0.0.0")}

    def record(k: int, case: Case, klass: str, reason: str, served: Served, data: bytes) -> None:
        report["counts"][klass] += 1
        report["by_kind"].setdefault(case.kind, Counter())[klass] += 1
        if klass in ("INTERNAL", "HANG"):
            entry = {"index": k, "kind": case.kind, "what": case.what[:200], "reason": reason,
                     "reproduce": reproduce(served, case, data)}
            report["internal" if klass == "INTERNAL" else "hangs"].append(entry)
            campaign.say(f"fuzz: {klass} server #{k} ({case.kind} {case.what[:80]}): {reason}\n"
                         f"  reproduce: {entry['reproduce'][:600]}")

    try:
        time.sleep(0.5)
        warning = servers[True].new_errors()
        if len(warning) != 1 or not warning[0].startswith("aerobat browse: warning: listening on 0.0.0.0:"):
            report["internal"].append({"kind": "host", "what": "--host 0.0.0.0", "reason": f"expected one warning "
                                       f"line on stderr, got {warning[:3]}", "reproduce": "aerobat browse --host "
                                       "0.0.0.0 --port 0"})
        servers[False].new_errors()
        slow = [(k, c) for k, c in enumerate(cases) if c.kind == "slow"]
        for k, case in enumerate(cases):
            if case.kind == "slow":
                continue
            served = servers[case.wide]
            data = case.request.replace(b"{port}", str(served.port).encode())
            campaign.current = {"phase": "server", "index": k, "what": case.what[:200]}
            if case.kind == "disconnect":
                disconnect(served.port, data, case.mode)
                time.sleep(0.05)
                status: int | None = 0
            else:
                status = exchange(served.port, data, address=case.address)
            normal = exchange(served.port, _get("index.html").replace(b"{port}", str(served.port).encode()))
            printed = served.new_errors()
            if served.proc.poll() is not None:
                record(k, case, "INTERNAL", f"the server ended (exit {served.proc.returncode}): {printed[-3:]}",
                       served, data)
                servers[case.wide] = Served(store, "0.0.0.0" if case.wide else "127.0.0.1")
                servers[case.wide].new_errors()
            elif status is None or normal != 200:
                record(k, case, "HANG", f"no answer within {ANSWER_S:g} s (the case: {status}, a normal request "
                       f"after it: {normal})", served, data)
            elif printed:
                record(k, case, "INTERNAL", f"printed on stderr: {printed[:3]}", served, data)
            elif status not in case.expect:
                record(k, case, "INTERNAL", f"status {status}, expected {' or '.join(map(str, case.expect))}",
                       served, data)
            else:
                record(k, case, "ok", "", served, data)
            if (k + 1) % 50 == 0:
                campaign.say(f"fuzz: server {k + 1}/{len(cases)}: "
                             + " ".join(f"{c}={v}" for c, v in sorted(report["counts"].items())))
        if slow:
            failures = _slow_batch(slow, servers[False])
            printed = servers[False].new_errors()
            for k, case in slow:
                data = case.request.replace(b"{port}", str(servers[False].port).encode())
                if k in failures:
                    record(k, case, "HANG", failures[k], servers[False], data)
                elif printed:
                    record(k, case, "INTERNAL", f"printed on stderr: {printed[:3]}", servers[False], data)
                else:
                    record(k, case, "ok", "", servers[False], data)
    finally:
        for wide, served in servers.items():
            code, printed = served.stop()
            if code != 0 or printed != ["aerobat browse: stopped"]:
                report["internal"].append({"kind": "stop", "what": f"Ctrl-C {'0.0.0.0' if wide else '127.0.0.1'}",
                                           "reason": f"exit {code}, stderr {printed[:3]}",
                                           "reproduce": f"aerobat {shlex.join(served.argv)}, then Ctrl-C"})
    if hashlib.sha256(store.read_bytes()).hexdigest() != before or files.store_counts(store) != counts:
        report["data_loss"].append({"kind": "store", "reason": "the store's file changed while it was served",
                                    "reproduce": "(the whole server phase)"})
    campaign.say(f"fuzz: server {len(cases)}/{len(cases)}: "
                 + " ".join(f"{c}={v}" for c, v in sorted(report["counts"].items())))
    report["wall_s"] = round(time.perf_counter() - started, 1)


def main(argv: list[str] | None = None) -> int:
    """Only the server phase (every case; ``--server N`` a sample), in a scratch campaign."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("fuzz_exports", Path(__file__).with_name("fuzz_exports.py"))
    assert spec is not None and spec.loader is not None
    exports = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_exports"] = exports
    spec.loader.exec_module(exports)
    return int(exports.standalone(argv, exports=0, server=-1, description=__doc__.split("\n\n")[0]))


if __name__ == "__main__":
    raise SystemExit(main())
