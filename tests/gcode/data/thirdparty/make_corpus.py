"""Regenerate the third-party G-code corpus in this folder (see README.md).

Not a test: run by hand on a Debian machine with the slicers installed
(``apt-get install prusa-slicer slic3r cura-engine openscad``; Cura's printer
definitions come from the ``cura`` package: ``apt-get download cura`` and unpack
it, then pass ``--cura-resources .../usr/share/cura/resources``).

    python tests/gcode/data/thirdparty/make_corpus.py --cura-resources DIR

Every file is sliced for *another* printer with that printer's stock settings
(the slicer's own vendor presets), from the models in ``shapes.scad``; big ones
are cropped to their first layers (plus the last layer and the end block), with a
``G92 E`` where layers were cut out so the extrusion stays right. The label
post-processors turn PrusaSlicer 2.5's ``; printing object`` comments into M486
or Klipper EXCLUDE_OBJECT commands, as the common post-processing scripts do.
"""

from __future__ import annotations

import argparse
import configparser
import math
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
PRUSA_PROFILES = Path("/usr/share/PrusaSlicer/profiles")


# ---------------------------------------------------------------- models
def stl(shape: str, work: Path) -> Path:
    out = work / f"{shape}.stl"
    if not out.exists():
        subprocess.run(
            ["openscad", "-D", f'shape="{shape}"', "-o", str(out), str(HERE / "shapes.scad")],
            check=True,
            capture_output=True,
        )
    return out


# ------------------------------------------------------ PrusaSlicer presets
def _bundle(vendor: str) -> configparser.RawConfigParser:
    cp = configparser.RawConfigParser(strict=False, interpolation=None)
    cp.optionxform = str  # keep key case
    cp.read(PRUSA_PROFILES / f"{vendor}.ini", encoding="utf-8")
    return cp


def _flatten(cp: configparser.RawConfigParser, section: str) -> dict[str, str]:
    """A vendor preset with its ``inherits`` chain resolved (later parents win)."""
    values: dict[str, str] = {}
    own = dict(cp[section])
    parents = [p.strip() for p in own.pop("inherits", "").split(";") if p.strip()]
    kind = section.split(":", 1)[0]
    for parent in parents:
        values.update(_flatten(cp, f"{kind}:{parent}"))
    values.update(own)
    return values


def prusa_config(vendor: str, printer: str, print_: str, filament: str, **extra: str) -> str:
    cp = _bundle(vendor)
    merged: dict[str, str] = {}
    for section in (f"printer:{printer}", f"print:{print_}", f"filament:{filament}"):
        merged.update(_flatten(cp, section))
    drop = ("compatible_printers", "compatible_prints", "renamed_from", "alias", "printer_model")
    merged = {k: v for k, v in merged.items() if not k.startswith(drop)}
    merged.update(extra)
    return "".join(f"{k} = {v}\n" for k, v in merged.items())


def prusa_slice(config: str, models: list[Path], out: Path, center: str, work: Path) -> None:
    ini = work / f"{out.stem}.ini"
    ini.write_text(config)
    subprocess.run(
        ["prusa-slicer", "--export-gcode", "--load", str(ini), "--center", center]
        + (["--merge"] if len(models) > 1 else [])
        + ["-o", str(out)]
        + [str(m) for m in models],
        check=True,
        capture_output=True,
    )


# ----------------------------------------------------------------- Slic3r
def slic3r_slice(model: Path, out: Path, *options: str) -> None:
    subprocess.run(
        ["slic3r", "--no-gui", *options, "-o", str(out), str(model)],
        check=True,
        capture_output=True,
    )


