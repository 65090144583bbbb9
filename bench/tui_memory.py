"""Memory of the terminal UI over repeated prints: it must stay flat (issue 23: 143 -> 253 MB).

Run: python bench/tui_memory.py [--prints 8] [--layers 10] [--top 8]

The UI runs headless (Textual's test driver, 120x40) on the embedded simulated device at full
speed and prints the same small part ``--prints`` times, keys only (s, y). After each print
(and a settle), Python's traced memory (tracemalloc) and the process RSS are read. Reported:
both per print, the growth from the second print to the last per print, and the allocation
sites that grew most over that span (what accumulates, if anything).
"""

from __future__ import annotations

import argparse
import asyncio
import ctypes
import gc
import sys
import tempfile
import tracemalloc
from collections.abc import Callable
from functools import partial
from pathlib import Path

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


async def run(prints: int, layers: int, top: int, trim: bool = False) -> None:
    from cdprhost.job.state import JobState
    from cdprhost.tui.app import CdprApp
    from cdprhost.tui.control.live import LiveBackend
    from cdprhost.tui.screens.dialogs import ConfirmScreen
    from tests.tui.parts import small_part

    work = Path(tempfile.mkdtemp(prefix="tui-memory-"))
    part = work / "part.gcode"
    part.write_text(small_part(layers=layers), encoding="utf-8")
    backend = LiveBackend(
        "paper-prototype",
        speedup=None,
        job_options={"resume_dir": work / "resume", "log_path": work / "job.jsonl"},
    )
    app = CdprApp(backend, open_file=str(part), state_folder=work / "state", status_interval_s=1.0)

    async def until(pred: Callable[[], object], timeout: float = 300.0) -> None:
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        while not pred():
            if loop.time() > end:
                raise SystemExit(f"timed out; state {app.state.job.state}")
            await pilot.pause(0.05)

    def ended(n: int) -> bool:
        s = app.state
        return s.job_id == n and s.job.state.finished and not s.busy and len(s.history) >= n

    rows: list[tuple[int, float, float]] = []
    counts: dict[int, dict[str, int]] = {}
    snaps = []
    async with app.run_test(size=(120, 40)) as pilot:
        await until(lambda: app.state.connected and app.state.file.preflight is not None)
        tracemalloc.start(1)
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
            rows.append((n, current / 2**20, rss_mb()))
            snaps.append(tracemalloc.take_snapshot())
            print(
                f"print {n}: traced {current / 2**20:7.2f} MB  rss {rss_mb():7.1f} MB", flush=True
            )
            counts[n] = widget_counts()
    if len(rows) >= 3:
        span = rows[-1][0] - rows[1][0]
        traced = (rows[-1][1] - rows[1][1]) / span
        rss = (rows[-1][2] - rows[1][2]) / span
        print(
            f"growth per print (print 2 -> {rows[-1][0]}): traced {traced:+.3f} MB, rss {rss:+.2f} MB"
        )
        grown = {
            k: v - counts[rows[1][0]].get(k, 0)
            for k, v in counts[rows[-1][0]].items()
            if v > counts[rows[1][0]].get(k, 0)
        }
        print("live widgets that grew:", grown or "none")
        stats = snaps[-1].compare_to(snaps[1], "lineno")
        print("largest growth by allocation site:")
        for stat in stats[:top]:
            print(f"  {stat.size_diff / 1024:+9.1f} KiB  {stat.traceback[0]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--prints", type=int, default=8)
    parser.add_argument("--layers", type=int, default=10)
    parser.add_argument("--top", type=int, default=8)
    parser.add_argument("--trim", action="store_true", help="malloc_trim(0) after each print")
    args = parser.parse_args()
    asyncio.run(run(args.prints, args.layers, args.top, args.trim))


if __name__ == "__main__":
    main()
