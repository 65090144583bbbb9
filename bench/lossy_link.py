"""The link on a noisy and on a silent line (issues 30 and 32): the acceptance runs.

Each section starts ``cdprhost sim-device`` in its own process on a pty, as a user would:

1. ``handshake``: N handshakes (``open_link``) to a device at 1x and at 10x with
   ``corrupt=0.01,drop=0.01`` per byte; how many succeed and how long each took.
2. ``stream``: ``cdprhost print --port`` of a file on that line, one run per seed; a run
   passes when it completes and the device's record equals the embedded print's (the
   baseline, computed in the same run). ``--stream-file head`` is the fixture's start
   (heating, homing and the first ``--head-moves`` moves of layer 1) at ``--stream-speedup``
   (default 1x); ``two`` is its first two layers (default 10x).
3. ``clean``: a print of ``--clean-file`` (default ``examples/example.gcode``; with
   ``--clean-layers N`` the fixture's first N layers) at ``--clean-speedup`` (default 1x) on
   a clean pty: the host's retransmissions (target 0).
4. ``frozen``: a link to a 1x device whose process is then stopped (SIGSTOP): the host's
   retransmissions in the first 2 s (target: about 10 at most, the 25 ms floor doubling),
   and when the link declares the device lost (bounded: the link timeout of silence).

Run: python bench/lossy_link.py [--only handshake|stream|clean|frozen] [--seeds 5] ...
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

FIXTURE = (
    Path(os.environ.get("CDPRHOST_SHARED", REPO.parent / "shared"))
    / "fixtures"
    / "part-prusaslicer.gcode"
)
PROFILE = "paper-prototype"
LOSSY = "corrupt=0.01,drop=0.01"


def start_device(*args: str) -> tuple[subprocess.Popen[str], str]:
    dev = subprocess.Popen(
        [sys.executable, "-m", "cdprhost", "sim-device", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    assert dev.stdout is not None
    return dev, dev.stdout.readline().strip()


def stop_device(dev: subprocess.Popen[str]) -> None:
    dev.send_signal(signal.SIGCONT)
    dev.send_signal(signal.SIGTERM)
    dev.wait(30)


def head_file(src: Path, out: Path, moves: int) -> Path:
    """The fixture's start up to and including the ``moves``-th extruding move of layer 1."""
    lines, seen, layer = [], 0, False
    for line in src.read_text().splitlines():
        lines.append(line)
        layer = layer or line.startswith(";LAYER_CHANGE")
        if layer and line.startswith("G1 ") and " E" in line:
            seen += 1
            if seen >= moves:
                break
    path = out / f"head-{moves}.gcode"
    path.write_text("\n".join([*lines, "M104 S0", "M140 S0"]) + "\n")
    return path


def first_layers(src: Path, out: Path, layers: int) -> Path:
    lines, seen = [], 0
    for line in src.read_text().splitlines():
        if line.startswith(";LAYER_CHANGE"):
            seen += 1
            if seen > layers:
                break
        lines.append(line)
    path = out / f"first-{layers}-layers.gcode"
    path.write_text("\n".join([*lines, "M104 S0", "M140 S0"]) + "\n")
    return path


def reference_record(gcode: Path) -> list[dict]:
    from cdprhost.job.runner import PrintJob, PrintOptions
    from cdprhost.profile import load_profile
    from cdprhost.sim.embedded import open_embedded

    holder = {}

    def factory():
        holder["link"] = open_embedded()
        return holder["link"]

    with tempfile.TemporaryDirectory() as tmp:
        result = PrintJob(gcode, load_profile(PROFILE), factory, PrintOptions(resume_dir=tmp)).run()
    assert result.status == "completed", result.reason
    return list(holder["link"].device.record)


