"""`--engine ray --address` where no Ray cluster answers (a web server, an HTTP/2 server that is not Ray's
GCS, a server that says nothing, a closed port): one line naming what is there and exit 2 within seconds,
before Ray is imported, never Ray's minutes of retries or its log lines; SIGTERM while the address is
checked ends in the CLI's line and 143. That a real cluster still joins is checked by test_ray.py, whose
cluster fixture and drivers go through the same check.
"""

from __future__ import annotations

import importlib.util
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest
from test_user_inputs import NEURALAO, TET, refusal

if importlib.util.find_spec("ray") is None:
    pytest.skip("--engine ray needs the 'ray' package", allow_module_level=True)

# An HTTP/2 server's answer to any request: its SETTINGS, then on stream 1 a ":status 404" (HPACK static
# entry 13) that ends the stream, as a web server speaking HTTP/2 (or a proxy) answers a gRPC call.
H2_NOT_FOUND = bytes.fromhex("000000040000000000") + bytes.fromhex("000001010500000001") + b"\x8d"


class _QuietHandler(BaseHTTPRequestHandler):
    def log_message(self, *args) -> None:
        pass


@contextmanager
def _server(kind: str) -> Iterator[tuple[str, threading.Event]]:
    """("127.0.0.1:PORT", an event set once a connection is accepted) of a local server of ``kind``: "http"
    (http.server, HTTP/1), "http2" (answers H2_NOT_FOUND), "silent" (accepts, never answers) or "closed"
    (the port is taken but nothing listens: connections are refused)."""
    accepted = threading.Event()
    if kind == "http":
        with ThreadingHTTPServer(("127.0.0.1", 0), _QuietHandler) as httpd:
            threading.Thread(target=httpd.serve_forever, daemon=True).start()
            try:
                yield f"127.0.0.1:{httpd.server_address[1]}", accepted
            finally:
                httpd.shutdown()
        return
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        held: list[socket.socket] = []

        def serve() -> None:
            while True:
                try:
                    conn, _ = listener.accept()
                except OSError:  # closed at the end of the test
                    return
                held.append(conn)
                accepted.set()
                if kind == "http2":
                    conn.recv(65536)
                    conn.sendall(H2_NOT_FOUND)

        if kind != "closed":
            listener.listen()
            threading.Thread(target=serve, daemon=True).start()
        try:
            yield f"127.0.0.1:{listener.getsockname()[1]}", accepted
        finally:
            for conn in held:
                conn.close()


def _bake(address: str, tmp_path) -> list[str]:
    """``neuralao bake`` of a tetrahedron on the Ray cluster at ``address``, to tmp_path/out.ply."""
    (tmp_path / "tet.obj").write_text(TET)
    args = ["bake", str(tmp_path / "tet.obj"), "--method", "vertex", "--rays", "4", "--out"]
    return [*args, str(tmp_path / "out.ply"), "--engine", "ray", "--address", address]


def _lines(err: str) -> list[str]:
    return [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip() and not ln.startswith("INFO ")]


@pytest.mark.parametrize(
    "kind, words",
    [
        ("http", "no Ray cluster answered there; a web server (HTTP/1) answered instead"),
        ("http2", "no Ray cluster answered there; an HTTP/2 or gRPC server answered instead"),
        (
            "silent",
            "no Ray cluster answered there; the server there accepted the connection but gave no answer",
        ),
        ("closed", "nothing listens there (connection refused"),
    ],
)
def test_an_address_where_no_ray_cluster_answers_is_one_line(kind, words, tmp_path, capsys):
    with _server(kind) as (address, _):
        line = refusal(capsys, [*_bake(address, tmp_path)])
    assert f" at {address}: " in line and words in line and "6379 by default" in line, line
    assert not (tmp_path / "out.ply").exists()


def test_a_web_server_given_as_address_fails_in_seconds_without_ray_log_lines(tmp_path):
    """The command as users run it, in a process of its own (Ray's C++ log lines go to its stderr)."""
    with _server("http") as (address, _):
        start = time.monotonic()
        p = subprocess.run(
            [*NEURALAO, *_bake(address, tmp_path)],
            capture_output=True,
            text=True,
            timeout=120,
        )
        elapsed = time.monotonic() - start
    err = _lines(p.stderr)
    assert p.returncode == 2 and len(err) == 1, (p.returncode, err)
    assert err[0].startswith(f"neuralao bake: error: cannot connect to Ray at {address}: "), err
    assert elapsed < 30, f"{elapsed:.1f} s to refuse a web server"


def test_sigterm_while_the_address_is_checked_ends_in_one_line_and_143(tmp_path):
    with _server("silent") as (address, accepted):
        p = subprocess.Popen(
            [*NEURALAO, *_bake(address, tmp_path)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            preexec_fn=lambda: signal.signal(signal.SIGTERM, signal.SIG_DFL),
        )
        try:
            assert accepted.wait(60), "the command never connected"
            sent = time.monotonic()
            p.send_signal(signal.SIGTERM)
            _, err = p.communicate(timeout=60)
        finally:
            p.kill()
    assert p.returncode == 143 and _lines(err) == ["neuralao bake: terminated (SIGTERM)"], (p.returncode, err)
    assert time.monotonic() - sent < 10
