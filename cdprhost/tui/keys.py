"""Key labels taken from the bindings themselves, so the footer, the help screen and every
hint on a screen name the same key with the same words.

A label is ``App.get_key_display(binding)`` (what Textual's footer shows) and the binding's
own description; nothing here spells a key by hand.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from textual.app import App
from textual.binding import Binding
from textual.dom import DOMNode


@dataclass(frozen=True)
class KeyRow:
    keys: str  # as the footer shows them, "/"-separated when several keys do the same
    description: str
    tooltip: str
    enabled: bool  # False: not possible right now (greyed in the footer)
    why: str = ""  # why not, when not enabled


def _bindings(node: DOMNode) -> list[Binding]:
    return [b for _, b in node._bindings]


def _ours(node: DOMNode, binding: Binding) -> bool:
    """Declared by a class of this project (not inherited from Textual's own widgets)."""
    for cls in type(node).__mro__:
        if not cls.__module__.startswith("cdprhost"):
            continue
        for b in cls.__dict__.get("BINDINGS", ()):
            if isinstance(b, Binding) and b.action == binding.action:
                return True
    return False


def action_name(binding: Binding) -> str:
    return binding.action.split("(", 1)[0]


def key_rows(app: App[Any], node: DOMNode, ours: bool = True) -> list[KeyRow]:
    """One row per action bound on ``node``, in the order they are declared; keys of the same
    action and description are joined. ``ours``: the project's own bindings; else the ones
    Textual brings (focus movement, copy)."""
    grouped: dict[tuple[str, str], list[Binding]] = {}
    for b in _bindings(node):
        if b.system or _ours(node, b) is not ours:
            continue
        grouped.setdefault((b.action, b.description), []).append(b)
    rows = []
    for (action, description), bindings in grouped.items():
        name = action.split("(", 1)[0]
        enabled = bool(node.check_action(name, ()))
        why = getattr(node, "why_not", None)
        rows.append(
            KeyRow(
                "/".join(app.get_key_display(b) for b in bindings),
                description or action,
                bindings[0].tooltip,
                enabled,
                why(name) if why is not None and not enabled else "",
            )
        )
    return rows


def key_for(app: App[Any], node: DOMNode, action: str) -> str:
    """The key shown for ``action`` (its name without arguments, or the exact action)."""
    for b in _bindings(node):
        if b.action == action or action_name(b) == action:
            return app.get_key_display(b)
    raise KeyError(f"no binding for {action!r} on {type(node).__name__}")


def hint(app: App[Any], node: DOMNode, action: str) -> str:
    """ "key Description", as the footer writes it."""
    for b in _bindings(node):
        if b.action == action or action_name(b) == action:
            return f"{app.get_key_display(b)} {b.description}"
    raise KeyError(f"no binding for {action!r} on {type(node).__name__}")
