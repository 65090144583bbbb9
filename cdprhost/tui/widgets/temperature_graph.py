"""Hotend and bed temperatures against their targets, with a history chart; readings older
than a few seconds are marked stale (the link may be gone)."""

from __future__ import annotations

from collections.abc import Sequence

from rich.text import Text
from textual.widget import Widget

from cdprhost.tui.widgets.charts import block_chart

AMBIENT_C = 20.0
HEATERS = (("hotend", "bright_red"), ("bed", "dodger_blue1"))


class TemperatureGraph(Widget):
    """Two stacked charts (hotend, bed); the dotted line marks the target."""

    def __init__(self, *, id: str | None = None, classes: str | None = None):
        super().__init__(id=id, classes=classes)
        self._current: tuple[float | None, float | None] = (None, None)
        self._targets: tuple[float, float] = (0.0, 0.0)
        self._history: Sequence[tuple[float, float]] = ()
        self._stale_s: float | None = None

    def show(
        self,
        current: tuple[float | None, float | None],
        targets: tuple[float, float],
        history: Sequence[tuple[float, float]],
        stale_s: float | None = None,
    ) -> None:
        """``history`` holds (hotend, bed) samples, oldest first; ``stale_s``: the age of the
        readings when they are too old to trust (None: fresh)."""
        args = (current, targets, tuple(history), stale_s)
        if args == (self._current, self._targets, self._history, self._stale_s):
            return
        self._current, self._targets, self._history, self._stale_s = args
        self.refresh()

    @property
    def stale(self) -> bool:
        return self._stale_s is not None

    def render(self) -> Text:
        width, height = self.size.width, self.size.height
        per_heater = max(1, (height - 2) // 2)
        out = Text(no_wrap=True, overflow="crop")
        for k, (name, colour) in enumerate(HEATERS):
            now, target = self._current[k], self._targets[k]
            now_text = " --.-" if now is None else f"{now:5.1f}"
            stale = self._stale_s is not None and now is not None
            out.append(
                f"{name:<6} {now_text}/{target:<3.0f} °C",
                style="dim" if stale else f"bold {colour}",
            )
            if stale:
                out.append(f" STALE {self._stale_s:.0f}s", style="bold reverse red")
            out.append("\n")
            series = [h[k] for h in self._history]
            hi = max([target * 1.1, 60.0, *series]) if series else max(target * 1.1, 60.0)
            rows = block_chart(
                series, width, per_heater, AMBIENT_C, hi, marker=target if target > 0 else None
            )
            for r, row in enumerate(rows):
                out.append(row, style=colour)
                if k < len(HEATERS) - 1 or r < len(rows) - 1:
                    out.append("\n")
        return out
