"""Real clients over loopback: PrusaSlicer's exact request replayed byte for byte, OctoPrint's
own client (``octoprint client ... upload``) when installed, and octorest's request. Each
upload with print=true prints to the end on the embedded simulated device."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import uuid
from pathlib import Path

import pytest

from tests.server.conftest import multipart, printed_to_the_end, small_part

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "examples" / "example.gcode"
CURL_BOUNDARY = "------------------------" + "Zq3d0Fv8Rk1sX7bN2mYc4T"  # 24 dashes + 22 alnum


def raw_exchange(port: int, request: bytes, expect_continue: bool = False) -> tuple[int, bytes]:
    """Send ``request`` as is; the status and body of the reply (bounded reads)."""
    with socket.create_connection(("127.0.0.1", port), timeout=60) as sock:
        if expect_continue:  # curl: headers, wait for 100 Continue, then the body
            head, body = request.split(b"\r\n\r\n", 1)
            sock.sendall(head + b"\r\n\r\n")
            interim = sock.recv(4096)
            assert interim.startswith(b"HTTP/1.1 100"), interim
            sock.sendall(body)
        else:
            sock.sendall(request)
        data = b""
        for _ in range(10_000):  # bounded: until the declared body has arrived
            if b"\r\n\r\n" in data:
                head, _, rest = data.partition(b"\r\n\r\n")
                length = next(
                    int(line.split(b":", 1)[1])
                    for line in head.split(b"\r\n")
                    if line.lower().startswith(b"content-length:")
                )
                if len(rest) >= length:
                    return int(head.split(b" ", 2)[1]), rest[:length]
            chunk = sock.recv(65536)
            if not chunk:
                break
            data += chunk
    raise AssertionError(f"incomplete reply: {data[:300]!r}")


def prusaslicer_requests(port: int, key: str, name: str, data: bytes, start: bool) -> list[bytes]:
    """What PrusaSlicer (2.x, physical printer of host type OctoPrint) sends: the connection
    test ``GET /api/version``, then the upload made with libcurl's form API: fields ``print``
    and ``path`` (the upload path's folder, '' for none), then ``file`` as
    application/octet-stream; the key in ``X-Api-Key``; curl's boundary form."""
    host = f"Host: 127.0.0.1:{port}\r\nUser-Agent: PrusaSlicer/2.8.1\r\nAccept: */*\r\n"
    version = f"GET /api/version HTTP/1.1\r\n{host}X-Api-Key: {key}\r\n\r\n".encode()
    b = CURL_BOUNDARY
    body = (
        (
            f"--{b}\r\n"
            'Content-Disposition: form-data; name="print"\r\n\r\n'
            f"{'true' if start else 'false'}\r\n"
            f"--{b}\r\n"
            'Content-Disposition: form-data; name="path"\r\n\r\n'
            "\r\n"
            f"--{b}\r\n"
            f'Content-Disposition: form-data; name="file"; filename="{name}"\r\n'
            "Content-Type: application/octet-stream\r\n\r\n"
        ).encode()
        + data
        + f"\r\n--{b}--\r\n".encode()
    )
    expect = "Expect: 100-continue\r\n" if len(body) > 1024 * 1024 else ""
    upload = (
        f"POST /api/files/local HTTP/1.1\r\n{host}X-Api-Key: {key}\r\n"
        f"Content-Length: {len(body)}\r\n{expect}"
        f"Content-Type: multipart/form-data; boundary={b}\r\n\r\n"
    ).encode() + body
    return [version, upload]


def test_prusaslicer_upload_and_print_replayed_byte_for_byte_prints_to_the_end(serve):
    """On `cdprhost serve` with the simulated device: the connection test, then the upload."""
    server = serve("--speedup", "1000")
    data = EXAMPLE.read_bytes()
    version, upload = prusaslicer_requests(server.port, server.key, "cup.gcode", data, True)
    status, body = raw_exchange(server.port, version)
    assert status == 200 and b'"text":"OctoPrint' in body and b'"api"' in body
    status, body = raw_exchange(server.port, upload)
    assert status == 201, body
    assert (server.uploads / "cup.gcode").read_bytes() == data
    job = server.wait_job(printed_to_the_end)
    assert job["job"]["file"]["name"] == "cup.gcode"
    assert "PrusaSlicer/2.8.1" in job["job"]["user"]
    code, err = server.stop()
    assert code == 0 and "job done: completed" in err, err


def test_prusaslicer_large_upload_with_expect_100_continue(make_server):
    """Above 1 MiB curl asks ``Expect: 100-continue`` and waits for the interim answer."""
    server = make_server(max_upload_bytes=4_000_000)
    data = small_part().encode() + b";" + b"p" * 1_200_000 + b"\n"
    _, upload = prusaslicer_requests(server.port, server.key, "big.gcode", data, False)
    assert b"Expect: 100-continue" in upload
    status, body = raw_exchange(server.port, upload, expect_continue=True)
    assert status == 201, body
    assert (server.uploads / "big.gcode").read_bytes() == data
    assert server.links == []  # print=false: stored only


def octoprint_executable() -> str | None:
    return os.environ.get("CDPRHOST_OCTOPRINT") or shutil.which("octoprint")


def test_octoprint_client_upload_with_print_true_prints_to_the_end(serve, tmp_path):
    """`octoprint client ... upload /api/files/local FILE -P print true` on `cdprhost serve`."""
    exe = octoprint_executable()
    if exe is None:
        pytest.skip("OctoPrint is not installed (CI installs it in .venv-octoprint)")
    server = serve("--speedup", "1000")
    part = tmp_path / "part.gcode"
    part.write_text(small_part())
    cmd = [exe, "--basedir", str(tmp_path / "octo"), "client", "--apikey", server.key]
    cmd += ["--host", "127.0.0.1", "--port", str(server.port)]
    out = subprocess.run(
        [*cmd, "upload", "/api/files/local", str(part), "-P", "print", "true"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert "Status Code: 201" in out.stdout, out.stdout + out.stderr
    server.wait_job(printed_to_the_end)
    code, err = server.stop()
    assert code == 0 and "job done: completed" in err, err


def test_octoprint_client_request_replayed_prints(make_server):
    """The request OctoPrint's client makes (python-requests multipart: the ``-P`` fields
    first, then the file without a content type; a uuid4-hex boundary)."""
    server = make_server()
    b = uuid.UUID(int=0x1234).hex
    body = (
        (
            f'--{b}\r\nContent-Disposition: form-data; name="print"\r\n\r\ntrue\r\n'
            f'--{b}\r\nContent-Disposition: form-data; name="file"; filename="part.gcode"\r\n\r\n'
        ).encode()
        + small_part().encode()
        + f"\r\n--{b}--\r\n".encode()
    )
    request = (
        f"POST /api/files/local HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\n"
        "User-Agent: python-requests/2.32.3\r\nAccept-Encoding: gzip, deflate\r\nAccept: */*\r\n"
        f"Connection: keep-alive\r\nX-Api-Key: {server.key}\r\nContent-Length: {len(body)}\r\n"
        f"Content-Type: multipart/form-data; boundary={b}\r\n\r\n"
    ).encode() + body
    status, reply = raw_exchange(server.port, request)
    assert status == 201, reply
    server.wait_job(lambda j: j["state"] == "Operational" and j["progress"]["completion"])
    assert server.printer.status().job.state.value == "done"


def test_octorest_upload_stores_without_printing_and_says_so(make_server):
    """octorest 0.4 passes ``select``/``print`` as ``json=`` beside ``files=``; requests then
    sends the file alone (the JSON is dropped), so the server receives a plain upload. It is
    stored and not printed, and the reply says so: ``effectivePrint`` false."""
    server = make_server()
    body, ctype = multipart([], ("part.gcode", small_part().encode()))
    reply = server.request("POST", "/api/files/local", body, {"Content-Type": ctype})
    assert reply.status == 201
    assert reply.json()["effectivePrint"] is False and reply.json()["effectiveSelect"] is False
    assert server.stored() == ["part.gcode"]
    assert server.links == [] and server.job()["state"] == "Operational"
