#!/usr/bin/env python3
"""The board firmware's static worst-case stack, against the RAM left above static data.

    python firmware/tools/stack_usage.py [--margin BYTES] [--elf build/cdpr.elf]

Frames: each source compiled again with the board's flags and ``-fstack-usage`` (the
same code as the ELF's; warnings off, since gcc cannot size the naked assembly
functions); a function without a frame there (naked, assembly, libgcc) counts the
``push`` instructions of its disassembly. Call graph: the ELF's disassembly (``call``,
``rcall`` add the 3-byte return address of the ATmega2560; ``jmp`` and ``rjmp`` to another
function are tail calls; ``icall``/``eicall`` reach the functions main.c wires in, listed in
INDIRECT below: a new indirect call fails the run until it is listed). The worst
case is ``main``'s deepest path plus the deepest interrupt (3 bytes for its entry), plus,
for an interrupt that enables interrupts again (``sei``), the deepest other interrupt
nested in it. Exit status 1 when less than ``--margin`` bytes would stay free.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from functools import cache
from pathlib import Path

FIRMWARE = Path(__file__).resolve().parents[1]
MARGIN = 64  # bytes that must stay free below the static data at the worst case
RET = 3  # a call's return address on the ATmega2560 (22-bit program counter)
RAMEND = 0x21FF
CANARY = 2  # the canary word at _end (src/watchdog.c)
CFLAGS = [
    "-std=c99",
    "-mmcu=atmega2560",
    "-DF_CPU=16000000UL",
    "-Os",
    "-ffunction-sections",
    "-fdata-sections",
    "-fstack-usage",
    "-w",
    "-Isrc",
]
SIM_ONLY = {"sim_hooks.c"}
# The targets of each function's indirect calls: the wiring of src/main.c (its tables of
# upper-layer functions). A function with an indirect call missing here fails the run.
#: vectors of which at most one has interrupts enabled at a time: the step engine's
#: steppers (Timer3 compare A-C, Timer5 compare A), whose C paths run one at a time
#: (src/step_engine.c, step_c_open: a second one leaves its work to the first)
#: A member nested inside another's C path (the one that enabled interrupts) finds the C
#: path open and returns from its entry: its C functions (``C_PATH``) are not on the
#: stack then.
EXCLUSIVE = ({"__vector_32", "__vector_33", "__vector_34", "__vector_47"},)
C_PATH = re.compile(r"__vector_\w+_c")
INDIRECT = {
    "deframer_run": ("link_frame_received", "link_frame_rejected", "prepare_one"),
    "link_frame_received": ("proto_accept", "proto_urgent", "proto_frame_seen"),
    "send_ack": ("proto_flow",),
    "machine_shutdown": ("report_error",),
    "machine_free": ("proto_pending_items",),
    "machine_credit": ("proto_pending_items",),
    "autotune_step": ("report_event", "machine_fail"),
    "heater_control": ("autotune_heater", "autotune_relay"),
    "report_status": ("health_read",),
}

FUNC = re.compile(r"^([0-9a-f]+) <([\w.]+)>:$")
CALL = re.compile(r"\b(r?call)\s+[^<]*<([\w.]+)(\+0x[0-9a-f]+)?>")
JUMP = re.compile(r"\b(r?jmp)\s+[^<]*<([\w.]+)(\+0x[0-9a-f]+)?>")


def frames(tmp: Path, cflags: list[str]) -> dict[str, int]:
    """Each function's frame from -fstack-usage, compiled as the build was (``cflags``:
    its EXTRA_CFLAGS; a build option such as STEP_ENGINE changes the frames)."""
    out: dict[str, int] = {}
    for src in sorted((FIRMWARE / "src").glob("*.c")):
        if src.name in SIM_ONLY:
            continue
        obj = tmp / (src.stem + ".o")
        subprocess.run(
            ["avr-gcc", *CFLAGS, *cflags, "-c", str(src), "-o", str(obj)], cwd=FIRMWARE, check=True
        )
        su = obj.with_suffix(".su")
        for line in su.read_text().splitlines() if su.exists() else []:
            where, size, _kind = line.split("\t")
            out[where.rsplit(":", 1)[-1]] = int(size)
    return out


def disassembly(elf: Path) -> dict[str, tuple[int, list[str]]]:
    text = subprocess.run(
        ["avr-objdump", "-d", str(elf)], capture_output=True, text=True, check=True
    ).stdout
    funcs: dict[str, tuple[int, list[str]]] = {}
    name = ""
    for line in text.splitlines():
        m = FUNC.match(line)
        if m:
            name = m.group(2)
            funcs[name] = (int(m.group(1), 16), [])
        elif name and line.strip():
            funcs[name][1].append(line)
    return funcs


def analyse(elf: Path, cflags: list[str] | None = None) -> dict[str, int | str]:
    with tempfile.TemporaryDirectory() as tmp:
        frame_of = frames(Path(tmp), cflags or [])
    funcs = disassembly(elf)

    def frame(name: str) -> int:
        if frame_of.get(name):
            return frame_of[name]
        return sum(1 for ln in funcs[name][1] if "\tpush\t" in ln)

    @cache
    def depth(
        name: str, stack: tuple[str, ...] = (), entry_only: bool = False
    ) -> tuple[int, tuple[str, ...]]:
        if name in stack:
            raise SystemExit(f"stack_usage: recursion through {' -> '.join((*stack, name))}")
        here = (*stack, name)
        best, path = frame(name), (name,)
        for line in funcs.get(name, (0, []))[1]:
            callees: list[tuple[str, int]] = []
            m = CALL.search(line)
            if m and not m.group(3) and m.group(2) != name:
                callees.append((m.group(2), RET))
            m = JUMP.search(line)
            if m and not m.group(3) and m.group(2) != name:
                callees.append((m.group(2), 0))  # a tail call: the frame is gone
            if re.search(r"\be?icall\b", line):
                if name not in INDIRECT:
                    raise SystemExit(
                        f"stack_usage: {name} calls through a pointer: list its targets"
                    )
                callees += [(f, RET) for f in INDIRECT[name]]
            for callee, ret in callees:
                if callee not in funcs or (entry_only and C_PATH.fullmatch(callee)):
                    continue
                d, p = depth(callee, here, entry_only)
                total = (frame(name) + ret + d) if ret else max(frame(name), d)
                if total > best:
                    best, path = total, (name, *p)
        return best, path

    main, main_path = depth("main")
    main += RET  # the C runtime's call
    isrs = {n: depth(n) for n in funcs if re.fullmatch(r"__vector_\d+", n)}
    isr_depth = {n: RET + d for n, (d, _) in isrs.items()}
    isr_depth_entry: dict[str, int] = {}  # a nested EXCLUSIVE member: its entry only

    def reachable(n: str) -> set[str]:
        seen, todo = set(), [n]
        while todo:
            f = todo.pop()
            if f in seen or f not in funcs:
                continue
            seen.add(f)
            for line in funcs[f][1]:
                for rx in (CALL, JUMP):
                    m = rx.search(line)
                    if m and not m.group(3):
                        todo.append(m.group(2))
                todo += INDIRECT.get(f, ()) if re.search(r"\be?icall\b", line) else ()
        return seen

    def nests(n: str) -> bool:
        """Interrupts enabled again somewhere inside it (another one may then nest)."""
        return any("\tsei" in ln for f in reachable(n) for ln in funcs[f][1])

    # Each vector is on the stack at most once; every one that enables interrupts inside
    # may have the others nested in it, one of each EXCLUSIVE group at a time: the worst
    # case is all those that nest, one on top of them (any other, its whole depth).
    nesting = {n for n in isr_depth if nests(n)}

    def chain(top: str) -> tuple[int, list[str]]:
        below = [n for n in nesting if n != top]
        for group in EXCLUSIVE:
            inside = [n for n in below if n in group]
            if len(inside) > 1:
                keep = max(inside, key=lambda n: isr_depth[n])
                below = [n for n in below if n not in group or n == keep]
        below.sort(key=lambda n: -isr_depth[n])
        top_depth = isr_depth[top]
        if any(top in group and any(n in group for n in below) for group in EXCLUSIVE):
            top_depth = RET + depth(top, (), True)[0]
            isr_depth_entry[top] = top_depth
        return sum(isr_depth[n] for n in below) + top_depth, [*below, top]

    worst_isr, worst_name, worst_chain = 0, "", []
    for n in isr_depth:
        d, names = chain(n)
        if d > worst_isr:
            worst_isr, worst_name, worst_chain = d, n, names
    end = next(
        int(ln.split()[0], 16) & 0xFFFF
        for ln in subprocess.run(
            ["avr-nm", str(elf)], capture_output=True, text=True, check=True
        ).stdout.splitlines()
        if ln.endswith(" _end")
    )
    available = RAMEND - end + 1 - CANARY
    worst = main + worst_isr
    return {
        "available": available,
        "worst": worst,
        "free": available - worst,
        "main": main,
        "main_path": " -> ".join(main_path),
        "interrupts": worst_isr,
        "interrupt": " > ".join(
            f"{n} {isr_depth_entry[n] if n == worst_name and n in isr_depth_entry else isr_depth[n]} B"
            for n in worst_chain
        )
        + (" (nested, each enabling interrupts but the last)" if len(worst_chain) > 1 else ""),
        "interrupt_path": " -> ".join(
            depth(worst_name, (), worst_name in isr_depth_entry)[1] if worst_name else ()
        ),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--margin", type=int, default=MARGIN)
    ap.add_argument("--elf", type=Path, default=FIRMWARE / "build" / "cdpr.elf")
    ap.add_argument(
        "--cflags",
        default="",
        help="the build's EXTRA_CFLAGS (e.g. -DSTEP_ENGINE=1): the frames are compiled so",
    )
    args = ap.parse_args()
    r = analyse(args.elf, args.cflags.split())
    print(
        f"stack: {r['available']} B above static data (less the canary); worst case "
        f"{r['worst']} B = main {r['main']} B ({r['main_path']}) + interrupts "
        f"{r['interrupts']} B ({r['interrupt']}: {r['interrupt_path']}); "
        f"{r['free']} B free, margin {args.margin} B"
    )
    if int(r["free"]) < args.margin:
        print(f"stack_usage: only {r['free']} B free, below the margin of {args.margin} B")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
