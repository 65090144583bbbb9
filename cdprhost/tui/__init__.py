"""The terminal UI (``cdprhost tui``), built with Textual.

- :mod:`.app`: :class:`~cdprhost.tui.app.CdprApp`, modes (screens), bindings, command palette;
- :mod:`.state`: the one UI state value and its pure updates;
- :mod:`.control`: the backend seam (:mod:`.control.backend`), its implementation on
  the real layers (:mod:`.control.live`), and the controller that runs blocking
  calls in thread workers and feeds job events through an event pump;
- :mod:`.screens`: one module per screen; :mod:`.widgets`: panels and text charts.

Keys: F1 link (c connect, d disconnect, r rescan), F2 print (o open, s start,
p pause, r resume, x cancel; Enter on a violation shows its line), F3 jog
(arrows and PgUp/PgDn choose a target, 1-4 the step, Enter moves, h home,
m motors off, t heaters), F4 calibrate (n plan, m move, k take, i identify),
F5 diagnose (e session), Ctrl+P command palette, Ctrl+Q quit.
"""
