"""Ports to offer on the link screen: serial adapters and pseudo-terminals, each named.

pyserial lists USB and on-board serial ports but not pseudo-terminals, where ``cdprhost
sim-device`` (and other simulators or bridges) serve. On Linux the process holding the
master side of ``/dev/pts/N`` shows in ``/proc/<pid>/fdinfo`` (``tty-index: N``), so each
pseudo-terminal is named after the program behind it; a simulated device is marked.
Nothing here opens a port.
"""

from __future__ import annotations

import contextlib
import os
import re
from pathlib import Path

from cdprhost.tui.control.views import PortChoice

SIMULATOR_WORDS = ("sim-device", "simulated")
_TTY_INDEX = re.compile(r"^tty-index:\s*(\d+)", re.M)


def pty_owners(proc: Path = Path("/proc")) -> dict[int, tuple[int, str]]:
    """{pts index: (pid, command line)} for the pseudo-terminal masters we may look at."""
    owners: dict[int, tuple[int, str]] = {}
    try:
        pids = [p for p in proc.iterdir() if p.name.isdigit()]
    except OSError:
        return owners
    for pid_dir in pids:
        try:
            fds = list((pid_dir / "fd").iterdir())
        except OSError:
            continue
        for fd in fds:
            try:
                if not os.readlink(fd).endswith("ptmx"):
                    continue
                info = (pid_dir / "fdinfo" / fd.name).read_text()
            except OSError:
                continue
            m = _TTY_INDEX.search(info)
            if m is None:
                continue
            cmd = ""
            with contextlib.suppress(OSError):
                cmd = (pid_dir / "cmdline").read_bytes().replace(b"\0", b" ").decode().strip()
            owners.setdefault(int(m.group(1)), (int(pid_dir.name), cmd))
    return owners


def _own_ttys() -> set[str]:
    out = set()
    for fd in (0, 1, 2):
        with contextlib.suppress(OSError):
            out.add(os.ttyname(fd))
    return out


def short_command(cmd: str) -> str:
    """ "cdprhost sim-device" for ``/venv/bin/python /venv/bin/cdprhost sim-device --speedup 1``."""
    words = cmd.split()
    names = [Path(w).name for w in words if not w.startswith("-")]
    keep = [n for n in names if not n.startswith("python")]
    return " ".join(keep[:2]) or (names[0] if names else "")


def pty_choices(
    pts: Path = Path("/dev/pts"), proc: Path = Path("/proc"), exclude: set[str] | None = None
) -> list[PortChoice]:
    """Pseudo-terminals with a program behind them, simulated devices first."""
    exclude = _own_ttys() if exclude is None else exclude
    owners = pty_owners(proc)
    out: list[PortChoice] = []
    for index, (pid, cmd) in sorted(owners.items()):
        path = str(pts / str(index))
        if path in exclude or not os.path.exists(path):
            continue
        simulated = any(w in cmd for w in SIMULATOR_WORDS)
        name = short_command(cmd) or "unknown program"
        label = f"{path}  simulated device" if simulated else f"{path}  pseudo-terminal"
        out.append(PortChoice(path, label, f"{name} (pid {pid})", simulated=simulated))
    out.sort(key=lambda c: (not c.simulated, c.port))
    return out


def serial_choices() -> list[PortChoice]:
    """Serial ports pyserial finds (USB adapters, boards, on-board UARTs)."""
    try:
        from serial.tools import list_ports

        ports = sorted(list_ports.comports(), key=lambda p: p.device)
    except Exception:  # noqa: BLE001 - a broken enumeration must not hide the other ports
        return []
    return [
        PortChoice(p.device, p.device, p.description if p.description != "n/a" else "")
        for p in ports
    ]
