"""The browser's server against hostile and broken clients (issue 45 E8, E11).

Huge ids are 404 on every route, clients that leave mid-answer or stall print nothing and are
dropped, others are served meanwhile, and only requests naming this server (its ``Host``) are
answered: a web page elsewhere cannot read the store through a visitor's browser (DNS rebinding).
"""

from __future__ import annotations

import contextlib
import io
import json
import socket
import threading
import time
from pathlib import Path

import pytest

from aerobat.browse import server, start
from aerobat.cli import main
from browse_fixtures import build_store

HUGE = "9" * 5000  # Python refuses to parse more than 4,300 digits


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("server-safety") / "v.sqlite"
    build_store(path, sessions=2, study_vehicles=1, failed_jobs=0)
    return path


def port_of(browser) -> int:
    return int(browser.url.rstrip("/").rsplit(":", 1)[1])


def ask(port: int, request: bytes, *, host: str = "127.0.0.1", timeout: float = 30.0) -> tuple[int, bytes]:
    """Send a raw request; the status and the body of the answer (0 if the connection closed without one)."""
    with socket.create_connection((host, port), timeout=timeout) as conn:
        conn.sendall(request)
        data = b""
        while chunk := conn.recv(1 << 16):
            data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    return (int(head.split()[1]) if head.startswith(b"HTTP/") else 0), body


def get(port: int, path: str, host: str | None = None) -> tuple[int, bytes]:
    header = f"Host: {host}\r\n" if host is not None else ""
    return ask(port, f"GET {path} HTTP/1.1\r\n{header}\r\n".encode())


def closed_within(conn: socket.socket, seconds: float) -> bool:
    """Whether the server closes ``conn`` within ``seconds`` (reads until end of stream)."""
    conn.settimeout(seconds)
    try:
        while conn.recv(1 << 16):
            pass
    except TimeoutError:
        return False
    except OSError:  # reset by the server: closed too
        pass
    return True


def test_huge_negative_and_garbage_ids_are_404_on_every_route(store, capfd):
    with start(store, port=0) as browser:
        port = port_of(browser)
        here = f"127.0.0.1:{port}"
        routes = ["session-{}.html", "study-{}.html", "api/session-{}.json", "session-{}/learning.png",
                  "session-{}/side_views.png", "session-{}/replay-default.html", "session-1/replay-{}.html",
                  "study-{}/figure.png", "compare/1-{}.png", "compare/{}-2.png", "compare.html?ids=1,{}"]
        for route in routes:
            for value in (HUGE, "9" * 4301, "9" * 20, str(2**63), str(2**63 - 1), "0"):
                status, body = get(port, "/" + route.format(value), here)
                assert status == 404 and body.count(b"\n") == 1 and len(body) < 500, (route, value[:30], body[:300])
            for value in ("-1", "x", "1.5", "%31", " 1"):
                status, _ = get(port, "/" + route.format(value).replace(" ", "%20"), here)
                assert status in (400, 404), (route, value)
        assert get(port, "/session-1.html", here)[0] == 200
        assert get(port, "/compare.html?ids=1,2," + ",".join(["1"] * 5000), here)[0] == 200  # repeats are one
        assert get(port, "/compare/" + "-".join(map(str, range(1, 60))) + ".png", here)[0] in (400, 404)
    assert capfd.readouterr().err == ""


def test_clients_that_leave_mid_answer_end_quietly_and_the_server_serves_on(store, capfd):
    with start(store, port=0) as browser:
        port = port_of(browser)
        request = f"GET /session-1/replay-default.html HTTP/1.1\r\nHost: localhost:{port}\r\n\r\n".encode()
        assert len(ask(port, request)[1]) > 1_000_000  # megabytes: the server is still writing when they leave
        for k in range(30):
            conn = socket.create_connection(("127.0.0.1", port))
            if k % 2:  # a reset (RST) instead of an orderly close
                conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
            conn.sendall(request)
            conn.recv(100)
            conn.close()
        time.sleep(1.0)
        assert get(port, "/index.html", f"localhost:{port}")[0] == 200
    err = capfd.readouterr().err
    assert err == "", err[:3000]


