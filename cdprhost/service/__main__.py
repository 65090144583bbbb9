"""``python -m cdprhost.service --name NAME [--port DEV] [--idle-s S]``: one printer service.

Started detached by a front end (:func:`cdprhost.service.client.attach`), never by hand;
its stdout and stderr go to the service's log beside its socket.
"""

from __future__ import annotations

import argparse
import sys

from cdprhost.logs import configure_logging
from cdprhost.service.paths import ServiceFiles, private_dir
from cdprhost.service.printer_service import PrinterService, ServiceBusy, install_signals


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m cdprhost.service")
    p.add_argument("--name", required=True)
    p.add_argument("--port", default=None)
    p.add_argument("--idle-s", type=float, default=30.0)
    args = p.parse_args(argv)
    if not args.name.replace("-", "").isalnum():
        print(f"--name: not a service name: {args.name!r}", file=sys.stderr)
        return 2
    configure_logging(1)
    service = PrinterService(ServiceFiles(private_dir(), args.name), args.port, idle_s=args.idle_s)
    try:
        service.bind()
    except ServiceBusy:
        print("another service owns this device", file=sys.stderr)
        return 0
    install_signals(service)
    service.serve()
    return 0


if __name__ == "__main__":
    sys.exit(main())
