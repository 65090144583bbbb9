"""The job's and the service's modules import each other in one direction only (no
circle: ``stopping`` serves the streamer through a protocol, never importing it)."""

from __future__ import annotations

import pytest

from tests.test_layers import ROOT, imports_of, module_name


def _graph(package: str) -> dict[str, set[str]]:
    folder = ROOT.joinpath(*package.split("."))
    graph: dict[str, set[str]] = {}
    for path in folder.glob("*.py"):
        name = module_name(path)
        graph[name] = {t for _, t in imports_of(path) if t.startswith(package + ".")}
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt) :], nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


@pytest.mark.parametrize("package", ["cdprhost.job", "cdprhost.service"])
def test_no_import_circle(package):
    cycle = _cycle(_graph(package))
    assert cycle is None, " -> ".join(cycle or [])


def test_the_check_finds_a_circle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
