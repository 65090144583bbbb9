"""Memory of the terminal UI over repeated prints: it must stay flat (issue 23: 143 -> 253 MB).

Run: python bench/tui_memory.py [--prints 14] [--since 4] [--layers 10] [--top 8] [--frames 1]
[--in-process]

The UI runs headless (Textual's test driver, 120x40) on the embedded simulated device at full
speed and prints the same small part ``--prints`` times, keys only (s, y). By default, as
``cdprhost tui`` does, the UI is a client of the printer service (the print, the link and
the device in the service's own process, started for this run in a folder of its own): the
service's RSS is read too, and its growth per print reported. ``--in-process`` measures the
UI driving the device itself (``cdprhost tui --in-process``). After each print
(and a settle), Python's traced memory (tracemalloc) and the process RSS are read. Reported:
both per print, the growth per print from print ``--since`` to the last (least-squares
slope), and the allocation sites (``--frames`` > 1: whole tracebacks) that grew most over
that span (from the print before it: what accumulates, if anything). Only the two snapshots
compared are taken, the first before the span and on disk until the end: snapshots held in
memory (one of every print, before) grew the RSS by megabytes per print themselves, and even
a freed one leaves a few MB of RSS behind (fragmented arenas).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import ctypes
import gc
import os
import signal
import sys
import tempfile
import tracemalloc
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def widget_counts() -> dict[str, int]:
    """Live Textual widgets (and screens) by class name."""
    from textual.widget import Widget

    out: dict[str, int] = {}
    for obj in gc.get_objects():
        if isinstance(obj, Widget):
            name = type(obj).__name__
            out[name] = out.get(name, 0) + 1
    return out


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def rss_of_mb(pid: int | None) -> float:
    """The RSS of another process (the printer service), NaN when unknown."""
    if pid is None:
        return float("nan")
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return float("nan")
    for line in text.splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def service_pid() -> int | None:
    """The pid of the embedded device's printer service of this run."""
    from cdprhost.service.client import embedded_files

    return embedded_files().read_pid()


def slope(xs: list[float], ys: list[float]) -> float:
    """Least-squares growth of ``ys`` per unit of ``xs``."""
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    den = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / den if den else 0.0


