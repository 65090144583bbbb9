"""The terminal UI (``cdprhost tui``), built with Textual.

- :mod:`.app`: :class:`~cdprhost.tui.app.CdprApp`, modes (screens), bindings, command palette;
- :mod:`.state`: the one UI state value and its pure updates;
- :mod:`.control`: the backend seam (:mod:`.control.backend`), its implementation on
  the real layers (:mod:`.control.live`), and the controller that runs blocking
  calls in thread workers and feeds job events through an event pump;
- :mod:`.screens`: one module per screen; :mod:`.widgets`: panels and text charts.

Keys: press ``?`` on any screen (the help is generated from the bindings, so it always
names the keys the key bar shows); the tabs and their keys are in :mod:`.tabs`.
"""