# ------------------------------------------------------------------- Cura
def cura_slice(resources: Path, printer: str, model: Path, out: Path, **settings: str) -> None:
    """CuraEngine with a stock printer definition; the header is completed as Cura's
    front end does (print time, filament used) and its placeholders are filled."""
    defs, extruders = resources / "definitions", resources / "extruders"
    definition = defs / f"{printer}.def.json"
    extruder = next(extruders.glob(f"{printer.split('_', maxsplit=1)[0]}*extruder_0.def.json"))
    given = [a for k, v in settings.items() for a in ("-s", f"{k}={v}")]
    args = ["CuraEngine", "slice", "-v", "-j", str(definition), *given]
    args += ["-e0", "-j", str(extruder), *given]
    args += ["-l", str(model), "-o", str(out)]
    env = {"CURA_ENGINE_SEARCH_PATH": f"{defs}:{extruders}", "PATH": "/usr/bin:/bin"}
    res = subprocess.run(args, check=True, capture_output=True, text=True, env=env)
    seconds = re.search(r"Print time \(s\): (\d+)", res.stderr)
    volume = re.search(r"Filament \(mm\^3\): (\d+)", res.stderr)
    text = out.read_text()
    if seconds:
        text = re.sub(r";TIME:\d+", f";TIME:{seconds.group(1)}", text, count=1)
    if volume:
        metres = float(volume.group(1)) / (math.pi * 1.75**2 / 4) / 1000.0
        text = re.sub(r";Filament used: .*", f";Filament used: {metres:.5f}m", text, count=1)
        text = re.sub(r";MATERIAL:\d+", f";MATERIAL:{volume.group(1)}", text, count=1)
    text = text.replace("{machine_depth}", settings.get("machine_depth", "235"))
    out.write_text(text)


# --------------------------------------------------------- post-processing
_OBJ = re.compile(r"^; (printing|stop printing) object (.+?) id:(\d+) copy \d+\s*$")


def label_objects(path: Path, style: str) -> None:
    """PrusaSlicer 2.5's object comments -> M486 (Marlin) or EXCLUDE_OBJECT_* (Klipper)."""
    lines = path.read_text().splitlines()
    names: dict[int, str] = {}
    bbox: dict[int, list[float]] = {}
    current = None
    for line in lines:
        m = _OBJ.match(line)
        if m:
            current = int(m.group(3)) if m.group(1) == "printing" else None
            names.setdefault(int(m.group(3)), re.sub(r"\W", "_", m.group(2)))
            continue
        if current is not None and line.startswith("G1") and " E" in line:
            x = re.search(r"X(-?[\d.]+)", line)
            y = re.search(r"Y(-?[\d.]+)", line)
            if x and y:
                b = bbox.setdefault(current, [math.inf, math.inf, -math.inf, -math.inf])
                xv, yv = float(x.group(1)), float(y.group(1))
                bbox[current] = [min(b[0], xv), min(b[1], yv), max(b[2], xv), max(b[3], yv)]
    out: list[str] = []
    header_done = False
    for line in lines:
        if not header_done and (line.startswith(("M107", ";TYPE"))):
            header_done = True
            if style == "klipper":
                for i, name in names.items():
                    x0, y0, x1, y1 = bbox.get(i, [0, 0, 0, 0])
                    poly = f"[[{x0:.3f},{y0:.3f}],[{x1:.3f},{y0:.3f}],[{x1:.3f},{y1:.3f}],[{x0:.3f},{y1:.3f}]]"
                    out.append(
                        f"EXCLUDE_OBJECT_DEFINE NAME={name} CENTER={(x0 + x1) / 2:.3f},{(y0 + y1) / 2:.3f} POLYGON={poly}"
                    )
            else:
                out.append(f"M486 T{len(names)}")
        m = _OBJ.match(line)
        if m:
            i = int(m.group(3))
            if style == "klipper":
                verb = "START" if m.group(1) == "printing" else "END"
                out.append(f"EXCLUDE_OBJECT_{verb} NAME={names[i]}")
            elif m.group(1) == "printing":
                out.append(f'M486 S{i} A"{names[i]}"')
            else:
                out.append("M486 S-1")
        out.append(line)
    path.write_text("\n".join(out) + "\n")


_MOVE = re.compile(r"^G1 X(-?[\d.]+) Y(-?[\d.]+) E(-?[\d.]+)(?: F([\d.]+))?\s*$")
_POS = re.compile(r"([XYZE])(-?[\d.]+)")


