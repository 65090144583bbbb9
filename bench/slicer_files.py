"""Checking real slicer files and absurd ones: cost per 1000 lines against the fixture.

Run: python bench/slicer_files.py [--fixture FILE] [--profile P]

In one run, each case in a fresh subprocess (so peak memory is its own):
- the baseline: ``check`` of the team's fixture (PrusaSlicer, 128k lines);
- ``check --retarget`` of every file of tests/gcode/data/thirdparty (and ``--center``
  for the arc boat);
- absurd inputs: 20,000 lines of moves to +-1e9 mm, 20,000 arcs of radius 1-100 m,
  single moves to X1e7, X1e8, X99999999999, X1e20.
Reports seconds (and per 1000 lines as a ratio to the fixture's: small files are
dominated by fixed costs such as the workspace certificate), peak memory (VmHWM) next
to the interpreter-plus-imports baseline, and for the slicer files our filament and
time against the figures in their headers. Target: no input above a few seconds per
1000 lines or a few hundred MB.
"""

from __future__ import annotations

import argparse
import json
import random
import subprocess
import sys
import tempfile
from pathlib import Path

from bench_inputs import gcode_fixture

REPO = Path(__file__).resolve().parents[1]
CORPUS = REPO / "tests" / "gcode" / "data" / "thirdparty"

_CHILD = r"""
import json, sys, time
from cdprhost.profile import load_profile
from cdprhost.kinematics import MachineModel
from cdprhost.motion.prepared import Setup
from cdprhost.preflight import preflight
path, profile_name, center, retarget = sys.argv[1], sys.argv[2], sys.argv[3] == "1", sys.argv[4] == "1"
profile = load_profile(profile_name)
model = MachineModel.from_profile(profile)
def hwm():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM"):
            return int(line.split()[1]) / 1024
base = hwm()
t0 = time.perf_counter()
try:
    r = preflight(path, profile, model, setup=Setup(center=center, retarget=retarget))
    out = {"ok": r.ok, "violations": r.violations_total, "filament": r.filament_mm,
           "time": r.estimated_time_s,
           "slicer_filament": r.slicer.filament_mm if r.slicer else None,
           "slicer_time": r.slicer.time_s if r.slicer else None}
except Exception as exc:  # an input error is a result too
    out = {"error": f"{type(exc).__name__}: {exc}"[:120]}
out["seconds"] = time.perf_counter() - t0
out["peak_mb"], out["base_mb"] = hwm(), base
print(json.dumps(out))
"""


def lines_of(path: Path) -> int:
    with open(path, "rb") as fh:
        return sum(block.count(b"\n") for block in iter(lambda: fh.read(1 << 20), b"")) or 1


def run(path: Path, profile: str, center: bool = False, retarget: bool = False) -> dict:
    cmd = [sys.executable, "-c", _CHILD, str(path), profile, str(int(center)), str(int(retarget))]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def absurd_files(folder: Path) -> list[Path]:
    r = random.Random(1)
    start = "M104 S200\nM109 S200\nG28\nG1 Z5 F600\nG1 X10 Y10 E1 F1200\n"
    files = []
    p = folder / "absurd_moves_20k.gcode"
    p.write_text(
        start
        + "".join(
            f"G1 X{r.uniform(-1e9, 1e9):.1f} Y{r.uniform(-1e9, 1e9):.1f} E{i} F3000\n"
            for i in range(20000)
        )
    )
    files.append(p)
    p = folder / "absurd_arcs_20k.gcode"
    p.write_text(
        start
        + "".join(f"G1 X0 Y0\nG2 X0 Y0 I{r.uniform(1e3, 1e5):.1f} J0 E{i}\n" for i in range(10000))
    )
    files.append(p)
    for x in ("10000000", "100000000", "99999999999", "1" + "0" * 20):
        p = folder / f"typo_X{x[:12]}.gcode"
        p.write_text(start + f"G1 X{x} E2\nG1 X20 Y20 E3\n")
        files.append(p)
    return files


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--fixture", type=Path, help="default: the team's fixture, else examples/example.gcode"
    )
    ap.add_argument("--profile", default="paper-prototype")
    args = ap.parse_args()
    args.fixture = gcode_fixture(args.fixture)
    base = run(args.fixture, args.profile)
    base_per_k = base["seconds"] / lines_of(args.fixture) * 1000
    print(
        f"baseline: check of {args.fixture.name}: {base['seconds']:.2f} s "
        f"({base_per_k * 1000:.2f} ms per 1000 lines), peak {base['peak_mb']:.0f} MB "
        f"(interpreter + imports {base['base_mb']:.0f} MB)"
    )
    print(f"{'case':<58} {'lines':>7} {'seconds':>8} {'per 1000 lines':>15} {'peak MB':>8}  result")
    cases = [(f, False, True) for f in sorted(CORPUS.glob("*.gcode"))]
    cases.append((CORPUS / "slic3r13_arcs_boat.gcode", True, False))
    with tempfile.TemporaryDirectory() as tmp:
        cases += [(f, False, False) for f in absurd_files(Path(tmp))]
        for path, center, retarget in cases:
            r = run(path, args.profile, center, retarget)
            per_k = r["seconds"] / lines_of(path) * 1000
            flag = " --center" if center else " --retarget" if retarget else ""
            if "error" in r:
                result = r["error"]
            else:
                result = f"ok={r['ok']} violations={r['violations']}"
                if r.get("slicer_filament"):
                    result += f" filament {100 * (r['filament'] / r['slicer_filament'] - 1):+.2f} %"
                if r.get("slicer_time"):
                    result += f" time {100 * (r['time'] / r['slicer_time'] - 1):+.1f} %"
            print(
                f"{path.name + flag:<58} {lines_of(path):>7} {r['seconds']:>8.2f} "
                f"{per_k / base_per_k:>13.2f} x {r['peak_mb']:>8.0f}  {result}"
            )


if __name__ == "__main__":
    main()
