"""Write firmware/sim/thermal_plant.h: the simulated heaters' plant for the AVR harness.

The numbers come from firmware_protocol/device/thermal_plant.py, which the Python
device model reads too, so the two simulated devices heat the same plant.
``--check`` exits 1 when the checked-in header is stale.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "firmware" / "sim" / "thermal_plant.h"


def render() -> str:
    sys.path.insert(0, str(ROOT))
    from firmware_protocol.device.thermal_plant import c_header

    return c_header()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        return 0 if OUT.exists() and OUT.read_text() == text else 1
    OUT.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