def weld_arcs(path: Path, tolerance: float = 0.02, min_points: int = 4) -> int:
    """Replace runs of short extruding G1 moves that lie on a circle by G2/G3, as the
    common arc-welding post-processors do (absolute XY, absolute E). Returns the arcs made."""
    lines = path.read_text().splitlines()
    out: list[str] = []
    x = y = 0.0
    arcs = 0
    i = 0
    while i < len(lines):
        run = []
        j = i
        while j < len(lines):
            m = _MOVE.match(lines[j])
            if not m or (m.group(4) and run):
                break
            run.append((float(m.group(1)), float(m.group(2)), m.group(3), m.group(4)))
            j += 1
        if len(run) < min_points:
            line = lines[i]
            for letter, value in _POS.findall(line.split(";", 1)[0]):
                if letter == "X":
                    x = float(value)
                elif letter == "Y":
                    y = float(value)
            out.append(line)
            i += 1
            continue
        pts = [(x, y)] + [(r[0], r[1]) for r in run]
        k = 0
        while k < len(run):
            end = _longest_arc(pts, k, tolerance, min_points)
            if end is None:
                r = run[k]
                out.append(f"G1 X{r[0]:.3f} Y{r[1]:.3f} E{r[2]}" + (f" F{r[3]}" if r[3] else ""))
                k += 1
                continue
            (cx, cy), ccw = end[1], end[2]
            sx, sy = pts[k]
            r = run[end[0] - 1]
            feed = f" F{run[k][3]}" if run[k][3] else ""
            out.append(
                f"G{3 if ccw else 2} X{r[0]:.3f} Y{r[1]:.3f} I{cx - sx:.3f} J{cy - sy:.3f} E{r[2]}{feed}"
            )
            arcs += 1
            k = end[0]
        x, y = pts[-1]
        i = j
    path.write_text("\n".join(out) + "\n")
    return arcs


def _circle(a, b, c):
    (ax, ay), (bx, by), (cx, cy) = a, b, c
    d = 2 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    if abs(d) < 1e-9:
        return None
    ux = (
        (ax**2 + ay**2) * (by - cy) + (bx**2 + by**2) * (cy - ay) + (cx**2 + cy**2) * (ay - by)
    ) / d
    uy = (
        (ax**2 + ay**2) * (cx - bx) + (bx**2 + by**2) * (ax - cx) + (cx**2 + cy**2) * (bx - ax)
    ) / d
    return ux, uy


