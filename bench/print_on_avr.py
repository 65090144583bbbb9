"""A whole print on the AVR firmware in simavr against the Python device at the same limits.

    python bench/print_on_avr.py [--gcode examples/example.gcode] [--profile paper-prototype]
                                 [--engine] [--rate N] [--speedup 1] [--busy-host]
                                 [--from-layer N [--to-layer M]] [--keep DIR]

Builds the firmware (the default build, or with ``--engine`` the step engine's build;
``--rate`` sets the ``MAX_STEP_RATE`` it announces, else the build's own), prints the file
with ``cdprhost print --port`` on it in simavr (the hotend warm at 190 C, as the first-layer
test), prints it again on ``cdprhost sim-device --firmware python`` announcing the AVR's
rate, and prints JSON figures:

- ``avr`` / ``python``: the job's status, device time of the print (``print_time_s``) and
  the job's own estimate;
- ``records_equal``: every executed segment's number, step totals and device-clock times
  the same on both (the AVR's record is read from its pins, at its motion marker); else the
  rows that differ or are missing; ``final_steps_equal``: the step counters each device
  reported when the job ended (what moved, whatever the record says);
- ``unlimited_s``: the same file planned with the profile's own limits (no step-rate cap:
  what the board costs is ``avr.print_time_s / unlimited_s - 1``, less the homing time
  that counts in the device's motion time only);
- ``harness``: the simulator's figures (late or lost pulses, tick overruns, stalls).

``--busy-host``: the host fits no schedule block it is not bound to (its time for the fits,
``segment_feed.FIT_TURN_S``, at 0), as a host with no time to spare: every ramp the device
may step from its profile (under ``STEPPING``'s rate) goes without its block, to the tick's
DDA beside the engine.

``--from-layer N``: the file's start (its lines before the first layer: homing, heating)
and its layers from the Nth on (1-based, marked as the host's reader marks them:
``;LAYER_CHANGE``, Cura's ``;LAYER:``, Simplify3D's ``; layer N, Z =``), as one
file for both devices and the plan with no cap: the cup's upper layers in 5 minutes
instead of all of it in 15.

A print in simavr runs in real time at ``--speedup 1`` (a real board's pace): the cup takes
about 15 minutes at 26,000 steps/s. Use ``--keep DIR`` to keep both records.

Measured (issue 29), ``--engine --rate 26000`` (26,000 steps/s announced, 8,000 without a block), the
cup with paper-prototype, nothing else running: printed in 749.47 s on the AVR, +0.66 % on
the plan with no step-rate cap (744.59 s; +0.39 % without the start's 2.00 s of homing),
the job's estimate 747.47 s, the AVR's record equal to the Python device's (24,371
segments), 0 late pulses, 0 lost steps, 17 tick overruns. Before the host cut its ramps for
their blocks: 2,958 tick overruns, 7 steps lost, the record off by 6 steps. With
``--busy-host``: the same time, both devices' final step counters equal, no step lost or
late, but 424 tick overruns and 19,278 record rows off by 1-3 steps (2 missing) from
segment 3,004: the record's marker late under overruns (firmware/README.md).
``--engine --rate 26000 --from-layer 10`` (layers 10-40, 266 s of print, 14,337 segments):
clean in none of 6 runs; 4 ran dry (UNDERRUN), 2 completed with 51-187 tick overruns and
thousands of record rows off, with up to about 3,500 frames sent again: the ring of
schedule chunks full, frames refused (firmware/README.md, "Not yet"). The whole cup again
on 0c69937 (``--engine --rate 26000``, idle): UNDERRUN at segment 17,990 (628 s in), 2,887
frames sent again by then. The clean run above was not the rule.
Stop 50 found the records apart again (the counters equal): a steady segment after two
0.65 ms ramps lost its module steps (the engine's ring full, docs/step-engine.md section
10). Fixed in stop 51: the whole cup at 26,000 in 749.47 s, records equal over 24,371
segments, 0 steps lost or late, 7 tick overruns (``--from-layer 6 --to-layer 6`` shows the
fault in 4 minutes).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cdprhost.gcode import annotations  # noqa: E402
from cdprhost.preflight.run import preflight  # noqa: E402
from cdprhost.profile import load_profile  # noqa: E402


def build(engine: bool, rate: int | None) -> Path:
    """The build directory with ``cdpr-sim`` and ``cdpr-sim.elf`` for these options."""
    flags = (["-DSTEP_ENGINE=1"] if engine else []) + (
        [f"-DMAX_STEP_RATE={rate}UL"] if rate else []
    )
    name = ("engine" if engine else "default") + (f"-rate-{rate}" if rate else "")
    build_dir = f"build/print-{name}"
    cmd = ["make", "-s", "-C", str(ROOT / "firmware"), f"BUILD={build_dir}"]
    cmd += [f"EXTRA_CFLAGS={' '.join(flags)}", "all", "sim"]
    subprocess.run(cmd, check=True)
    return ROOT / "firmware" / build_dir


def announced_rates(build_dir: Path) -> tuple[int, int | None, int | None, int | None]:
    """The build's MAX_STEP_RATE (IDENT), PROFILE_STEP_RATE (STEPPING), the entries of
    its ring of schedule blocks (RING; None: the default build keeps none) and the budget
    its axes share (STEP_BUDGET; None: none), read from a short session."""
    from cdprhost.link.connect import open_link  # the host's own handshake

    proc = subprocess.Popen(
        [str(build_dir / "cdpr-sim"), str(build_dir / "cdpr-sim.elf"), "--speedup", "1"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        pty = proc.stdout.readline().strip() if proc.stdout else ""
        link = open_link(pty)
        try:
            assert link.identity is not None and link.caps is not None
            ring = link.ring.entries if link.ring is not None else None
            caps = link.caps
            return (
                int(link.identity.max_step_rate),
                caps.profile_step_rate,
                ring,
                caps.total_step_rate,
            )
        finally:
            link.close()
    finally:
        proc.terminate()
        proc.wait(timeout=30)


#: ``cdprhost`` with the host's time for the ramps' fits at 0 (``--busy-host``)
BUSY_HOST = (
    "import sys; import cdprhost.link.segment_feed as feed; feed.FIT_TURN_S = 0.0; "
    "from cdprhost.cli.main import main; sys.exit(main())"
)


def from_layer(gcode: str, layer: int, last: int | None = None) -> str:
    """``gcode``'s lines before its first layer and its layers from ``layer`` (1-based) on,
    up to ``last`` (its end; None: the file's), the layers as the host's reader marks them
    (``cdprhost.gcode.annotations``)."""
    lines = gcode.splitlines(keepends=True)
    found = annotations.scan(gcode.encode())
    style = annotations.choose_style(found)
    marks = [a.index for a in found if a.tag == style.value]
    if not 1 <= layer <= len(marks):
        raise SystemExit(f"--from-layer {layer}: the file has {len(marks)} marked layers")
    if last is not None and not layer <= last <= len(marks):
        raise SystemExit(f"--to-layer {last}: not between {layer} and {len(marks)}")
    end = marks[last] if last is not None and last < len(marks) else len(lines)
    return "".join(lines[: marks[0]] + lines[marks[layer - 1] : end])


def print_on(
    cmd: list[str], gcode: str, profile: str, tmp: Path, env: dict, busy: bool = False
) -> dict:
    """``cdprhost print`` on the device ``cmd`` starts (it prints its pty first)."""
    dev = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, env=env)
    try:
        pty = dev.stdout.readline().strip() if dev.stdout else ""
        if not pty.startswith("/dev/"):
            raise SystemExit(f"the device printed {pty!r}")
        report = tmp / "job.json"
        host = [sys.executable, "-c", BUSY_HOST] if busy else [sys.executable, "-m", "cdprhost"]
        args = [*host, "print", gcode, "--profile", profile]
        subprocess.run(
            [*args, "--port", pty, "--json", str(report)], check=False, env=env, stdout=sys.stderr
        )
        job = json.loads(report.read_text()) if report.exists() else {"status": "no report"}
    finally:
        dev.send_signal(signal.SIGTERM)
        dev.wait(timeout=120)
    return job


def rows(path: Path) -> list[dict]:
    """A record's rows (none when the device wrote no record)."""
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gcode", default=str(ROOT / "examples" / "example.gcode"))
    ap.add_argument("--profile", default="paper-prototype")
    ap.add_argument("--engine", action="store_true", help="the step engine's build")
    ap.add_argument("--rate", type=int, help="MAX_STEP_RATE of the build (default: its own)")
    ap.add_argument("--speedup", type=float, default=1.0)
    ap.add_argument("--keep", type=Path, help="copy both records and the job logs here")
    ap.add_argument(
        "--busy-host", action="store_true", help="no schedule block the host is not bound to"
    )
    ap.add_argument("--from-layer", type=int, help="the file's start, then its layers from N on")
    ap.add_argument("--to-layer", type=int, help="with --from-layer: its layers up to N only")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="print-on-avr-"))
    try:
        run(args, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def run(args: argparse.Namespace, work: Path) -> None:
    if args.from_layer is not None:
        part = work / f"{Path(args.gcode).stem}-from-layer-{args.from_layer}.gcode"
        text = Path(args.gcode).read_text()
        part.write_text(from_layer(text, args.from_layer, args.to_layer))
        args.gcode = str(part)
    build_dir = build(args.engine, args.rate)
    rate, profile_rate, ring, total = announced_rates(build_dir)
    unlimited = preflight(
        args.gcode, load_profile(args.profile).model_copy(update={"device": None})
    )
    out: dict = {"gcode": args.gcode, "profile": args.profile, "engine": args.engine, "rate": rate}
    out["from_layer"] = args.from_layer
    out["to_layer"] = args.to_layer
    out["busy_host"] = args.busy_host
    out["profile_step_rate"] = profile_rate
    out["ring_entries"] = ring
    out["total_step_rate"] = total
    out["unlimited_s"] = unlimited.estimated_time_s
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        env = {**os.environ, "CDPRHOST_STATE": str(tmp / "state")}
        fields = ("status", "print_time_s", "estimated_time_s", "final_steps", "notices")
        for kind in ("avr", "python"):
            (tmp / kind).mkdir()
            record = tmp / kind / "record.jsonl"
            if kind == "avr":
                stats = tmp / kind / "stats.json"
                cmd = [str(build_dir / "cdpr-sim"), str(build_dir / "cdpr-sim.elf")]
                cmd += ["--speedup", f"{args.speedup:g}", "--record", str(record)]
                cmd += ["--stats", str(stats), "--hotend-start-c", "190"]
            else:
                cmd = [sys.executable, "-m", "cdprhost", "sim-device", "--firmware", "python"]
                cmd += ["--speedup", "25", "--record", str(record), "--max-step-rate", str(rate)]
                cmd += ["--faults", "hotend_start_c=190"]
                if profile_rate is not None and profile_rate < rate:
                    cmd += ["--profile-step-rate", str(profile_rate)]
                if total is not None:  # the same plan: the budget reaches the host's plan
                    cmd += ["--total-step-rate", str(total)]
                # no --ring-entries: the reference runs at 25x, where the ring's tens of ms
                # of fast ramps are a ms or two of the host's time (it ran dry at once);
                # its record does not depend on the ring, only its waits do
            t0 = time.monotonic()
            job = print_on(cmd, args.gcode, args.profile, tmp / kind, env, args.busy_host)
            out[kind] = {k: job.get(k) for k in fields} | {
                "wall_s": round(time.monotonic() - t0, 1)
            }
            if kind == "avr":
                out["harness"] = json.loads(stats.read_text()) if stats.exists() else {}
            out[kind]["segments"] = len(rows(record))
        if args.keep:
            shutil.copytree(tmp, args.keep, dirs_exist_ok=True)
        a, p = rows(tmp / "avr" / "record.jsonl"), rows(tmp / "python" / "record.jsonl")
        out["records_equal"] = a == p
        # the step counters each device reported at the end: what moved, whatever its record
        out["final_steps_equal"] = out["avr"].get("final_steps") == out["python"].get("final_steps")
        if a != p:
            by_seq = {r["seq"]: r for r in p}
            out["rows_differing"] = sum(by_seq.get(r["seq"]) not in (None, r) for r in a)
            out["rows_missing"] = len(set(by_seq) - {r["seq"] for r in a})
            first = next((i for i, (x, y) in enumerate(zip(a, p)) if x != y), min(len(a), len(p)))
            out["first_difference"] = {
                "index": first,
                "avr": a[first : first + 1],
                "python": p[first : first + 1],
            }
    printed = out["avr"].get("print_time_s") or 0.0
    if printed and out["unlimited_s"]:
        out["board_cost_pct"] = round(100.0 * (printed / out["unlimited_s"] - 1.0), 2)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
