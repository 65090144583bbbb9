"""Every refusal over real HTTP on loopback: the right status, a reason, and nothing changed
(no file stored, not even in staging; no device opened, so nothing moved)."""

from __future__ import annotations

import http.client
import socket

import pytest

from tests.server.conftest import OUTSIDE, multipart, small_part


def _nothing_changed(server) -> None:
    assert server.stored() == []
    assert server.links == []  # no device was even opened: nothing moved
    assert server.printer.status().file is None


def _upload(server, name="part.gcode", data=None, fields=(("print", "true"),), **kw):
    body, ctype = multipart(list(fields), (name, data or small_part().encode()))
    return server.request("POST", "/api/files/local", body, {"Content-Type": ctype}, **kw)


@pytest.mark.parametrize(
    ("key", "status"),
    [(None, 401), ("", 401), ("   ", 401), ("0" * 32, 403), ("wrong", 403)],
    ids=["no-key", "empty-key", "blank-key", "wrong-key", "short-wrong-key"],
)
def test_upload_without_the_right_key_is_refused_and_changes_nothing(make_server, key, status):
    server = make_server()
    reply = _upload(server, key=key)
    assert reply.status == status
    assert "error" in reply.json()
    _nothing_changed(server)


@pytest.mark.parametrize("path", ["/api/version", "/api/job", "/api/files/local", "/nope"])
def test_every_route_needs_the_key(make_server, path):
    server = make_server()
    assert server.request("GET", path, key=None).status == 401
    assert server.request("GET", path + "?apikey=", key=None).status == 401
    assert server.request("GET", path + "?apikey=bad", key=None).status == 403


def test_key_in_the_query_works_and_a_wrong_header_wins_over_it(make_server):
    server = make_server()
    assert server.request("GET", f"/api/version?apikey={server.key}", key=None).status == 200
    assert server.request("GET", f"/api/version?apikey={server.key}", key="bad").status == 403


def test_job_commands_without_the_key_change_nothing(make_server):
    server = make_server()
    body = b'{"command": "start"}'
    reply = server.request("POST", "/api/job", body, {"Content-Type": "application/json"}, key="x")
    assert reply.status == 403
    _nothing_changed(server)


@pytest.mark.parametrize(
    ("name", "fields", "status"),
    [
        ("../escape.gcode", (), 400),
        ("../../etc/cron.d/x.gcode", (), 400),
        ("/etc/passwd.gcode", (), 400),
        ("sub/dir.gcode", (), 400),
        ("a\\b.gcode", (), 400),
        ("nul\x00.gcode", (), 400),
        (".hidden.gcode", (), 400),
        ("tab\tname.gcode", (), 400),
        ("ok.gcode", (("path", "../up"),), 400),
        ("ok.gcode", (("path", "a/../../b"),), 400),
        ("ok.gcode", (("path", ".incoming"),), 400),
        ("ok.gcode", (("print", "maybe"),), 400),
        ("model.stl", (), 415),
    ],
)
def test_bad_names_are_refused_and_nothing_is_written(make_server, name, fields, status):
    server = make_server()
    reply = _upload(server, name=name, fields=fields)
    assert reply.status == status, reply
    assert reply.json()["error"]
    _nothing_changed(server)


def test_a_windows_full_path_never_lands_outside_the_folder(make_server):
    """python-multipart keeps only the last part of a drive path (the convention of old
    Windows browsers): stored inside the upload folder as that part; a parser that passes
    the whole path on gets a 400. Never anything at C:\\."""
    server = make_server()
    reply = _upload(server, name="C:\\Users\\x.gcode", fields=())
    if reply.status == 201:
        assert server.stored() == ["x.gcode"]
    else:
        assert reply.status == 400
        _nothing_changed(server)


def test_over_the_size_cap_is_413_before_the_body_and_nothing_is_written(make_server):
    """An announced size over the cap is answered before a byte of the body is read (the
    client may then see its send cut: it has the 413 already)."""
    server = make_server(max_upload_bytes=50_000)
    big = (small_part() + ";" + "x" * 60_000 + "\n").encode()
    body, ctype = multipart([("print", "true")], ("big.gcode", big))
    head = (
        f"POST /api/files/local HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Api-Key: {server.key}\r\n"
        f"Content-Type: {ctype}\r\nContent-Length: {len(body)}\r\n\r\n"
    ).encode()
    with socket.create_connection(("127.0.0.1", server.port), timeout=60) as sock:
        sock.sendall(head)  # headers only: the answer comes without the body
        reply = sock.recv(4096)
    assert reply.startswith(b"HTTP/1.1 413"), reply
    _nothing_changed(server)


def test_a_chunked_body_over_the_cap_is_cut_with_413(make_server):
    """No Content-Length to check first: the body is counted as it streams."""
    server = make_server(max_upload_bytes=50_000)
    body, ctype = multipart([("print", "true")], ("big.gcode", b";" + b"x" * 80_000 + b"\n"))
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=60)
    try:
        chunks = (body[i : i + 8192] for i in range(0, len(body), 8192))
        conn.request(
            "POST",
            "/api/files/local",
            body=chunks,
            headers={"Content-Type": ctype, "X-Api-Key": server.key},
            encode_chunked=True,
        )
        assert conn.getresponse().status == 413
    except (BrokenPipeError, ConnectionResetError):
        pass  # the server may close while the client still sends: refused all the same
    finally:
        conn.close()
    _nothing_changed(server)


def test_a_file_failing_preflight_is_409_with_the_reason_and_not_stored(make_server):
    server = make_server()
    reply = _upload(server, name="outside.gcode", data=OUTSIDE.encode())
    assert reply.status == 409
    reason = reply.json()["error"]
    assert "preflight" in reason and "line 3" in reason and "nothing started" in reason
    assert "outside.gcode" not in server.stored()
    _nothing_changed(server)


def test_no_cors_headers_ever(make_server):
    server = make_server()
    origin = {"Origin": "http://evil.example", "Access-Control-Request-Method": "POST"}
    for method, key in (("OPTIONS", None), ("OPTIONS", True), ("GET", True)):
        reply = server.request(method, "/api/version", headers=origin, key=key)
        assert not any(h.startswith("access-control-") for h in reply.headers), reply.headers
    assert "server" not in server.request("GET", "/api/version").headers
