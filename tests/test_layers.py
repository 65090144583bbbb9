"""The layer contract: every import points down (docs/architecture.md).

Read from the source (every ``import``, including those inside functions), so a lazy
import cannot hide an upward arrow. A package may import its own modules and anything in
a lower layer; packages in the same layer may not import each other.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Lowest first. One tuple per layer; packages within a layer are independent.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("firmware_protocol",),
    ("firmware_protocol.device",),
    ("cdprhost",),  # the package itself: its version, nothing else
    ("cdprhost.errors", "cdprhost.jsonsafe"),
    ("cdprhost.fileio", "cdprhost.logs"),
    ("cdprhost.effects",),
    ("cdprhost.profile",),
    ("cdprhost.kinematics", "cdprhost.gcode"),
    ("cdprhost.motion",),
    ("cdprhost.preflight", "cdprhost.calibration"),
    ("cdprhost.diagnosis",),
    ("cdprhost.link",),
    ("cdprhost.machine", "cdprhost.sim"),
    ("cdprhost.job",),
    ("cdprhost.service",),  # the printer service: job, link and device in one process
    ("cdprhost.server",),  # the print server (slicer upload API): the TUI runs it
    ("cdprhost.tui",),
    ("cdprhost.cli",),  # `cdprhost tui` starts the terminal UI
    ("cdprhost.__main__",),
)
RANK = {name: rank for rank, layer in enumerate(LAYERS) for name in layer}
CORE = {
    "cdprhost.effects",
    "cdprhost.profile",
    "cdprhost.kinematics",
    "cdprhost.gcode",
    "cdprhost.motion",
    "cdprhost.preflight",
    "cdprhost.calibration",
    "cdprhost.diagnosis",
}


def unit(module: str) -> str | None:
    """The contract unit a dotted module belongs to (the longest listed prefix)."""
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        name = ".".join(parts[:n])
        if name in RANK:
            return name
    return None


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path) -> list[tuple[int, str]]:
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append((node.lineno, node.module))
        elif isinstance(node, ast.Import):
            out.extend((node.lineno, a.name) for a in node.names)
    return out


def source_files() -> list[Path]:
    files = [
        *ROOT.joinpath("cdprhost").rglob("*.py"),
        *ROOT.joinpath("firmware_protocol").rglob("*.py"),
    ]
    return sorted(files)


def arrows() -> list[tuple[str, str, str]]:
    """(file:line, from unit, to unit) for every import between two contract units."""
    out = []
    for path in source_files():
        src = unit(module_name(path))
        assert src is not None, f"{path} belongs to no layer: add its package to LAYERS"
        for line, target in imports_of(path):
            dst = unit(target)
            if dst is not None and dst != src:
                out.append((f"{path.relative_to(ROOT)}:{line}", src, dst))
    return out


def test_every_package_has_a_layer():
    for path in source_files():
        assert unit(module_name(path)) is not None, path


def test_imports_point_down():
    upward = [
        f"{where}: {src} imports {dst}" for where, src, dst in arrows() if RANK[dst] >= RANK[src]
    ]
    assert not upward, "imports that do not point down:\n" + "\n".join(upward)


def test_firmware_protocol_stands_alone():
    bad = [
        f"{where}: {src} imports {dst}"
        for where, src, dst in arrows()
        if src.startswith("firmware_protocol") and not dst.startswith("firmware_protocol")
    ]
    assert not bad, "\n".join(bad)


def test_core_reaches_no_device_model():
    """The pure core never touches the simulated device (it is part of the simulated world)."""
    bad = [
        f"{where}: {src} imports {dst}"
        for where, src, dst in arrows()
        if src in CORE and dst == "firmware_protocol.device"
    ]
    assert not bad, "\n".join(bad)


def test_contract_catches_an_upward_import(tmp_path):
    """The checker itself: a lazy upward import inside a function is seen."""
    probe = tmp_path / "probe.py"
    probe.write_text("def f():\n    from cdprhost.job.runner import PrintJob\n")
    ((line, target),) = imports_of(probe)
    assert line == 2
    assert RANK[unit(target)] > RANK["cdprhost.kinematics"]


# --- no import circle inside a package ------------------------------------------------

# Packages whose modules must form no circle among themselves (lazy imports included).
ACYCLIC = ("cdprhost.calibration",)
# Packages whose single modules form no circle (lazy and TYPE_CHECKING imports included): the
# TUI's app, screens and controller (screens type the app by ``screens.host.ScreenHost``,
# the controller by ``control.host.ControllerHost``), the print job's modules, and the wire
# protocol with its simulated device (the segment coder uses the step schedules and their
# block, which use the ramp profile, not the coder).
ACYCLIC_MODULES = (*ACYCLIC, "cdprhost.tui", "cdprhost.job", "firmware_protocol")


def module_of(target: str, modules: set[str]) -> str | None:
    """The module a dotted import reaches (``from pkg.mod import name`` reaches pkg.mod)."""
    parts = target.split(".")
    for n in range(len(parts), 0, -1):
        name = ".".join(parts[:n])
        if name in modules:
            return name
    return None


def import_graph(package: str) -> dict[str, set[str]]:
    """module -> the modules of ``package`` it imports, read from the source."""
    base = ROOT.joinpath(*package.split("."))
    files = {module_name(p): p for p in sorted(base.rglob("*.py"))}
    graph: dict[str, set[str]] = {m: set() for m in files}
    for mod, path in files.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            for t in targets:
                hit = module_of(t, set(files))
                if hit is not None and hit != mod:
                    graph[mod].add(hit)
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected groups of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_circle_inside_a_package():
    for package in ACYCLIC_MODULES:
        graph = import_graph(package)
        found = circles(graph)
        text = [
            " <-> ".join(group)
            + "\n"
            + "\n".join(f"    {m} imports {sorted(graph[m] & set(group))}" for m in group)
            for group in found
        ]
        assert not found, f"import circles inside {package}:\n" + "\n".join(text)


def package_graph(package: str) -> dict[str, set[str]]:
    """The import graph of ``package``'s direct children, each sub-package one node: child
    -> the children it imports (anything inside a sub-package counts as the sub-package)."""
    prefix = package + "."

    def child(module: str) -> str:
        return (
            prefix + module[len(prefix) :].split(".", maxsplit=1)[0]
            if module.startswith(prefix)
            else module
        )

    graph: dict[str, set[str]] = {}
    for mod, targets in import_graph(package).items():
        if mod == package:
            continue
        node = graph.setdefault(child(mod), set())
        node.update(child(t) for t in targets if t != package and child(t) != child(mod))
    return graph


def sub_packages(package: str) -> list[str]:
    """``package`` and every package inside it."""
    base = ROOT.joinpath(*package.split("."))
    return sorted(module_name(p) for p in base.rglob("__init__.py"))


def test_no_import_circle_between_the_parts_of_a_package():
    """Inside each package (and each of its sub-packages), a sub-package counts as one node:
    a source (``calibration.camera``) may use the modules beside it, but nothing it uses may
    use it back (no ``calibration.session`` -> ``camera`` -> ``calibration.session``)."""
    for top in ACYCLIC:
        for package in sub_packages(top):
            graph = package_graph(package)
            found = circles(graph)
            text = [
                " <-> ".join(group)
                + "\n"
                + "\n".join(f"    {m} imports {sorted(graph[m] & set(group))}" for m in group)
                for group in found
            ]
            assert not found, f"import circles between the parts of {package}:\n" + "\n".join(text)


def reach(graph: dict[str, set[str]], start: str) -> set[str]:
    """Every module ``start`` imports, directly or through others."""
    seen: set[str] = set()
    todo = [start]
    while todo:
        for nxt in graph.get(todo.pop(), set()):
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen


def test_identification_and_the_gate_import_no_measurement_source():
    """Sources produce observations; identification and the trust gate take them and
    reach no source (motion capture, camera), not even through another module."""
    graph = import_graph("cdprhost.calibration")
    sources = ("cdprhost.calibration.mocap", "cdprhost.calibration.camera")
    for module in ("identification", "trust", "verification", "measurements", "takes"):
        name = f"cdprhost.calibration.{module}"
        reached = sorted(m for m in reach(graph, name) if m.startswith(sources))
        assert not reached, f"{name} reaches the source module(s) {reached}"


def test_package_graph_sees_a_circle_through_a_sub_package(tmp_path, monkeypatch):
    """The checker itself: a module and a sub-package that import each other (no circle
    between single modules) are a circle between the package's parts."""
    pkg = tmp_path / "p"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from p.sub.x import f\n")
    (pkg / "sub" / "x.py").write_text("def f():\n    pass\n")
    (pkg / "sub" / "y.py").write_text("def g():\n    from p.a import f\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert circles(import_graph("p")) == []
    assert circles(package_graph("p")) == [["p.a", "p.sub"]]


def test_circle_checker_sees_a_type_checking_circle(tmp_path, monkeypatch):
    """The checker itself: an import only for the type checker closes a circle too (a screen
    that types ``self.app`` by the app that imports the screen)."""
    pkg = tmp_path / "p"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "app.py").write_text("from p.screen import Screen\n")
    (pkg / "screen.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from p.app import App\n"
    )
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert circles(import_graph("p")) == [["p.app", "p.screen"]]


def test_circle_checker_sees_a_lazy_circle():
    """The checker itself: a circle closed by an import inside a function is found."""
    graph = {"p.a": {"p.b"}, "p.b": {"p.c"}, "p.c": {"p.a"}, "p.d": {"p.a"}}
    assert circles(graph) == [["p.a", "p.b", "p.c"]]
    assert circles({"p.a": {"p.b"}, "p.b": set()}) == []