def _longest_arc(pts, k, tol, min_points):
    """(index after the arc's last move, centre, counter-clockwise) of the longest arc
    starting at point k through at least ``min_points`` moves, or None."""
    best = None
    for end in range(k + min_points, len(pts)):
        seg = pts[k : end + 1]
        centre = _circle(seg[0], seg[len(seg) // 2], seg[-1])
        if centre is None:
            break
        r = math.dist(seg[0], centre)
        if not 0.5 < r < 200:
            break
        if any(abs(math.dist(p, centre) - r) > tol for p in seg):
            break
        mids = [((p[0] + q[0]) / 2, (p[1] + q[1]) / 2) for p, q in zip(seg, seg[1:])]
        if any(r - math.dist(mp, centre) > tol for mp in mids):
            break
        turns = [
            (q[0] - p[0]) * (s[1] - q[1]) - (q[1] - p[1]) * (s[0] - q[0])
            for p, q, s in zip(seg, seg[1:], seg[2:])
        ]
        if not (all(t > 0 for t in turns) or all(t < 0 for t in turns)):
            break
        best = (end, centre, turns[0] > 0)
    return best


_LAYER = re.compile(r"^;(LAYER_CHANGE|LAYER:\d+)\s*$")


def crop(path: Path, keep_layers: int) -> None:
    """Keep the first ``keep_layers`` layers, the last layer and the end block; a
    ``G92 E`` where layers were cut keeps absolute extrusion right."""
    lines = path.read_text().splitlines()
    starts = [i for i, line in enumerate(lines) if _LAYER.match(line)]
    if len(starts) <= keep_layers + 1:
        return
    cut_from, cut_to = starts[keep_layers], starts[-1]
    e = _e_position(lines[:cut_to])
    note = f"; cropped: layers {keep_layers}..{len(starts) - 2} removed"
    fix = [note] if e is None else [note, f"G92 E{e:.5f}"]
    path.write_text("\n".join(lines[:cut_from] + fix + lines[cut_to:]) + "\n")


def _e_position(lines: list[str]) -> float | None:
    """The programmed E position after ``lines`` in absolute E mode (None: relative E)."""
    relative, e = False, 0.0
    for raw in lines:
        code = raw.split(";", 1)[0].split()
        if not code:
            continue
        if code[0] == "M83":
            relative = True
        elif code[0] == "M82":
            relative = False
        elif code[0] in ("G0", "G1", "G2", "G3", "G92"):
            for w in code[1:]:
                if w[:1] in "Ee" and len(w) > 1:
                    v = float(w[1:])
                    e = v if (code[0] == "G92" or not relative) else e + v
    return None if relative else e


def simplify3d_style(src: Path, out: Path) -> None:
    """A Slic3r file dressed as Simplify3D writes them (no Simplify3D runs on Linux here):
    its header, start code with a prime line, ``; layer N, Z = z`` markers, G10-free
    retraction and its build summary. The moves are Slic3r's."""
    lines = src.read_text().splitlines()
    modes = next(i for i, line in enumerate(lines) if line.startswith("M82"))
    first = next(i for i, line in enumerate(lines) if i > modes and line.startswith("G1 Z"))
    end = max(i for i, line in enumerate(lines) if line.startswith("G1 X") and " E" in line)
    body, layer = [], 0
    for line in lines[first : end + 1]:
        if line.startswith("G1 Z"):
            layer += 1
            z = float(line.split()[1][1:])
            body.append(f"; layer {layer}, Z = {z:.3f}")
        body.append(line.split(";", 1)[0].rstrip())
    e, total = 0.0, 0.0
    for line in body:
        code = line.split()
        if code and code[0] == "G92":
            e = next((float(w[1:]) for w in code[1:] if w[0] == "E"), e)
        elif code and code[0] == "G1":
            for w in code[1:]:
                if w[0] == "E":
                    v = float(w[1:])
                    if any(c[0] in "XY" for c in code[1:]):
                        total += max(v - e, 0.0)
                    e = v
    header = [
        "; G-Code generated by Simplify3D(R) Version 4.1.2",
        "; (our own file in Simplify3D's format: moves from Slic3r 1.3, see README.md)",
        ";   printExtruders,0",
        ";   extruderDiameter,0.4",
        ";   layerHeight,0.3",
        "G90",
        "M82",
        "M106 S0",
        "M140 S60",
        "M190 S60",
        "M104 S205 T0",
        "M109 S205 T0",
        "G28 ; home all axes",
        "G1 Z0.3 F1000",
        "G1 X5 Y5 F3000",
        "G92 E0",
        "G1 X120 Y5 E12 F1200 ; prime the nozzle",
        "G92 E0",
    ]
    footer = [
        "M104 S0 ; turn off extruder",
        "M140 S0 ; turn off bed",
        "G28 X0 ; home X axis",
        "M84 ; disable motors",
        "; Build Summary",
        ";   Build time: 0 hours 3 minutes",
        f";   Filament length: {total:.1f} mm ({total / 1000:.2f} m)",
        ";   Plastic volume: 0.00 mm^3 (0.00 cc)",
    ]
    out.write_text("\n".join(header + body + footer) + "\n")


# ------------------------------------------------------------------ corpus
def build(work: Path, cura: Path | None) -> None:
    out = HERE
    # PrusaSlicer, Prusa MK3S stock (250 x 210 bed, purge line at y = -3, G80, M862)
    prusa_slice(
        prusa_config(
            "PrusaResearch",
            "Original Prusa i3 MK3S & MK3S+",
            "0.20mm QUALITY @MK3",
            "Generic PLA",
        ),
        [stl("cube_small", work)],
        out / "prusaslicer25_mk3s_cube.gcode",
        "125,105",
        work,
    )
    prusa_slice(
        prusa_config(
            "PrusaResearch",
            "Original Prusa i3 MK3S & MK3S+",
            "0.20mm QUALITY @MK3",
            "Generic PLA",
        ),
        [stl("part", work)],
        out / "prusaslicer25_mk3s_part_cropped.gcode",
        "125,105",
        work,
    )
    crop(out / "prusaslicer25_mk3s_part_cropped.gcode", 3)
    # PrusaSlicer, Creality Ender-3 stock (220 bed, prime lines at x = 2), two objects, M486
    prusa_slice(
        prusa_config(
            "Creality",
            "Creality Ender-3 (0.4 mm nozzle)",
            "0.20 mm NORMAL (0.4 mm nozzle) @CREALITY",
            "Generic PLA @CREALITY",
            gcode_label_objects="1",
        ),
        [stl("cube_small", work), stl("tube", work)],
        out / "prusaslicer25_ender3_two_objects_m486.gcode",
        "110,110",
        work,
    )
    label_objects(out / "prusaslicer25_ender3_two_objects_m486.gcode", "marlin")
    # PrusaSlicer, Voron 2.4 stock (Klipper: print_start macro), EXCLUDE_OBJECT labels
    prusa_slice(
        prusa_config(
            "Voron",
            "Voron_v2_250 0.4 nozzle",
            "0.2mm 0.4nozzle V2",
            "Basic PLA @VORON",
            gcode_label_objects="1",
        ),
        [stl("cube_small", work), stl("tube", work)],
        out / "prusaslicer25_voron_klipper_exclude_object.gcode",
        "125,125",
        work,
    )
    label_objects(out / "prusaslicer25_voron_klipper_exclude_object.gcode", "klipper")
    # Slic3r 1.3 (its arc fitting is disabled in 1.3: arcs welded afterwards), 200 x 200 bed
    slic3r_slice(
        stl("boat", work),
        out / "slic3r13_arcs_boat.gcode",
        "--scale",
        "1.5",
        "--print-center",
        "100,100",
        "--layer-height",
        "0.18",
        "--first-layer-temperature",
        "210",
        "--temperature",
        "205",
        "--bed-temperature",
        "60",
    )
    print("arcs:", weld_arcs(out / "slic3r13_arcs_boat.gcode"))
    # Slic3r 1.3 without arcs, firmware retraction (G10/G11), relative E
    slic3r_slice(
        stl("tube", work),
        out / "slic3r13_firmware_retraction_tube.gcode",
        "--use-firmware-retraction",
        "--use-relative-e-distances",
        "--print-center",
        "100,100",
        "--temperature",
        "200",
        "--bed-temperature",
        "55",
    )
    # a file in Simplify3D's format (its header, layer markers, build summary)
    slic3r_slice(
        stl("cube_small", work),
        work / "for_s3d.gcode",
        "--print-center",
        "100,100",
        "--layer-height",
        "0.3",
    )
    simplify3d_style(work / "for_s3d.gcode", out / "simplify3d_style_cube.gcode")
    if cura is not None:
        # Cura 4.13 engine, Creality Ender-3 definition, its defaults (purge lines at x = 0.1)
        cura_slice(
            cura,
            "creality_ender3",
            stl("cube_small", work),
            out / "cura413_ender3_cube.gcode",
            layer_height="0.2",
            machine_depth="235",
        )
        # Ultimaker 2 definition: UltiGCode flavour (no temperatures, G10/G11 retraction)
        cura_slice(
            cura,
            "ultimaker2",
            stl("cube_small", work),
            out / "cura413_ultimaker2_ultigcode_cube.gcode",
            layer_height="0.2",
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cura-resources", type=Path, help="Cura's resources folder (definitions/)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        build(Path(tmp), args.cura_resources)
    shutil.rmtree(HERE / "__pycache__", ignore_errors=True)


if __name__ == "__main__":
    main()
