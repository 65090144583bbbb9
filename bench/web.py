"""Web page (issue 33): status latency in the browser, the server's CPU with browsers watching.

    python bench/web.py [--browsers 3] [--window 20] [--speedup 1] [--shots /tmp/web-shots]
    python bench/web.py --gcode ../shared/fixtures/part-prusaslicer.gcode --speedup 20 \
        --window 5 --shots /tmp/web-shots      # screenshots of a real sliced part

A print server on 127.0.0.1 with the embedded simulated device paced at ``--speedup`` x real
time (1: a print at 1x), a small part printing; Debian's chromium (headless, Playwright)
opens the page ``--browsers`` times with the key. Figures:

- the server thread's CPU (uvicorn's event loop, where the pages' event stream is built and
  sent; read from /proc/self/task/TID/stat) over ``--window`` s with no browser watching
  (the baseline, same print) and with the browsers watching, as % of one core;
- the status latency: the job is paused and resumed by the API N times; each state's time in
  the printer's event (wall clock) against the time each page rendered it (``cdpr.seen``);
- screenshots during the print: desktop 1280x800 and phone 390x844 in ``--shots``.
Wall-clock figures: noisy on a loaded machine.
"""

from __future__ import annotations

import argparse
import http.client
import os
import shutil
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

ARGS = ["--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
        "--disable-background-networking", "--disable-component-update", "--no-first-run",
        "--disable-sync"]  # fmt: skip


def part(layers: int, side: float = 20.0) -> str:
    """A square part without heating waits (M104/M140 set, not awaited: it prints at once)."""
    lines = ["G28", "M140 S40", "M104 S200", "G92 E0"]
    e = 0.0
    for n in range(layers):
        lines += [";LAYER_CHANGE", f"G1 Z{0.3 * (n + 1):.2f} F3000"]
        for x, y in [(side, 0), (side, side), (0, side), (0, 0)]:
            e += 1.0
            lines.append(f"G1 X{x:g} Y{y:g} E{e:.3f} F1800")
    return "\n".join([*lines, "M104 S0", "M140 S0", ""])


