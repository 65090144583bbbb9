"""Argument types for numeric options: finite, in range, or a clear usage error (exit 2)."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def bounded_float(lo: float, hi: float, *, lo_open: bool = True) -> Callable[[str], float]:
    """An argparse ``type``: a finite number in (lo, hi] (or [lo, hi] with ``lo_open=False``)."""
    bracket = "(" if lo_open else "["

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
        low_ok = value > lo if lo_open else value >= lo
        if not (math.isfinite(value) and low_ok and value <= hi):
            raise argparse.ArgumentTypeError(f"{text} is outside {bracket}{lo:g}, {hi:g}]")
        return value

    return parse


def bounded_int(lo: int, hi: int) -> Callable[[str], int]:
    """An argparse ``type``: an integer in [lo, hi]."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{text} is outside [{lo}, {hi}]")
        return value

    return parse