def print_over_pty(
    gcode: Path,
    speedup: float,
    faults: str,
    why: list[str] | None = None,
    firmware: str = "python",
) -> tuple[dict, list[dict], float]:
    """A print over a pty on ``sim-device --firmware firmware``; ``why`` collects the host's
    log lines on each retransmission."""
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        record = t / "record.jsonl"
        args = ["--firmware", firmware, "--speedup", f"{speedup:g}", "--record", str(record)]
        dev, port = start_device(*args, *(["--faults", faults] if faults else []))
        report = t / "report.json"
        # a printer service of its own (the print runs in it; its log is read below)
        env = {**os.environ, "CDPRHOST_STATE": str(t / "state"), "CDPRHOST_RUN": str(t / "run")}
        t0 = time.monotonic()
        host = subprocess.run(
            [sys.executable, "-m", "cdprhost", "print", str(gcode), "--profile", PROFILE]
            + ["--port", port, "--json", str(report)],
            check=False,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        wall = time.monotonic() - t0
        stop_device(dev)
        if why is not None:  # the link logs each resend in the service's log (info)
            for log in sorted((t / "run").glob("*.log")):
                why += [x for x in log.read_text(errors="replace").splitlines() if "resent" in x]
        if report.exists():
            result = json.loads(report.read_text())
        else:
            err = host.stderr.strip().splitlines()
            result = {"status": "crashed", "reason": err[-1] if err else f"exit {host.returncode}"}
        rows = [json.loads(x) for x in record.read_text().splitlines()] if record.exists() else []
    return result, rows, wall


def handshakes(speedup: float, n: int) -> None:
    from cdprhost.link import open_link

    ok, times, errors = 0, [], []
    for k in range(n):
        dev, port = start_device("--speedup", f"{speedup:g}", "--faults", f"{LOSSY},seed={k}")
        t0 = time.monotonic()
        try:
            link = open_link(port)
            link.close()
            ok += 1
            times.append(time.monotonic() - t0)
        except Exception as exc:  # noqa: BLE001 - reported
            errors.append(f"{type(exc).__name__}: {exc}")
        finally:
            stop_device(dev)
    worst = max(times) if times else float("nan")
    print(f"  {speedup:g}x: {ok} of {n} handshakes; slowest {worst:.2f} s", flush=True)
    for e in errors:
        print(f"    {e[:200]}")


def streams(gcode: Path, speedup: float, seeds: int) -> None:
    ref = reference_record(gcode)
    passed = 0
    for seed in range(1, seeds + 1):
        result, rows, wall = print_over_pty(gcode, speedup, f"{LOSSY},seed={seed}")
        good = result.get("status") == "completed" and rows == ref
        passed += good
        print(
            f"  seed {seed}: {result.get('status')} record "
            f"{'identical' if rows == ref else 'DIFFERS'} segments {result.get('segments')} "
            f"retransmits {result.get('retransmits')} wall {wall:.0f} s"
            + ("" if good else f"  ({str(result.get('reason'))[:200]})"),
            flush=True,
        )
    print(f"  {passed} of {seeds} exact at {speedup:g}x ({len(ref)} segments)")


def clean_print(gcode: Path, speedup: float = 1.0) -> None:
    why: list[str] = []
    result, _rows, wall = print_over_pty(gcode, speedup, "", why)
    print(
        f"  {gcode.name} at {speedup:g}x, clean pty: {result.get('status')} segments "
        f"{result.get('segments')} retransmits {result.get('retransmits')} wall {wall:.0f} s"
        + ("" if result.get("status") == "completed" else f"  ({result.get('reason')})"),
        flush=True,
    )
    for line in why:  # when and why the host resent (timeout, NAK, stale report)
        print(f"    {line[:300]}")


def frozen(seconds: float = 2.0) -> None:
    """A link streaming to a 1x device whose process is then stopped (SIGSTOP) mid-stream."""
    import threading

    from cdprhost.link import LinkError, open_link
    from firmware_protocol.streams import demo_stream

    dev, port = start_device("--speedup", "1")
    link = open_link(port)

    def stream() -> None:
        with contextlib.suppress(LinkError, OSError):  # stopped: the link is declared lost
            link.queue_segments(demo_stream(20000, seed=1))

    worker = threading.Thread(target=stream, daemon=True)
    try:
        worker.start()
        time.sleep(1.5)
        before = link.counters.retransmits
        dev.send_signal(signal.SIGSTOP)
        t0 = time.monotonic()
        marks = []
        while time.monotonic() - t0 < seconds:
            time.sleep(0.05)
            marks.append(link.counters.retransmits - before)
        while link.lost is None and time.monotonic() - t0 < 30:  # declared lost: when?
            time.sleep(0.05)
        lost = time.monotonic() - t0
        print(
            f"  device stopped mid-stream: {marks[-1]} retransmissions in the first {seconds:g} s "
            f"(after 0.5 s: {marks[9]}, 1 s: {marks[19]}); "
            + (
                f"the link declared it lost after {lost:.1f} s ({link.timeout_s:g} s timeout)"
                if link.lost is not None
                else "not declared lost within 30 s"
            ),
            flush=True,
        )
    finally:
        stop_device(dev)
        worker.join(10)
        link.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", action="append", choices=("handshake", "stream", "clean", "frozen"))
    ap.add_argument("--handshakes", type=int, default=20)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--stream-file", choices=("head", "two"), default="two")
    ap.add_argument("--stream-speedup", type=float)
    ap.add_argument("--head-moves", type=int, default=150)
    ap.add_argument("--clean-file", type=Path, default=REPO / "examples" / "example.gcode")
    ap.add_argument("--clean-layers", type=int, help="the fixture's first N layers instead")
    ap.add_argument("--clean-speedup", type=float, default=1.0)
    args = ap.parse_args()
    run = set(args.only or ("handshake", "stream", "clean", "frozen"))
    load = os.getloadavg()
    print(f"load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as tmp:
        if "handshake" in run:
            print(f"1. handshakes with {LOSSY}")
            for s in (1, 10):
                handshakes(s, args.handshakes)
        if "stream" in run:
            if args.stream_file == "head":
                path, speed = head_file(FIXTURE, Path(tmp), args.head_moves), 1.0
            else:
                path, speed = first_layers(FIXTURE, Path(tmp), 2), 10.0
            speed = args.stream_speedup or speed
            print(f"2. {path.name} at {speed:g}x with {LOSSY}, {args.seeds} seeds")
            streams(path, speed, args.seeds)
        if "clean" in run:
            print(f"3. clean pty at {args.clean_speedup:g}x")
            clean = args.clean_file
            if args.clean_layers:
                clean = first_layers(FIXTURE, Path(tmp), args.clean_layers)
            clean_print(clean, args.clean_speedup)
        if "frozen" in run:
            print("4. a frozen device")
            frozen()


if __name__ == "__main__":
    main()
