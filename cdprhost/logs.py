"""Logging set-up for the shells: stderr at the chosen verbosity, and a log file beside a
job's JSON-lines log. Library modules only ever call ``logging.getLogger(__name__)``."""

from __future__ import annotations

import contextlib
import logging
import os
import sys

FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"
LEVELS = (logging.WARNING, logging.INFO, logging.DEBUG)


def configure_logging(verbosity: int = 0) -> None:
    """Warnings and errors on stderr; ``-v`` adds info, ``-vv`` debug."""
    root = logging.getLogger("cdprhost")
    level = LEVELS[max(0, min(verbosity, len(LEVELS) - 1))]
    root.setLevel(min(level, logging.INFO))  # the job's log file always gets info
    if not any(getattr(h, "_cdprhost_stderr", False) for h in root.handlers):
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("cdprhost: %(levelname)s %(name)s: %(message)s"))
        handler._cdprhost_stderr = True  # type: ignore[attr-defined]
        root.addHandler(handler)
    for h in root.handlers:
        if getattr(h, "_cdprhost_stderr", False):
            h.setLevel(level)


class _QuietFileHandler(logging.FileHandler):
    """A log file that goes quiet, rather than printing tracebacks, once it cannot be
    written (disk full): the job's own log reports that failure."""

    def handleError(self, record: logging.LogRecord) -> None:
        logging.getLogger("cdprhost").removeHandler(self)
        with contextlib.suppress(OSError):
            self.close()


def attach_log_file(path: str | os.PathLike[str], *, quiet: bool = False) -> logging.Handler | None:
    """Also log (info and up) to ``path``; None, with a warning (unless ``quiet``), when it
    cannot be opened.

    A log file is a convenience: failing to open or write one never stops a command."""
    try:
        handler = _QuietFileHandler(path, encoding="utf-8", delay=False)
    except OSError as exc:
        if not quiet:
            logging.getLogger(__name__).warning("no log file %s: %s", path, exc.strerror or exc)
        return None
    handler.setLevel(logging.INFO)
    handler.setFormatter(logging.Formatter(FORMAT))
    logging.getLogger("cdprhost").addHandler(handler)
    return handler


def detach_log_file(handler: logging.Handler | None) -> None:
    if handler is None:
        return
    logging.getLogger("cdprhost").removeHandler(handler)
    with contextlib.suppress(OSError):  # a full disk on the last flush: the job log reports it
        handler.close()
