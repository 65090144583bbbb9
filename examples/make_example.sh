#!/usr/bin/env bash
# Regenerate the README's example part: export this machine's PrusaSlicer profile,
# slice examples/example.scad with it (PrusaSlicer 2.5 and OpenSCAD from Debian).
set -euo pipefail
cd "$(dirname "$0")"
cdprhost profile export-slicer paper-prototype --to prusaslicer --out paper-prototype.prusaslicer.ini
work=$(mktemp -d)
openscad -o "$work/example.stl" example.scad
prusa-slicer --export-gcode --load paper-prototype.prusaslicer.ini --center 0,0 \
  --layer-height 0.2 --first-layer-height 0.25 --perimeters 2 --fill-density 15% \
  --temperature 210 --first-layer-temperature 215 --bed-temperature 60 --first-layer-bed-temperature 60 \
  -o example.gcode "$work/example.stl"
rm -rf "$work"
cdprhost check example.gcode --profile paper-prototype
