"""The key bar: Textual's footer without its leak.

Each time the bindings change, the footer composes new keys, and every key binds itself to
the footer's ``compact`` setting: a watcher kept on the footer. The watchers of removed keys
are pruned only when ``compact`` changes, which it never does here, so every recompose kept a
set of dead keys alive (32 per print, the UI's memory grew with each print). After each
recompose this footer drops the watchers of keys no longer on screen, and what Textual's
render cache holds of them (and of any other widget removed since: see
:mod:`~cdprhost.tui.widgets.render_caches`).
"""

from __future__ import annotations

from textual.widgets import Footer

from cdprhost.tui.widgets.render_caches import forget_dead_widgets


class KeyBar(Footer):
    async def recompose(self) -> None:
        await super().recompose()
        watchers = getattr(self, "__watchers", {})
        for entries in watchers.values():
            entries[:] = [(node, cb) for node, cb in entries if getattr(node, "is_attached", True)]
        forget_dead_widgets()
