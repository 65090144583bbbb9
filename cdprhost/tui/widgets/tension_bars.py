"""Cable tensions as bars against the profile's tension limits."""

from __future__ import annotations

from rich.text import Text
from textual.widget import Widget

from cdprhost.tui.widgets.charts import hbar, tension_level

LEVEL_STYLE = {"ok": "green", "near": "yellow", "bad": "bold red"}


class TensionBars(Widget):
    def __init__(
        self, t_min: float, t_max: float, *, id: str | None = None, classes: str | None = None
    ):
        super().__init__(id=id, classes=classes)
        self.t_min, self.t_max = t_min, t_max
        self._tensions: tuple[float, float, float] | None = None
        self._title = "tension"

    def show(self, tensions: tuple[float, float, float] | None, title: str = "tension") -> None:
        """``title`` says what the figures are (predicted where, measured...)."""
        shown = (
            None
            if tensions is None
            else (float(tensions[0]), float(tensions[1]), float(tensions[2]))
        )
        if shown != self._tensions or title != self._title:
            self._tensions, self._title = shown, title
            self.refresh()

    def levels(self) -> tuple[str, ...]:
        if self._tensions is None:
            return ()
        return tuple(tension_level(t, self.t_min, self.t_max) for t in self._tensions)

    def render(self) -> Text:
        out = Text(no_wrap=True, overflow="crop")
        limits = f" [{self.t_min:g}-{self.t_max:g} N]"
        width = self.size.width or 80
        out.append(self._title, style="bold")
        if len(self._title) + len(limits) <= width:  # the limits when there is room
            out.append(limits, style="dim")
        bar_w = max(self.size.width - 14, 4)
        for k in range(3):
            out.append("\n")
            if self._tensions is None:
                out.append(f"T{k + 1} " + "·" * bar_w + "     -- N", style="dim")
                continue
            t = self._tensions[k]
            style = LEVEL_STYLE[tension_level(t, self.t_min, self.t_max)]
            out.append(f"T{k + 1} ")
            out.append(hbar(t, self.t_max, bar_w), style=style)
            out.append(f" {t:6.1f} N", style=style)
        return out
