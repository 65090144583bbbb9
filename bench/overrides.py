"""Speed override (M220) on a print on the embedded simulated device (virtual time): how
much motion runs before an override takes effect, and what S200 / S50 do to the print's
device time, as ratios against the same print at 100 % in the same run.

    python bench/overrides.py
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from cdprhost.gcode.sample_parts import square_walls
from cdprhost.job.runner import PrintJob
from cdprhost.job.state import JobState, Progress
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded


def _part(folder: Path, layers: int = 12) -> Path:
    path = folder / "part.gcode"
    path.write_text(square_walls(layers))
    return path


def _run(path: Path, percent: float | None = None, at: int = 0) -> tuple[dict[int, float], int]:
    """(device time of each executed segment, the segment executed when the override was
    asked); ``at`` 0: asked before the start."""
    profile = load_profile("paper-prototype")
    holder: dict[str, object] = {}
    asked = {"seq": 0}
    job: PrintJob

    def factory():  # type: ignore[no-untyped-def]
        holder["link"] = open_embedded()
        return holder["link"]

    def on_event(e: object) -> None:
        if (
            percent is not None
            and at
            and isinstance(e, Progress)
            and job.state is JobState.PRINTING
            and e.segments_done >= at
            and not asked["seq"]
        ):
            asked["seq"] = e.segments_done
            job.request_speed(percent)

    job = PrintJob(path, profile, factory, on_event=on_event)
    if percent is not None and not at:
        job.request_speed(percent)
    job.run()
    record = holder["link"].device.record  # type: ignore[attr-defined]
    return {r["seq"]: r["t"] for r in record}, asked["seq"]


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = _part(Path(tmp))
        clean, _ = _run(path)
        end = clean[max(clean)]
        for percent in (200.0, 50.0):
            t, _ = _run(path, percent)
            print(f"M220 S{percent:g} from the start: device time x{t[max(t)] / end:.2f}")
        for at in (400, 900, 1500):
            t, seq = _run(path, 200.0, at)
            first = next(
                s
                for s in sorted(t)
                if s - 1 in t and abs((t[s] - t[s - 1]) - (clean[s] - clean[s - 1])) > 1e-5
            )
            print(
                f"M220 S200 asked at segment {seq}: in effect after {t[first - 1] - t[seq]:.2f} s "
                "of motion (the device's buffer, the link's high watermark: about 1 s)"
            )


if __name__ == "__main__":
    main()
