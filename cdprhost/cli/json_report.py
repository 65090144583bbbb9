"""A command's ``--json`` report: written atomically, NaN and infinities as null."""

from __future__ import annotations

from typing import Any

from cdprhost.fileio.atomic import write_text_atomic
from cdprhost.jsonsafe import dumps


def write_json(path: str | None, data: dict[str, Any]) -> None:
    if path:
        write_text_atomic(path, dumps(data, indent=2) + "\n")
