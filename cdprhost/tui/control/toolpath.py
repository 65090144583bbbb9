"""The moves of a program gathered for the layer preview while another pass reads it.

:class:`ToolpathTap` passes the reader's items through unchanged (the preflight consumes
them) and keeps, per move, its start and end in the plane, line, layer and whether it
extrudes, plus the program's waits for temperature. One read of the file serves both.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Any

import numpy as np

from cdprhost.gcode.items import MoveChunk, MoveKind, SetTemperature
from cdprhost.tui.control.views import Toolpath, Vec3


class ToolpathTap:
    def __init__(self, bed_origin: Vec3 = (0.0, 0.0, 0.0)):
        self.bed_origin = bed_origin
        self._chunks: list[tuple[np.ndarray, ...]] = []
        self._waits: list[tuple[int, str, float]] = []

    def tap(self, items: Iterable[Any]) -> Iterator[Any]:
        for item in items:
            if isinstance(item, MoveChunk) and len(item.line):
                extrude = item.kind == int(MoveKind.EXTRUDE)
                self._chunks.append(
                    (
                        item.start[:, :2].astype(np.float32),
                        item.end[:, :2].astype(np.float32),
                        item.line.astype(np.int64),
                        item.layer.astype(np.int32),
                        extrude,
                        item.end[:, 2].astype(np.float32),
                    )
                )
            elif isinstance(item, SetTemperature) and item.wait and item.target_c > 0:
                self._waits.append((int(item.line), str(item.heater), float(item.target_c)))
            yield item

    def result(self) -> Toolpath:
        if not self._chunks:
            empty2 = np.zeros((0, 2), np.float32)
            return Toolpath(
                empty2,
                empty2,
                np.zeros(0, np.int64),
                np.zeros(0, np.int32),
                np.zeros(0, bool),
                (),
                tuple(self._waits),
                self.bed_origin,
            )
        xy0, xy1, line, layer, extrude, z = (np.concatenate(c) for c in zip(*self._chunks))
        n_layers = int(layer.max()) + 1 if len(layer) else 0
        layer_z = []
        for k in range(n_layers):
            sel = (layer == k) & extrude
            zs = z[sel] if sel.any() else z[layer == k]
            layer_z.append(float(zs.min()) if len(zs) else 0.0)
        return Toolpath(
            xy0, xy1, line, layer, extrude, tuple(layer_z), tuple(self._waits), self.bed_origin
        )