async def run(
    prints: int,
    layers: int,
    top: int,
    trim: bool = False,
    since: int = 4,
    frames: int = 1,
    in_process: bool = False,
) -> None:
    from cdprhost.job.state import JobState
    from cdprhost.tui.app import CdprApp
    from cdprhost.tui.control.live import LiveBackend
    from cdprhost.tui.screens.dialogs import ConfirmScreen
    from tests.tui.parts import small_part

    work = Path(tempfile.mkdtemp(prefix="tui-memory-"))
    part = work / "part.gcode"
    part.write_text(small_part(layers=layers), encoding="utf-8")
    backend: Any
    if in_process:
        backend = LiveBackend(
            "paper-prototype",
            speedup=None,
            job_options={"resume_dir": work / "resume", "log_path": work / "job.jsonl"},
        )
    else:  # a service of this run's own (its folder, its job logs)
        from cdprhost.tui.control.service_backend import ServiceBackend

        os.environ["CDPRHOST_RUN"] = str(work / "run")
        os.environ["CDPRHOST_STATE"] = str(work / "cdprhost-state")
        backend = ServiceBackend("paper-prototype", speedup=None)
    print(
        "the UI "
        + (
            "drives the device itself (--in-process)"
            if in_process
            else "is a client of the printer service (the default)"
        ),
        flush=True,
    )
    app = CdprApp(backend, open_file=str(part), state_folder=work / "state", status_interval_s=1.0)

    async def until(pred: Callable[[], object], timeout: float = 300.0) -> None:
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        while not pred():
            if loop.time() > end:
                notes = "; ".join(str(n.message) for n in app._notifications)
                raise SystemExit(
                    f"timed out; state {app.state.job.state} {app.state.job.reason} "
                    f"busy {app.state.busy!r} connected {app.state.connected} job {app.state.job_id} "
                    f"history {len(app.state.history)}; notes: {notes}"
                )
            await pilot.pause(0.05)

    def ended(n: int) -> bool:
        s = app.state
        return s.job_id == n and s.job.state.finished and not s.busy and len(s.history) >= n

    rows: list[tuple[int, float, float, float]] = []
    pid: int | None = None
    counts: dict[int, dict[str, int]] = {}
    snaps: dict[int, tracemalloc.Snapshot] = {}
    since = min(max(since, 2), max(prints - 1, 2))
    first = since - 1  # the first snapshot: before the span, so what it leaves is not growth
    async with app.run_test(size=(120, 40)) as pilot:
        await until(lambda: app.state.connected and app.state.file.preflight is not None)
        tracemalloc.start(frames)
        for n in range(1, prints + 1):
            await pilot.press("s")
            await until(lambda: isinstance(app.screen, ConfirmScreen))
            await pilot.press("y")
            await until(partial(ended, n))
            await pilot.pause(1.5)  # the device read again, the screen drawn
            assert app.state.job.state is JobState.DONE, app.state.job.reason
            gc.collect()
            if trim:
                ctypes.CDLL("libc.so.6").malloc_trim(0)
            current, _ = tracemalloc.get_traced_memory()
            if not in_process and pid is None:
                pid = service_pid()
            rows.append((n, current / 2**20, rss_mb(), rss_of_mb(pid)))
            served = "" if in_process else f"  service rss {rows[-1][3]:7.1f} MB"
            print(
                f"print {n}: traced {rows[-1][1]:7.2f} MB  rss {rows[-1][2]:7.1f} MB{served}",
                flush=True,
            )
            if n == first:  # on disk until the end: held, it would add to every later RSS
                snapshot = tracemalloc.take_snapshot()
                snapshot.dump(str(work / "first.snapshot"))
                del snapshot
            elif n == prints:
                snaps[n] = tracemalloc.take_snapshot()
                snaps[first] = tracemalloc.Snapshot.load(str(work / "first.snapshot"))
            counts[n] = widget_counts()
    if pid is not None:  # the run's own service: it would idle on for half a minute
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGTERM)
    span = [r for r in rows if r[0] >= since]
    if len(span) >= 2:
        xs = [float(r[0]) for r in span]
        traced, rss = slope(xs, [r[1] for r in span]), slope(xs, [r[2] for r in span])
        served = ""
        if not in_process:
            served = f", service rss {slope(xs, [r[3] for r in span]):+.2f} MB"
        print(
            f"growth per print (print {since} -> {rows[-1][0]}, least squares): "
            f"traced {traced:+.3f} MB, rss {rss:+.2f} MB{served}"
        )
        grown = {
            k: v - counts[since].get(k, 0)
            for k, v in counts[rows[-1][0]].items()
            if v > counts[since].get(k, 0)
        }
        print("live widgets that grew:", grown or "none")
        key = "traceback" if frames > 1 else "lineno"
        stats = snaps[prints].compare_to(snaps[first], key)
        print(f"largest growth by allocation site (print {first} -> {prints}):")
        for stat in stats[:top]:
            print(f"  {stat.size_diff / 1024:+9.1f} KiB  {stat.traceback[0]}")
            for frame in list(stat.traceback)[1:frames]:
                print(f"                 {frame}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--prints", type=int, default=8)
    parser.add_argument("--since", type=int, default=4, help="growth from this print on")
    parser.add_argument("--frames", type=int, default=1, help="traceback depth of the sites")
    parser.add_argument("--layers", type=int, default=10)
    parser.add_argument("--top", type=int, default=8)
    parser.add_argument("--trim", action="store_true", help="malloc_trim(0) after each print")
    parser.add_argument(
        "--in-process", action="store_true", help="the UI drives the device (no printer service)"
    )
    args = parser.parse_args()
    asyncio.run(
        run(
            args.prints,
            args.layers,
            args.top,
            args.trim,
            args.since,
            args.frames,
            args.in_process,
        )
    )


if __name__ == "__main__":
    main()
