"""`cdprhost serve` and `cdprhost api-key` as a user runs them (separate processes)."""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import urllib.request

import pytest

from cdprhost.server.apikey import KeyFile, key_matches, read_key, rotate
from cdprhost.server.listen import is_loopback, parse_listen
from tests.server.conftest import multipart, small_part

CLI = [sys.executable, "-m", "cdprhost"]


def _env(tmp_path) -> dict[str, str]:
    return {**os.environ, "XDG_CONFIG_HOME": str(tmp_path / "cfg")}


def test_api_key_made_once_with_mode_600_and_rotated(tmp_path):
    env = _env(tmp_path)
    first = subprocess.run([*CLI, "api-key"], env=env, capture_output=True, text=True, timeout=60)
    again = subprocess.run([*CLI, "api-key"], env=env, capture_output=True, text=True, timeout=60)
    path = tmp_path / "cfg" / "cdprhost" / "api-key"
    assert first.returncode == again.returncode == 0
    assert "made now" in first.stderr and "made now" not in again.stderr
    assert first.stdout == again.stdout and len(first.stdout.strip()) == 32
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    rotated = subprocess.run(
        [*CLI, "api-key", "--rotate"], env=env, capture_output=True, text=True, timeout=60
    )
    assert rotated.stdout != first.stdout and read_key(path) == rotated.stdout.strip()
    path.chmod(0o644)
    loose = subprocess.run([*CLI, "api-key"], env=env, capture_output=True, text=True, timeout=60)
    assert loose.returncode == 2 and "readable by others" in loose.stderr


def test_a_running_server_takes_a_rotated_key_at_once(make_server, config_home):
    server = make_server()
    assert server.request("GET", "/api/version").status == 200
    new = rotate(config_home / "cdprhost" / "api-key")
    assert server.request("GET", "/api/version").status == 403  # the old key
    assert server.request("GET", "/api/version", key=new).status == 200


def test_key_comparison_refuses_empty_keys(tmp_path):
    assert not key_matches("", "")
    assert not key_matches("ABC", "")
    assert not key_matches("ABC", None)
    assert key_matches("ABC", "ABC")
    keys = KeyFile(tmp_path / "k")
    assert keys.created and len(keys.current()) == 32


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("5000", ("127.0.0.1", 5000)),
        ("0.0.0.0:8080", ("0.0.0.0", 8080)),
        ("[::1]:5001", ("::1", 5001)),
        ("localhost:0", ("localhost", 0)),
    ],
)
def test_listen_forms(text, expected):
    assert parse_listen(text) == expected


@pytest.mark.parametrize("text", ["x", "1:2:3", "70000", "host:"])
def test_bad_listen_is_a_usage_error(text, tmp_path):
    with pytest.raises(ValueError):
        parse_listen(text)
    out = subprocess.run(
        [*CLI, "serve", "-p", "paper-prototype", "--listen", text],
        env=_env(tmp_path),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "--listen" in out.stderr


def test_loopback_or_not():
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")


def test_serve_prints_an_upload_and_sigterm_stops_the_print_safely(serve):
    server = serve("--speedup", "10")
    assert "API key made now" in server.banner  # said once, at first use ...
    assert server.key and server.key not in server.banner  # ... and never printed
    body, ctype = multipart([("print", "true")], ("long.gcode", small_part(40).encode()))
    headers = {"X-Api-Key": server.key, "Content-Type": ctype}
    req = urllib.request.Request(server.url + "/api/files/local", body, headers)
    with urllib.request.urlopen(req, timeout=60) as resp:
        assert resp.status == 201
    server.wait_job(lambda j: j["state"] == "Printing")
    code, rest = server.stop(signal.SIGTERM)
    assert code == 0, rest
    assert "SIGTERM: stopping" in rest and "job cancelled" in rest
    assert server.key not in rest  # nor anywhere in its log
    assert (server.uploads / "long.gcode").is_file()


def test_serve_on_a_port_that_does_not_exist_says_so_before_listening(tmp_path):
    out = subprocess.run(
        [*CLI, "serve", "-p", "paper-prototype", "--port", str(tmp_path / "no-tty")],
        env=_env(tmp_path),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "no such port" in out.stderr
    assert "upload API on" not in out.stderr


def test_a_listen_address_beyond_loopback_is_warned_about(
    tmp_path, config_home, monkeypatch, capsys
):
    """(Bound on 127.0.0.1 all the same: the test never listens beyond this machine.)"""
    import argparse

    from cdprhost.cli.commands import serve as serve_cmd
    from cdprhost.server import listen

    monkeypatch.setattr(listen, "is_loopback", lambda host: False)
    args = argparse.Namespace(
        uploads=str(tmp_path / "up"), max_upload_mb=1.0, listen=("127.0.0.1", 0), allow_host=[]
    )
    server = serve_cmd.start_api(args, printer=None)
    try:
        err = capsys.readouterr().err
        assert "warning: listening on 127.0.0.1" in err and "not only on this machine" in err
    finally:
        server.stop()
