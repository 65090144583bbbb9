"""Fault injection: the ``--faults`` spec and a byte channel that applies it.

Spec keys (comma-separated ``key=value``): ``corrupt`` and ``drop`` (per-byte
probabilities), ``dup`` (probability a written chunk, normally one frame, is sent
twice), ``latency_ms`` and ``jitter_ms`` (delivery delay, uniform jitter on top;
order is preserved as on a real wire), ``reset_after`` / ``stall_after`` (the
device resets / stops answering after N executed segments), ``heater_fail_after``
(device seconds after which the hotend element is disconnected),
``thermistor_open_after`` / ``thermistor_short_after`` (device seconds after which the
hotend's thermistor opens / shorts), ``hotend_start_c`` (the hotend's temperature at
power-on: a printer still warm from a print; not a fault, but the same kind of
scenario for both simulated devices), ``seed``.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, fields
from typing import Any

import numpy as np


class FaultSpecError(ValueError):
    """A ``--faults`` spec that does not parse; the message names the key."""


@dataclass(frozen=True)
class FaultSpec:
    corrupt: float = 0.0
    drop: float = 0.0
    dup: float = 0.0
    latency_ms: float = 0.0
    jitter_ms: float = 0.0
    reset_after: int | None = None
    stall_after: int | None = None
    heater_fail_after: float | None = None
    thermistor_open_after: float | None = None
    thermistor_short_after: float | None = None
    hotend_start_c: float | None = None
    seed: int = 0

    @property
    def lossy(self) -> bool:
        return bool(self.corrupt or self.drop or self.dup)

    @classmethod
    def parse(cls, spec: str | None) -> FaultSpec:
        if not spec:
            return cls()
        known = {f.name: f for f in fields(cls)}
        values: dict[str, Any] = {}
        for part in spec.split(","):
            part = part.strip()
            if not part:
                continue
            key, sep, raw = part.partition("=")
            key = key.strip()
            if not sep:
                raise FaultSpecError(f"'{part}': expected key=value")
            if key not in known:
                raise FaultSpecError(f"unknown key '{key}' (known: {', '.join(known)})")
            try:
                value: float | int = (
                    int(raw) if key in ("reset_after", "stall_after", "seed") else float(raw)
                )
            except ValueError:
                raise FaultSpecError(f"{key}: '{raw}' is not a number") from None
            if not math.isfinite(value):
                raise FaultSpecError(f"{key} must be a finite number, not '{raw}'")
            if key in ("corrupt", "drop", "dup") and not 0.0 <= value <= 1.0:
                raise FaultSpecError(f"{key}: probability {raw} is outside [0, 1]")
            if value < 0:
                raise FaultSpecError(f"{key}: {raw} must not be negative")
            values[key] = value
        return cls(**values)


class FaultyChannel:
    """One direction of a serial wire: optional baud-rate serialisation, then faults.

    ``send(chunk, now)`` schedules delivery; ``receive(now)`` returns every byte due
    by ``now``; ``next_delivery()`` is the next time something becomes due.
    """

    def __init__(
        self, spec: FaultSpec | None = None, *, seed_offset: int = 0, baud: int | None = None
    ):
        self.spec = spec or FaultSpec()
        self.baud = baud
        self._rng = np.random.default_rng([self.spec.seed, seed_offset])
        self._queue: deque[tuple[float, bytes]] = deque()
        self._wire_free = 0.0
        self._last_due = 0.0
        self.bytes_in = 0
        self.corrupted = 0
        self.dropped = 0
        self.duplicated = 0

    def _damage(self, data: bytes) -> bytes:
        s = self.spec
        if not (s.corrupt or s.drop) or not data:
            return data
        arr = np.frombuffer(data, dtype=np.uint8).copy()
        if s.corrupt:
            hit = self._rng.random(arr.size) < s.corrupt
            n = int(hit.sum())
            if n:
                arr[hit] ^= self._rng.integers(1, 256, n, dtype=np.uint8)
                self.corrupted += n
        if s.drop:
            keep = self._rng.random(arr.size) >= s.drop
            self.dropped += int(arr.size - keep.sum())
            arr = arr[keep]
        return arr.tobytes()

    def send(self, data: bytes, now: float) -> None:
        if not data:
            return
        self.bytes_in += len(data)
        copies = 1
        if self.spec.dup and self._rng.random() < self.spec.dup:
            copies = 2
            self.duplicated += 1
        for _ in range(copies):
            start = max(now, self._wire_free)
            done = start + (10.0 * len(data) / self.baud if self.baud else 0.0)
            self._wire_free = done
            delay = self.spec.latency_ms / 1000.0
            if self.spec.jitter_ms:
                delay += self._rng.random() * self.spec.jitter_ms / 1000.0
            due = max(self._last_due, done + delay)
            self._last_due = due
            chunk = self._damage(data)
            if chunk:
                self._queue.append((due, chunk))

    def next_delivery(self) -> float | None:
        return self._queue[0][0] if self._queue else None

    def receive(self, now: float) -> bytes:
        out = bytearray()
        while self._queue and self._queue[0][0] <= now:
            out += self._queue.popleft()[1]
        return bytes(out)

    def clear(self) -> None:
        self._queue.clear()
