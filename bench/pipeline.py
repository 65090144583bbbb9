"""Print pipeline throughput: preflight and parse+plan+IK+segment(+encode) vs parse-only baselines.

Run: python bench/pipeline.py [--fixture FILE] [--repeat 10] [--profile P]

On the fixture and on the fixture repeated ``--repeat`` times (written to a temp
dir), measured in the same run:
- ``gcodeparser`` and ``pygcode`` parse-only rates (the baselines; pygcode is slow,
  so it parses at most ``--pygcode-lines`` lines of each file);
- our reader alone, the preflight (``cdprhost check`` minus printing) and the full
  pipeline (reader, planner, IK, segments; plus the wire encoder when
  ``firmware_protocol`` is importable);
- peak memory (VmHWM) of preflight and pipeline on the big file, each in a
  fresh subprocess, next to the interpreter-plus-imports baseline.
Targets: preflight >= 5x gcodeparser's rate, full pipeline >= 3x, peak < 400 MB.
Install the baselines with ``pip install gcodeparser pygcode`` (bench extra).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_inputs import gcode_fixture

REPO = Path(__file__).resolve().parents[1]


def count_lines(path: Path) -> int:
    with open(path, "rb") as fh:
        return sum(block.count(b"\n") for block in iter(lambda: fh.read(1 << 20), b""))


def rate_of(fn, lines: int, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return lines / best


# ----------------------------------------------------------------- workloads
def gcodeparser_parse(path: Path) -> None:
    import gcodeparser

    text = path.read_text()
    if hasattr(gcodeparser, "parse_gcode_lines"):
        for _ in gcodeparser.parse_gcode_lines(text):
            pass
    else:  # older releases
        gcodeparser.GcodeParser(text)


def pygcode_parse(path: Path, max_lines: int) -> int:
    from pygcode import Line

    n = 0
    with open(path) as fh:
        for raw in itertools.islice(fh, max_lines):
            Line(raw.rstrip("\n"))
            n += 1
    return n


def reader_only(path: Path, profile, model) -> None:
    from cdprhost.motion.program import read_items

    for _ in read_items(path, profile, model):
        pass


def run_preflight(path: Path, profile, model):
    from cdprhost.preflight import preflight

    return preflight(path, profile, model)


def encoder():
    """The wire-encode hook: the protocol's vectorised segment encoder, when present."""
    try:
        from firmware_protocol.ramp_profile import ramp_codes_from_speeds
        from firmware_protocol.segments import SegmentBatch, SegmentContext, encode_segments
    except ImportError:
        return None
    ctx = SegmentContext()

    def encode(batch):
        wire = SegmentBatch(
            batch.ticks, batch.delta, ramp_codes_from_speeds(batch.v_start, batch.v_end)
        )
        return encode_segments(wire, ctx)[0]

    return encode


def run_pipeline(path: Path, profile, model, encode=None) -> dict:
    """Blocks of segments, each encoded at once (the job sends the bytes up to each command)."""
    from cdprhost.motion.pipeline import PipelineTotals, SegmentBlock, segment_blocks
    from cdprhost.motion.program import read_items

    totals = PipelineTotals()
    wire_bytes = 0
    for out in segment_blocks(
        read_items(path, profile, model), profile, model, encode=encode, totals=totals
    ):
        if isinstance(out, SegmentBlock) and out.encoded is not None:
            wire_bytes += len(out.encoded)
    return {
        "segments": totals.segments,
        "moves": totals.moves,
        "time_s": totals.planned_time_s,
        "wire_bytes": wire_bytes,
    }


