"""The firmware's files are laid out in layers (firmware/README.md, "Layers"): no file
includes one above it, so the includes form no cycle, the transport names nothing above
it, and the board target has no simulator hooks."""

from __future__ import annotations

import re
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / "firmware" / "src"
TRANSPORT = {"uart", "frame", "link"}
# what the transport may include: itself and the leaves under it
BELOW_TRANSPORT = TRANSPORT | {"config", "crc", "protocol_gen", "cdpr_protocol", "sched"}


def _includes() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for f in sorted(SRC.glob("*.[ch]")):
        names = set(re.findall(r'#include "([a-z_0-9]+)\.h"', f.read_text()))
        graph.setdefault(f.stem, set()).update(names - {f.stem})
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(v: str) -> list[str] | None:
        state[v] = 1
        path.append(v)
        for w in sorted(graph.get(v, ())):
            if state.get(w) == 1:
                return path[path.index(w) :] + [w]
            if w not in state and (found := visit(w)):
                return found
        state[v] = 2
        path.pop()
        return None

    for v in sorted(graph):
        if v not in state and (found := visit(v)):
            return found
    return None


def test_no_file_includes_one_above_it():
    graph = _includes()
    graph.pop("main")  # the top: it wires the layers together
    assert _cycle(graph) is None, " -> ".join(_cycle(graph) or [])


def test_the_transport_names_nothing_above_it():
    graph = _includes()
    for name in sorted(TRANSPORT):
        assert graph[name] <= BELOW_TRANSPORT, (name, graph[name] - BELOW_TRANSPORT)


def test_only_the_hooks_header_names_the_mailbox():
    users = {f.name for f in SRC.glob("*.[ch]") if "sim_mailbox" in f.read_text()}
    assert users <= {"mailbox.h", "sim_hooks.h", "sim_hooks.c"}, users
