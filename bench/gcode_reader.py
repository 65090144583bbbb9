"""G-code reader throughput: cdprhost.gcode.read_program vs gcodeparser and pygcode (parse only).

Run: python bench/gcode_reader.py [--file F] [--times 10] [--repeats 5]
Reads the fixture (128k lines) and the fixture concatenated ``--times`` times, and
prints lines/s of each parser measured in the same run (best of ``--repeats``,
wall clock and process CPU time), the ratios, and the reader's peak RSS on the
long file (a child process). Needs ``pip install gcodeparser pygcode`` for the
comparisons (skipped when missing). The reader is timed consuming every item;
gcodeparser is timed on ``parse_gcode_lines`` (list of parsed lines); pygcode on
``Line(text)`` for every line (a 20k-line sample: it is slow).
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_inputs import gcode_fixture

REPO = Path(__file__).resolve().parents[1]


def timed(fn, repeats: int) -> tuple[float, float]:
    """Best wall and best CPU seconds of ``fn()`` over ``repeats`` runs."""
    wall = cpu = float("inf")
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - w)
        cpu = min(cpu, time.process_time() - c)
    return wall, cpu


def run_reader(path: str) -> int:
    from cdprhost.gcode import read_program

    n = 0
    for _ in read_program(path):
        n += 1
    return n


def run_gcodeparser(text: str) -> int:
    from gcodeparser import parse_gcode_lines

    return sum(1 for _ in parse_gcode_lines(text, include_comments=False))


def run_pygcode(lines: list[str]) -> int:
    from pygcode import Line

    return sum(len(Line(line).block.gcodes) for line in lines)


def child_peak_rss_mb(path: str) -> float:
    """Peak RSS (MB) of a fresh process that imports the reader and reads ``path``."""
    code = (
        "import resource, sys\n"
        "from cdprhost.gcode import read_program\n"
        "base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "for _ in read_program(sys.argv[1]): pass\n"
        "print(base, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, path], capture_output=True, text=True, check=True
    ).stdout.split()
    return int(out[1]) / 1024.0


def available(module: str) -> bool:
    try:
        __import__(module)
    except ImportError:
        return False
    return True


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--file", help="G-code to read (default: the team's fixture, else the example)")
    ap.add_argument(
        "--times", type=int, default=10, help="concatenation factor of the long file (default 10)"
    )
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    args.file = str(gcode_fixture(Path(args.file) if args.file else None))
    text = Path(args.file).read_text(encoding="utf-8")
    n_lines = text.count("\n")
    with tempfile.TemporaryDirectory() as tmp:
        long_path = os.path.join(tmp, "long.gcode")
        with open(long_path, "w", encoding="utf-8") as fh:
            for _ in range(args.times):
                fh.write(text)
        print(
            f"file: {args.file} ({n_lines} lines); long file: x{args.times} ({n_lines * args.times} lines)"
        )
        print(f"{'parser':34s} {'lines':>9s} {'wall s':>8s} {'lines/s':>11s} {'cpu lines/s':>12s}")
        rates: dict[str, float] = {}

        def report(name: str, lines: int, wall: float, cpu: float) -> None:
            rates[name] = lines / wall
            print(f"{name:34s} {lines:9d} {wall:8.3f} {lines / wall:11.0f} {lines / cpu:12.0f}")

        report(
            "cdprhost read_program", n_lines, *timed(lambda: run_reader(args.file), args.repeats)
        )
        report(
            f"cdprhost read_program x{args.times}",
            n_lines * args.times,
            *timed(lambda: run_reader(long_path), max(1, args.repeats // 2)),
        )
        if available("gcodeparser"):
            gp = timed(lambda: run_gcodeparser(text), max(1, args.repeats // 2))
            report("gcodeparser parse_gcode_lines", n_lines, *gp)
        if available("pygcode"):
            sample = text.splitlines()[:20000]
            report(
                "pygcode Line() (20k-line sample)",
                len(sample),
                *timed(lambda: run_pygcode(sample), 1),
            )
        base = rates["cdprhost read_program"]
        for other in ("gcodeparser parse_gcode_lines", "pygcode Line() (20k-line sample)"):
            if other in rates:
                print(f"read_program / {other}: {base / rates[other]:.1f}x")
        print(
            f"peak RSS reading the x{args.times} file: {child_peak_rss_mb(long_path):.0f} MB "
            f"(this process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