# ----------------------------------------------------------------- memory (subprocess)
def peak_rss_mb() -> float:
    """This process's peak resident set (VmHWM; unlike ru_maxrss it does not inherit the parent's peak)."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def child(task: str, path: str, profile_name: str) -> None:
    from cdprhost.kinematics import MachineModel
    from cdprhost.profile import load_profile

    profile = load_profile(profile_name)
    model = MachineModel.from_profile(profile)
    if task == "preflight":
        run_preflight(Path(path), profile, model)
    elif task == "pipeline":
        run_pipeline(Path(path), profile, model, encoder())
    print(json.dumps({"maxrss_mb": peak_rss_mb()}))


def peak_mb(task: str, path: Path, profile_name: str) -> float:
    out = subprocess.run(
        [sys.executable, __file__, "--child", task, str(path), "--profile", profile_name],
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])["maxrss_mb"]


# ----------------------------------------------------------------- main
def bench_file(path: Path, profile, model, args) -> dict:
    """Every workload once per round, rounds interleaved; the best wall and CPU time of each."""
    lines = count_lines(path)
    rounds = args.rounds if lines < 500_000 else max(args.rounds - 1, 1)
    n_py = min(lines, args.pygcode_lines)
    enc = encoder()
    keep: dict = {}
    work = {
        "gcodeparser": (lines, lambda: gcodeparser_parse(path)),
        "pygcode": (n_py, lambda: pygcode_parse(path, n_py)),
        "reader": (lines, lambda: reader_only(path, profile, model)),
        "preflight": (lines, lambda: keep.update(report=run_preflight(path, profile, model))),
        "segments": (lines, lambda: run_pipeline(path, profile, model, None)),
        "pipeline": (lines, lambda: keep.update(run_pipeline(path, profile, model, enc))),
    }
    wall = {k: float("inf") for k in work}
    cpu = {k: float("inf") for k in work}
    for _ in range(rounds):
        for name, (_, fn) in work.items():
            w0, c0 = time.perf_counter(), time.process_time()
            fn()
            wall[name] = min(wall[name], time.perf_counter() - w0)
            cpu[name] = min(cpu[name], time.process_time() - c0)
    res = {
        "file": path.name,
        "lines": lines,
        "pygcode_lines": n_py,
        "encoded": enc is not None,
        "rounds": rounds,
    }
    res["wall"] = {k: work[k][0] / wall[k] for k in work}
    res["cpu"] = {k: work[k][0] / cpu[k] for k in work}
    res["estimated_time_s"] = keep["report"].estimated_time_s
    res["ok"] = keep["report"].ok
    res.update({f"pipeline_{k}": v for k, v in keep.items() if k != "report"})
    return res


def print_rates(results: list[dict], clock: str) -> None:
    print(f"{clock} time: lines/s, best of the rounds; x = rate / gcodeparser rate")
    print(
        f"{'file':<24}{'lines':>9}{'gcodeparser':>12}{'pygcode':>9}{'reader':>10}{'preflight':>10}{'x':>5}"
        f"{'segments':>10}{'x':>5}{'pipeline':>10}{'x':>5}"
    )
    for r in results:
        q = r[clock]
        g = q["gcodeparser"]
        print(
            f"{r['file']:<24}{r['lines']:>9}{g:>12.0f}{q['pygcode']:>9.0f}{q['reader']:>10.0f}"
            f"{q['preflight']:>10.0f}{q['preflight'] / g:>5.1f}{q['segments']:>10.0f}{q['segments'] / g:>5.1f}"
            f"{q['pipeline']:>10.0f}{q['pipeline'] / g:>5.1f}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--fixture", type=Path, help="default: the team's fixture, else examples/example.gcode"
    )
    ap.add_argument("--repeat", type=int, default=10, help="copies of the fixture in the big file")
    ap.add_argument("--profile", default="paper-simulation")
    ap.add_argument("--pygcode-lines", type=int, default=150_000)
    ap.add_argument(
        "--rounds", type=int, default=3, help="interleaved rounds (one fewer on the big file)"
    )
    ap.add_argument("--no-memory", action="store_true")
    ap.add_argument("--child", nargs=2, metavar=("TASK", "FILE"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child[0], args.child[1], args.profile)
        return

    import importlib.util

    from cdprhost.kinematics import MachineModel
    from cdprhost.profile import load_profile

    missing = [m for m in ("gcodeparser", "pygcode") if importlib.util.find_spec(m) is None]
    if missing:  # they are the baselines every figure is a ratio to
        raise SystemExit(
            f"bench/pipeline.py needs its baselines {' and '.join(missing)}: "
            "pip install -e '.[bench]'"
        )
    args.fixture = gcode_fixture(args.fixture)
    profile = load_profile(args.profile)
    model = MachineModel.from_profile(profile)
    with tempfile.TemporaryDirectory() as tmp:
        big = Path(tmp) / f"fixture-x{args.repeat}.gcode"
        data = args.fixture.read_bytes()
        with open(big, "wb") as fh:
            for _ in range(args.repeat):
                fh.write(data)
        results = [
            bench_file(args.fixture, profile, model, args),
            bench_file(big, profile, model, args),
        ]
        mem = {}
        if not args.no_memory:
            mem = {t: peak_mb(t, big, args.profile) for t in ("baseline", "preflight", "pipeline")}

    print(f"profile {args.profile}")
    print_rates(results, "wall")
    print_rates(results, "cpu")
    print(
        "targets: preflight >= 5x, pipeline >= 3x gcodeparser; segments = pipeline without the wire encoder"
    )
    for r in results:
        print(
            f"{r['file']}: preflight ok={r['ok']}, estimated {r['estimated_time_s']:.1f} s; pipeline "
            f"{r['pipeline_segments']} segments from {r['pipeline_moves']} moves"
            + (
                f", {r['pipeline_wire_bytes']} wire bytes"
                if r["encoded"]
                else " (no wire encoder found)"
            )
            + f"; pygcode over the first {r['pygcode_lines']} lines; {r['rounds']} rounds"
        )
    if mem:
        print(
            f"peak RSS on the big file: interpreter+imports {mem['baseline']:.0f} MB, preflight "
            f"{mem['preflight']:.0f} MB, pipeline {mem['pipeline']:.0f} MB (target < 400 MB)"
        )


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    main()
