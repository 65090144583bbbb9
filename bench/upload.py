"""Slicer upload API (issue 22): from "upload and print" to the first executed segment.

    python bench/upload.py [--runs N] [--speedup X]

A print server on 127.0.0.1 (ephemeral port) with the embedded simulated device; PrusaSlicer's
exact upload request (the example cup, print=true) is sent over loopback N times, one print
at a time (each cancelled once its first segment has run). Wall-clock seconds, so noisy on a
loaded machine: the reply (stored and preflighted), the job printing (its own preflight,
connect, device checks), and the first segment executed by the device (after G28 and the
heating waits, which run on the device's virtual clock: ``--speedup`` paces it). Then one
store-only upload of ``--store-mb`` MB (PrusaSlicer's request with Expect: 100-continue).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.server.test_slicer_clients import EXAMPLE, prusaslicer_requests, raw_exchange  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--speedup", type=float, default=None)
    parser.add_argument("--store-mb", type=float, default=50.0, help="store-only upload size")
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench-upload-"))
    os.environ["XDG_CONFIG_HOME"] = str(tmp / "cfg")
    os.environ["CDPRHOST_STATE"] = str(tmp / "state")
    from cdprhost.profile import load_profile
    from cdprhost.server.apikey import KeyFile
    from cdprhost.server.app import create_app
    from cdprhost.server.headless import HeadlessPrinter
    from cdprhost.server.listen import ServerThread
    from cdprhost.server.uploads import UploadFolder
    from cdprhost.sim.embedded import open_embedded

    links: list = []

    def open_device():
        links.append(open_embedded(speedup=args.speedup))
        return links[-1]

    printer = HeadlessPrinter(load_profile("paper-prototype"), open_device)
    keys = KeyFile()
    app = create_app(printer, UploadFolder(tmp / "up"), keys.current, max_upload_bytes=10**8)
    server = ServerThread(app, "127.0.0.1", 0)
    server.start()
    data = EXAMPLE.read_bytes()
    rows = []
    try:
        for n in range(args.runs):
            _, upload = prusaslicer_requests(server.port, keys.key, f"cup{n}.gcode", data, True)
            done = len(links[-1].device.record) if links else 0
            t0 = time.perf_counter()
            status, body = raw_exchange(server.port, upload)
            t_reply = time.perf_counter() - t0
            assert status == 201, body
            t_printing = t_first = None
            for _ in range(600_000):  # bounded: 10 min of 1 ms polls at most
                if t_printing is None and printer.status().job.state.value in (
                    "printing",
                    "heating",
                ):
                    t_printing = time.perf_counter() - t0
                if links and len(links[-1].device.record) > done:
                    t_first = time.perf_counter() - t0
                    break
                time.sleep(0.001)
            printer.cancel()
            printer.wait_idle(120)
            rows.append((t_reply, t_printing, t_first))
            print(
                f"run {n}: reply {t_reply:.3f} s, printing {t_printing:.3f} s, first segment {t_first:.3f} s"
            )
        big = data + b";" + b"p" * int(args.store_mb * 1e6) + b"\n"
        _, upload = prusaslicer_requests(server.port, keys.key, "big.gcode", big, False)
        t0 = time.perf_counter()
        status, body = raw_exchange(server.port, upload, expect_continue=b"Expect:" in upload)
        t_store = time.perf_counter() - t0
        assert status == 201, body
        print(
            f"store only: {len(big) / 1e6:.1f} MB in {t_store:.2f} s ({len(big) / 1e6 / t_store:.0f} MB/s)"
        )
    finally:
        printer.shutdown("bench over")
        server.stop()
    for i, what in enumerate(("reply (stored + preflight)", "job printing", "first segment")):
        print(f"median {what}: {statistics.median(r[i] for r in rows):.3f} s")
    print(f"file: {EXAMPLE.name}, {len(data)} bytes; speedup {args.speedup or 'unpaced'}")


if __name__ == "__main__":
    main()
