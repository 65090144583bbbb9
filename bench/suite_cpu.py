"""Where the test suite's time goes: each test's wall time against the CPU it used.

    python bench/suite_cpu.py [--workers 2] [--top 25] [PYTEST ARGS...]
    python bench/suite_cpu.py --summarise FOLDER      (a run's files again)

Runs the suite (or the paths given) under pytest-xdist with this file as a plugin: each
worker writes, for every test, its wall time and the CPU time of the worker process and
of the children it reaped (a ``sim-device``, simavr, a CLI run as a subprocess) to a JSON
lines file. The summary gives, by test folder and for the slowest tests, wall, CPU and
their ratio. The baseline is the wall time itself: a CPU/wall ratio well under 1 means
the test mostly waits (devices paced in real time, watchdogs, a browser), so a worker
beside it can use the core; a ratio near 1 is CPU-bound. Children a test leaves to others
(a service's daemon, a browser's helpers) are not counted: their tests look idler than
they are.

The figures behind CI's worker count (``.ci/run``) came from this (2 cores, 2026-12-02):
``-n 2``: 2,337 s of worker wall, 1,525 s of CPU counted (0.65), the run 1,188 s; ``-n 3``:
2,575 s of worker wall, 1,389 s of CPU (0.54), the run 909 s (0.77 of ``-n 2``'s), but each
of three ``-n 3`` runs failed one real-time test (a starved host ran past its lead), so CI
keeps two workers.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

OUT_ENV = "SUITE_CPU_DIR"


def _cpu() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


try:  # the plugin half: loaded into each pytest worker with ``-p suite_cpu``
    import pytest

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
        folder = os.environ.get(OUT_ENV)
        w0, (s0, c0) = time.monotonic(), _cpu()
        yield
        if not folder:
            return
        w1, (s1, c1) = time.monotonic(), _cpu()
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        row = {"id": item.nodeid, "wall": w1 - w0, "own": s1 - s0, "children": c1 - c0}
        with open(Path(folder) / f"{worker}.jsonl", "a") as f:
            f.write(json.dumps(row) + "\n")

except ImportError:  # pragma: no cover - the summary needs no pytest
    pass


def summarise(folder: Path, top: int) -> str:
    rows = [json.loads(x) for f in sorted(folder.glob("*.jsonl")) for x in f.open() if x.strip()]
    if not rows:
        return f"no figures in {folder}"
    lines = []
    wall = sum(r["wall"] for r in rows)
    cpu = sum(r["own"] + r["children"] for r in rows)
    lines.append(f"{len(rows)} tests: worker wall {wall:.0f} s, CPU {cpu:.0f} s ({cpu / wall:.2f})")
    by = collections.defaultdict(lambda: [0.0, 0.0])
    for r in rows:
        parts = r["id"].split("::")[0].split("/")
        key = "/".join(parts[:2]) if len(parts) > 2 else parts[-1]
        by[key][0] += r["wall"]
        by[key][1] += r["own"] + r["children"]
    lines.append(f"{'folder':32s} {'wall s':>8s} {'CPU s':>8s} {'CPU/wall':>8s}")
    for key, (w, c) in sorted(by.items(), key=lambda kv: -kv[1][0]):
        lines.append(f"{key:32s} {w:8.1f} {c:8.1f} {c / w if w else 0:8.2f}")
    lines.append(f"the {top} longest tests:")
    for r in sorted(rows, key=lambda r: -r["wall"])[:top]:
        c = r["own"] + r["children"]
        lines.append(
            f"{r['wall']:7.1f} {c:7.1f} {c / r['wall'] if r['wall'] else 0:5.2f}  {r['id']}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--summarise", type=Path, help="summarise a run's folder instead")
    args, pytest_args = ap.parse_known_args(argv)
    if args.summarise:
        print(summarise(args.summarise, args.top))
        return 0
    folder = Path(tempfile.mkdtemp(prefix="suite-cpu-"))
    here = Path(__file__).resolve().parent
    env = {**os.environ, OUT_ENV: str(folder)}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(here), env.get("PYTHONPATH")]))
    cmd = [sys.executable, "-m", "pytest", "-p", "suite_cpu", "-n", str(args.workers), "-q"]
    t0 = time.monotonic()
    rc = subprocess.call([*cmd, *pytest_args], env=env)
    print(
        f"pytest -n {args.workers}: exit {rc}, {time.monotonic() - t0:.0f} s; figures in {folder}"
    )
    print(summarise(folder, args.top))
    return rc


if __name__ == "__main__":
    sys.exit(main())