def test_stalled_and_half_open_clients_are_dropped_while_others_are_served(store, monkeypatch):
    with start(store, port=0) as browser:
        port = port_of(browser)
        monkeypatch.setattr(server, "REQUEST_S", 60.0)  # first the socket timeout alone: a client that sends nothing
        started = time.monotonic()
        silent = [socket.create_connection(("127.0.0.1", port)) for _ in range(150)]
        halves = [socket.create_connection(("127.0.0.1", port)) for _ in range(150)]
        for conn in halves:
            conn.sendall(b"GET /index.html HTTP/1.1\r\nHo")
        status, _ = get(port, "/index.html", f"localhost:{port}")
        assert status == 200 and time.monotonic() - started < 3.0  # not queued behind 300 stalled clients
        assert all(closed_within(c, server.TIMEOUT_S + 3.0) for c in silent + halves)
        assert time.monotonic() - started < server.TIMEOUT_S + 3.0
        monkeypatch.setattr(server, "REQUEST_S", 3.0)  # then the deadline: a byte a second, the request never ends
        trickler = socket.create_connection(("127.0.0.1", port))
        stop = threading.Event()

        def trickle() -> None:
            with contextlib.suppress(OSError):
                for byte in b"GET /index.html HTTP/1.1\r\nX-Slow: " + b"a" * 100:
                    trickler.sendall(bytes([byte]))
                    if stop.wait(1.0):
                        return

        thread = threading.Thread(target=trickle, daemon=True)
        started = time.monotonic()
        thread.start()
        assert closed_within(trickler, 3.0 + 3.0) and time.monotonic() - started < 3.0 + 3.0
        stop.set()
        thread.join()
        for conn in [*silent, *halves, trickler]:
            conn.close()
        assert get(port, "/index.html", f"localhost:{port}")[0] == 200


def test_only_requests_for_this_server_are_answered(store):
    with start(store, port=0) as browser:
        port = port_of(browser)
        for host in (f"localhost:{port}", f"127.0.0.1:{port}", f"[::1]:{port}", f"LOCALHOST:{port}", None):
            assert get(port, "/index.html", host)[0] == 200, host
        for host in (f"evil.example:{port}", f"localhost.evil.example:{port}", f"localhost:{port + 1}", "localhost",
                     f"192.0.2.1:{port}", f"0.0.0.0:{port}", "", f"a:b:{port}", f"[::1:{port}", f"localhost:{port}x"):
            status, body = get(port, "/index.html", host)
            assert status == 421 and b"misdirected" in body and body.count(b"\n") == 1, host
        status, _ = ask(port, f"GET http://evil.example:{port}/ HTTP/1.1\r\nHost: localhost:{port}\r\n\r\n".encode())
        assert status == 421  # an absolute request names its host itself
        status, _ = ask(port, f"GET / HTTP/1.1\r\nHost: localhost:{port}\r\nHost: evil.example:{port}\r\n\r\n".encode())
        assert status == 421


def test_serving_beyond_this_machine_is_warned_about_and_still_checks_the_host(store):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        assert main(["browse", "--db", str(store), "--host", "0.0.0.0", "--port", "0", "--seconds", "1",
                     "--json"]) == 0
    assert json.loads(out.getvalue())["url"].startswith("http://0.0.0.0:")
    assert err.getvalue().count("\n") == 1 and err.getvalue().startswith(
        "aerobat browse: warning: listening on 0.0.0.0:") and "--host 127.0.0.1" in err.getvalue()
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        assert main(["browse", "--db", str(store), "--port", "0", "--seconds", "1"]) == 0
    assert err.getvalue() == ""
    with start(store, host="0.0.0.0", port=0) as browser:
        assert browser.exposed
        port = port_of(browser)
        outward = next((a for a in {i[4][0] for i in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)}
                        if not a.startswith("127.")), None)
        assert get(port, "/index.html", f"{socket.gethostname()}:{port}")[0] == 200
        assert get(port, "/index.html", f"localhost:{port}")[0] == 200
        assert get(port, "/index.html", f"evil.example:{port}")[0] == 421
        if outward is not None:  # the machine's own address, reached at it
            status, _ = ask(port, f"GET / HTTP/1.1\r\nHost: {outward}:{port}\r\n\r\n".encode(), host=outward)
            assert status == 200
            status, _ = ask(port, f"GET / HTTP/1.1\r\nHost: 192.0.2.254:{port}\r\n\r\n".encode(), host=outward)
            assert status == 421 or outward == "192.0.2.254"
    with start(store, port=0) as browser:
        assert not browser.exposed
        assert get(port_of(browser), "/", f"{socket.gethostname()}:{port_of(browser)}")[0] == 421
