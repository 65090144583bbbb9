"""Streaming benchmark: how fast the fixture prints with zero underruns, over a real pty.

`cdprhost sim-device --speedup X [--faults F]` runs the device model in its own process
on a pseudo-terminal; `cdprhost print --port` drives it as a user would. A trial passes
when the print completes (no underrun, no other failure) and the device's record
(segment numbers, absolute steps, motion clock) equals the record of the same file
printed on the embedded device on a clean link: the baseline, computed in the same run.

Reported (with the machine's load average, since 2 cores are shared):
1. the highest speed-up that prints the whole fixture with zero underruns (clean link);
2. the first 6 layers at 1000x with corrupt=0.001,drop=0.001 (record identical?);
3. the highest speed-up with corrupt=0.01,drop=0.01, searched on the first layer, then
   the whole fixture at that speed-up (record identical?);
4. host CPU per second of printing at 1x (the print process, over --cpu-seconds);
5. wire bytes per segment on the fixture and the same motion as Marlin ASCII;
6. retransmissions on a clean link left idle, then paused, --idle-seconds each (issue 23).

   Baseline: the same link connected to a 1x device and idle, over as long, same run.
Run: python bench/link.py [--quick] [--cpu-seconds 60] [--skip-lossy-whole] [--only SECTION]
``--quick``: the first 6 layers instead of the whole fixture (ladder and lossy run);
``--only clean|light|lossy|cpu|wire|idle`` (repeatable) runs those sections only.
Figures of the latest run are in the closing note of issue 12 (and docs in PROTOCOL.md).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from bench_inputs import gcode_fixture

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

PROFILE = "paper-prototype"
CLEAN_LADDER = (100, 200, 350, 500, 700, 1000, 1400, 2000)
LOSSY_LADDER = (5, 20, 50, 100, 200, 350, 500)
LOSSY = "corrupt=0.01,drop=0.01"
LIGHT = "corrupt=0.001,drop=0.001"


@dataclass
class Trial:
    speedup: float
    faults: str
    status: str
    reason: str
    segments: int
    retransmits: int
    record_equal: bool
    wall_s: float
    host_cpu_s: float

    @property
    def ok(self) -> bool:
        return self.status == "completed" and self.record_equal


def first_layers(src: Path, out: Path, layers: int) -> Path:
    """The fixture up to (not including) layer ``layers + 1``, then the hotend off."""
    lines, seen = [], 0
    for line in src.read_text().splitlines():
        if line.startswith(";LAYER_CHANGE"):
            seen += 1
            if seen > layers:
                break
        lines.append(line)
    path = out / f"first-{layers}-layers.gcode"
    path.write_text("\n".join([*lines, "M104 S0"]) + "\n")
    return path


def reference_record(gcode: Path) -> list[dict]:
    """The baseline: the record of ``gcode`` printed on the embedded device, clean link."""
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


def trial(gcode: Path, speedup: float, faults: str, reference: list[dict]) -> Trial:
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        record = tmp_path / "record.jsonl"
        cmd = [sys.executable, "-m", "cdprhost", "sim-device", "--speedup", f"{speedup:g}"]
        cmd += ["--record", str(record)] + (["--faults", faults] if faults else [])
        dev = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        assert dev.stdout is not None
        port = dev.stdout.readline().strip()
        report = tmp_path / "report.json"
        env = {**os.environ, "CDPRHOST_STATE": str(tmp_path / "state")}
        t0 = time.monotonic()
        host = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "cdprhost",
                "print",
                str(gcode),
                "--profile",
                PROFILE,
                "--port",
                port,
                "--json",
                str(report),
                "--log",
                str(tmp_path / "job.jsonl"),
            ],
            stdout=subprocess.DEVNULL,
            stderr=(tmp_path / "host.err").open("w"),
            env=env,
        )
        _, _, usage = os.wait4(host.pid, 0)
        wall = time.monotonic() - t0
        dev.send_signal(signal.SIGTERM)
        dev.wait(60)
        if report.exists():
            result = json.loads(report.read_text())
        else:  # no summary: the host died; its last words say why
            err = (tmp_path / "host.err").read_text(errors="replace").strip().splitlines()
            result = {"status": "crashed", "reason": err[-1] if err else f"exit {host.returncode}"}
        rows = [json.loads(x) for x in record.read_text().splitlines()] if record.exists() else []
    return Trial(
        speedup,
        faults,
        result.get("status", "?"),
        result.get("reason", ""),
        int(result.get("segments", 0)),
        int(result.get("retransmits", 0)),
        rows == reference,
        wall,
        usage.ru_utime + usage.ru_stime,
    )


def ladder(
    gcode: Path, speeds: tuple[float, ...], faults: str, reference: list[dict]
) -> tuple[Trial | None, list[Trial]]:
    """The highest speed-up of ``speeds`` (ascending) that passes; a failure is retried once
    (the machine is shared), two failures end the search."""
    best, trials = None, []
    for s in speeds:
        t = trial(gcode, s, faults, reference)
        trials.append(t)
        report(t)
        if not t.ok:
            t = trial(gcode, s, faults, reference)
            trials.append(t)
            report(t)
        if not t.ok:
            break
        best = t
    return best, trials


def report(t: Trial) -> None:
    print(
        f"  {t.speedup:>6g}x {t.faults or 'clean':<26} {t.status:<9} "
        f"record {'identical' if t.record_equal else 'DIFFERS'}  segments {t.segments}  "
        f"retransmits {t.retransmits}  wall {t.wall_s:.1f} s  host cpu {t.host_cpu_s:.1f} s"
        + (f"  ({t.reason[:160]})" if t.status != "completed" else ""),
        flush=True,
    )


def real_time_device() -> tuple[subprocess.Popen[str], str]:
    """A ``sim-device`` at 1x in its own process, and the pty it prints."""
    dev = subprocess.Popen(
        [sys.executable, "-m", "cdprhost", "sim-device", "--speedup", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    assert dev.stdout is not None
    return dev, dev.stdout.readline().strip()


def idle_link_cpu(seconds: float) -> float:
    """The baseline of (4): host CPU per second of a link connected to a 1x device and
    left idle (its keep-alive thread only), over ``seconds`` in this process."""
    from cdprhost.link import open_link

    dev, port = real_time_device()
    link = open_link(port)
    try:
        c0, w0 = time.process_time(), time.monotonic()
        time.sleep(seconds)
        c1, w1 = time.process_time(), time.monotonic()
    finally:
        link.close()
        dev.send_signal(signal.SIGTERM)
        dev.wait(30)
    return (c1 - c0) / (w1 - w0)


def idle_retransmissions(seconds: float) -> dict[str, int]:
    """Issue 23: a link to a 1x device over a pty, left to its keep-alive thread for
    ``seconds`` idle and ``seconds`` paused (a heater on, the queue held by a heater wait,
    the job polling every 0.5 s); host and device retransmissions in each."""
    from cdprhost.link import open_link
    from firmware_protocol.messages import SetHeater, WaitHeater

    dev, port = real_time_device()
    link = open_link(port)
    link.start_keepalive()
    out: dict[str, int] = {}
    try:
        for phase in ("idle", "paused"):
            if phase == "paused":
                link.send(SetHeater(0, 2000), WaitHeater(0, 10))
            before, dev_before = link.counters, link.request_status().device_retransmits
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                time.sleep(0.5)
                if phase == "paused":
                    link.poll(0.0)
            out[f"{phase}_host"] = link.counters.retransmits - before.retransmits
            out[f"{phase}_device"] = link.request_status().device_retransmits - dev_before
    finally:
        link.close()
        dev.send_signal(signal.SIGTERM)
        dev.wait(30)
    return out


def host_cpu_at_1x(gcode: Path, seconds: float) -> tuple[float, float]:
    """Host CPU (this process: the print job and its threads) per second of printing at 1x,
    measured over ``seconds`` once the print is under way; and the wall time measured."""
    from cdprhost.job.runner import PrintJob, PrintOptions
    from cdprhost.job.state import JobState, Progress
    from cdprhost.link import open_link
    from cdprhost.profile import load_profile

    dev, port = real_time_device()
    moving = threading.Event()

    def on_event(e):
        if isinstance(e, Progress) and e.segments_done > 0:
            moving.set()

    with tempfile.TemporaryDirectory() as tmp:
        job = PrintJob(
            gcode,
            load_profile(PROFILE),
            lambda: open_link(port),
            PrintOptions(resume_dir=tmp, log_path=Path(tmp) / "job.jsonl"),
            on_event=on_event,
        )
        worker = threading.Thread(target=job.run, daemon=True)
        worker.start()
        moving.wait(600)
        time.sleep(5.0)  # past the start: planning ahead, heating
        c0, w0 = time.process_time(), time.monotonic()
        time.sleep(seconds)
        c1, w1 = time.process_time(), time.monotonic()
        printing = job.state in (JobState.PRINTING, JobState.HEATING)
        job.request_cancel()
        worker.join(120)
    dev.send_signal(signal.SIGTERM)
    dev.wait(30)
    if not printing:
        print("  (the print ended before the measurement did: shorten --cpu-seconds)")
    return (c1 - c0) / (w1 - w0), w1 - w0


def wire_bytes(gcode: Path) -> dict[str, float]:
    """Bytes per segment of the fixture's planned motion: payload, frames (clean link,
    acknowledgements excluded), and the same endpoints as Marlin ASCII."""
    from cdprhost.kinematics import MachineModel
    from cdprhost.motion.direct import to_wire
    from cdprhost.motion.pipeline import segment_program
    from cdprhost.motion.program import read_items
    from cdprhost.motion.segments import PlannedSegments
    from cdprhost.profile import load_profile
    from firmware_protocol.framing import OVERHEAD
    from firmware_protocol.segments import SegmentContext, encode_segments

    profile = load_profile(PROFILE)
    model = MachineModel.from_profile(profile)
    ctx = SegmentContext()
    n = payload = frames = ascii_bytes = 0
    motion = 0.0
    last_f = None
    items = read_items(gcode, profile, model)
    for out in segment_program(items, profile, model, clock_hz=100_000):
        if not isinstance(out, PlannedSegments):
            continue
        wire = to_wire(out)
        data, _offsets = encode_segments(wire, ctx)
        n += len(wire)
        payload += len(data)
        frames += int(np.ceil(len(data) / 248)) * OVERHEAD
        motion += float(wire.ticks.sum()) / 100_000
        for p, e in zip(out.point, out.e):
            body = f"G1 X{p[0]:.3f} Y{p[1]:.3f} Z{p[2]:.3f} E{e:.5f}"
            f = round(float(np.linalg.norm(p)))  # F only when it changes (a proxy)
            body += f" F{f}" if f != last_f else ""
            last_f = f
            ascii_bytes += len(f"N{n} {body}*99\n")
    return {
        "segments": n,
        "motion_s": motion,
        "payload_per_segment": payload / n,
        "wire_per_segment": (payload + frames) / n,
        "ascii_per_segment": ascii_bytes / n,
    }


SECTIONS = ("clean", "light", "lossy", "cpu", "wire", "idle")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--quick", action="store_true", help="the first 6 layers instead of the whole fixture"
    )
    ap.add_argument("--cpu-seconds", type=float, default=60.0)
    ap.add_argument("--skip-lossy-whole", action="store_true")
    ap.add_argument("--idle-seconds", type=float, default=60.0)
    ap.add_argument(
        "--lossy-speedup",
        type=float,
        help="section 3: skip the first-layer ladder, print the whole run at this speed-up",
    )
    ap.add_argument(
        "--only",
        action="append",
        choices=SECTIONS,
        help="run only these sections (repeatable; to repeat a noisy figure)",
    )
    args = ap.parse_args()
    run = set(args.only or SECTIONS)
    load = os.getloadavg()
    print(
        f"cdprhost link benchmark; load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} "
        f"on {os.cpu_count()} cores"
    )
    summary: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        fixture = gcode_fixture()
        six = first_layers(fixture, Path(tmp), 6)
        one = first_layers(fixture, Path(tmp), 1)
        whole = six if args.quick else fixture
        what = "first 6 layers" if args.quick else "whole fixture"
        refs: dict[Path, list[dict]] = {}

        def ref(path: Path) -> list[dict]:
            if path not in refs:
                refs[path] = reference_record(path)
            return refs[path]

        if "clean" in run:
            print(f"\n1. clean link, {what}: highest speed-up with zero underruns")
            best, _ = ladder(whole, CLEAN_LADDER, "", ref(whole))
            summary.append(
                f"clean, {what}: {best.speedup if best else 0:g}x with zero underruns "
                "(target >= 500x)"
            )
        if "light" in run:
            print(f"\n2. first 6 layers at 1000x with {LIGHT}")
            light = trial(six, 1000, LIGHT, ref(six))
            report(light)
            summary.append(
                f"6 layers, 1000x, {LIGHT}: "
                + ("completed, record identical" if light.ok else "FAILED: " + light.status)
            )
        if "lossy" in run:
            print(f"\n3. {LOSSY}: highest speed-up on the first layer, then the {what} there")
            if args.lossy_speedup:
                speed: float | None = args.lossy_speedup
                text = "first-layer ladder skipped"
            else:
                lossy_best, _ = ladder(one, LOSSY_LADDER, LOSSY, ref(one))
                speed = lossy_best.speedup if lossy_best else None
                text = f"{speed:g}x on the first layer" if speed else "none"
            if speed and not args.skip_lossy_whole:
                lossy_whole = trial(whole, speed, LOSSY, ref(whole))
                report(lossy_whole)
                text += f"; {what} at {lossy_whole.speedup:g}x: " + (
                    "completed, record identical"
                    if lossy_whole.ok
                    else f"FAILED: {lossy_whole.status}"
                )
            summary.append(f"{LOSSY}: {text}")
        if "cpu" in run:
            print(f"\n4. host CPU at 1x over {args.cpu_seconds:g} s of printing")
            cpu, wall = host_cpu_at_1x(one, args.cpu_seconds)
            print(f"  printing: {100 * cpu:.2f} % of a core ({cpu * wall:.2f} s over {wall:.0f} s)")
            idle = idle_link_cpu(args.cpu_seconds)
            print(f"  baseline, the same link connected and idle: {100 * idle:.2f} % of a core")
            summary.append(
                f"host CPU at 1x: {100 * cpu:.2f} % of a core (target <= 2 %); idle connected "
                f"link {100 * idle:.2f} %: printing costs {100 * (cpu - idle):.2f} % more"
            )
        if "wire" in run:
            print(f"\n5. wire bytes per segment ({what})")
            wb = wire_bytes(whole)
            print(
                f"  {wb['segments']} segments, {wb['motion_s']:.0f} s of motion; payload "
                f"{wb['payload_per_segment']:.2f} B, frames {wb['wire_per_segment']:.2f} B "
                f"(target <= 12); ASCII {wb['ascii_per_segment']:.1f} B "
                f"({wb['ascii_per_segment'] / wb['wire_per_segment']:.1f}x)"
            )
        if "idle" in run:
            print(
                f"\n6. retransmissions on a clean idle and paused link, {args.idle_seconds:g} s each"
            )
            r = idle_retransmissions(args.idle_seconds)
            print(f"  {r}")
            summary.append(
                f"idle {args.idle_seconds:g} s: {r['idle_host']} host / {r['idle_device']} device "
                f"retransmissions; paused: {r['paused_host']} / {r['paused_device']} (target 0)"
            )
    print("\nsummary")
    for line in summary:
        print(f"  {line}")
    load = os.getloadavg()
    print(f"  load average at the end {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}")


if __name__ == "__main__":
    main()