def thread_cpu_s(native_id: int) -> float:
    fields = Path(f"/proc/self/task/{native_id}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def post(port: int, key: str, path: str, body: bytes, kind: str) -> int:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    try:
        conn.request("POST", path, body, {"X-Api-Key": key, "Content-Type": kind})
        reply = conn.getresponse()
        reply.read()
        return reply.status
    finally:
        conn.close()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--browsers", type=int, default=3)
    parser.add_argument("--window", type=float, default=20.0, help="CPU window, s")
    parser.add_argument("--speedup", type=float, default=1.0)
    parser.add_argument("--pauses", type=int, default=3)
    parser.add_argument("--shots", default="/tmp/web-shots")
    parser.add_argument(
        "--gcode", help="print this file (default: a square part without heating waits)"
    )
    parser.add_argument(
        "--service",
        action="store_true",
        help="as `cdprhost serve` runs: the print in a printer service process, the server "
        "its client (latency then counted from the server's receipt of the event)",
    )
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench-web-"))
    os.environ["XDG_CONFIG_HOME"] = str(tmp / "cfg")
    os.environ["CDPRHOST_STATE"] = str(tmp / "state")
    from playwright.sync_api import sync_playwright

    from cdprhost.job.state import StateChanged
    from cdprhost.profile import load_profile
    from cdprhost.server.apikey import KeyFile
    from cdprhost.server.app import create_app
    from cdprhost.server.headless import HeadlessPrinter
    from cdprhost.server.listen import ServerThread
    from cdprhost.server.uploads import UploadFolder
    from cdprhost.sim.embedded import open_embedded
    from tests.server.conftest import multipart

    reached: list[tuple[str, float]] = []

    def on_event(event: Any) -> None:
        if isinstance(event, StateChanged):
            reached.append((event.state.value, time.time()))

    printer: Any
    if args.service:
        from cdprhost.server.service_printer import ServicePrinter

        os.environ["CDPRHOST_RUN"] = tempfile.mkdtemp(prefix="bw-", dir="/tmp")
        printer = ServicePrinter(
            load_profile("paper-prototype"), speedup=args.speedup, on_event=on_event
        )
        printer.connect()
    else:
        printer = HeadlessPrinter(
            load_profile("paper-prototype"), lambda: open_embedded(speedup=args.speedup),
            on_event=on_event,
        )  # fmt: skip
    keys = KeyFile()
    app = create_app(printer, UploadFolder(tmp / "up"), keys.current, max_upload_bytes=10**8)
    server = ServerThread(app, "127.0.0.1", 0)
    server.start()
    tid = server.thread.native_id
    assert tid is not None
    layers = int(3 * (args.window * 2 + 30) * args.speedup) // 2 + 4  # ~2.7 s a layer at 1x
    data = Path(args.gcode).read_bytes() if args.gcode else part(layers).encode()
    name = Path(args.gcode).name if args.gcode else "bench_part.gcode"
    body, kind = multipart([("print", "true")], (name, data))
    pw = sync_playwright().start()
    browser = pw.chromium.launch(
        executable_path=shutil.which("chromium") or "/usr/bin/chromium", headless=True, args=ARGS
    )
    try:
        assert post(server.port, keys.key, "/api/files/local", body, kind) == 201
        for _ in range(6000):  # bounded: 300 s (a sliced file heats first)
            if printer.status().job.state.value == "printing":
                break
            time.sleep(0.05)
        time.sleep(1.0)
        c0 = thread_cpu_s(tid)
        time.sleep(args.window)
        base = (thread_cpu_s(tid) - c0) / args.window
        pages = []
        for n in range(args.browsers):
            phone = n == 1
            ctx = browser.new_context(
                viewport={"width": 390, "height": 844} if phone else {"width": 1280, "height": 800},
                device_scale_factor=2 if phone else 1, is_mobile=phone, has_touch=phone,
                bypass_csp=True,
            )  # fmt: skip
            pg = ctx.new_page()
            pg.goto(server.url + "/")
            pg.fill("#key", keys.key)
            pg.click("#key-form button[type=submit]")
            pg.wait_for_function("window.cdpr.layer !== null && window.cdpr.doc.graph.length > 1")
            pages.append(pg)
        time.sleep(1.0)
        c0, w0 = thread_cpu_s(tid), time.monotonic()
        time.sleep(args.window)
        watched = (thread_cpu_s(tid) - c0) / (time.monotonic() - w0)
        shots = Path(args.shots)
        shots.mkdir(parents=True, exist_ok=True)
        pages[0].screenshot(path=str(shots / "desktop-1280x800.png"))
        if len(pages) > 1:
            pages[1].screenshot(path=str(shots / "phone-390x844.png"))
            pages[1].screenshot(path=str(shots / "phone-390-full.png"), full_page=True)
        lat: list[float] = []
        for _ in range(args.pauses):
            for action, state in (("pause", "paused"), ("resume", "printing")):
                mark = len(reached)
                done = threading.Event()
                payload = f'{{"command": "pause", "action": "{action}"}}'.encode()
                assert post(server.port, keys.key, "/api/job", payload, "application/json") == 204
                end = time.monotonic() + 30
                while time.monotonic() < end and not done.is_set():
                    if any(s == state for s, _ in reached[mark:]):
                        done.set()
                    time.sleep(0.01)
                t_dev = next(t for s, t in reached[mark:] if s == state)
                for pg in pages:
                    pg.wait_for_function(
                        f"window.cdpr.doc.state === '{state}' && window.cdpr.seen['{state}'] >= {t_dev * 1000 - 5}"
                    )
                    lat.append(pg.evaluate(f"window.cdpr.seen['{state}']") / 1000.0 - t_dev)
                time.sleep(0.5)
    finally:
        browser.close()
        pw.stop()
        printer.shutdown("bench over", timeout_s=30)
        server.stop()
    where = " (the print in a printer service)" if args.service else ""
    print(
        f"server thread CPU{where}, print at {args.speedup:g}x, no browser: "
        f"{100 * base:.2f} % of a core"
    )
    print(f"  with {args.browsers} browsers watching: {100 * watched:.2f} % of a core "
          f"(+{100 * (watched - base):.2f} points; ratio {watched / max(base, 1e-4):.1f}x)")  # fmt: skip
    print(f"status latency in the browser ({len(lat)} state changes x pages): "
          f"median {1000 * statistics.median(lat):.0f} ms, max {1000 * max(lat):.0f} ms")  # fmt: skip
    print(
        f"screenshots in {args.shots}: desktop-1280x800.png, phone-390x844.png, phone-390-full.png"
    )


if __name__ == "__main__":
    main()
