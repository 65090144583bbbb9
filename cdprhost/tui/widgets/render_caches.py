"""Textual's render cache that outlives its widgets, emptied.

``StylesCache.get_inner_outer`` (Textual 8) is an ``lru_cache`` on a method: its key holds
the widget's ``StylesCache`` (and with it the widget's rendered lines), so up to 1024 of
them stay alive after their widgets are gone (Textualize/textual#6665). Each print removes
dozens of widgets (the key bar's keys, dialogs, notifications): the UI's memory grew with
every print until the cache was full. The cache only saves building two styles: emptying
it when widgets have been removed costs nothing that matters.
"""

from __future__ import annotations

from textual._styles_cache import StylesCache


def forget_dead_widgets() -> None:
    """Drop what the method cache holds of widgets (a no-op once Textual fixes it)."""
    clear = getattr(StylesCache.get_inner_outer, "cache_clear", None)
    if clear is not None:
        clear()
