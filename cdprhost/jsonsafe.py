"""Plain, JSON-safe values: the one place that turns dataclasses, enums and numpy values
into Python ones and non-finite numbers (which JSON and TOML cannot hold) into None."""

from __future__ import annotations

import dataclasses
import json
import math
from enum import Enum
from typing import Any

import numpy as np


def json_safe(obj: Any, *, drop_none: bool = False) -> Any:
    """``obj`` with every NaN/inf as None, numpy scalars/arrays as Python numbers/lists,
    dataclasses as dicts and enums as their values. ``drop_none``: leave out dict entries
    whose value is None (TOML has no null)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        obj = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        items = ((str(k), json_safe(v, drop_none=drop_none)) for k, v in obj.items())
        return {k: v for k, v in items if not (drop_none and v is None)}
    if isinstance(obj, np.ndarray):
        obj = obj.tolist()
    if isinstance(obj, (list, tuple)):
        return [json_safe(v, drop_none=drop_none) for v in obj]
    if isinstance(obj, Enum):
        return json_safe(obj.value, drop_none=drop_none)
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return finite_or_none(obj)
    return obj


def finite_or_none(x: float | np.floating | None) -> float | None:
    if x is None:
        return None
    value = float(x)
    return value if math.isfinite(value) else None


def dumps(obj: Any, **options: Any) -> str:
    """``json.dumps`` of :func:`json_safe` (never writes NaN or Infinity)."""
    return json.dumps(json_safe(obj), allow_nan=False, **options)
