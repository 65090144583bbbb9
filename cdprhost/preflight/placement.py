"""Where a part may go: the allowed region of the build volume and an offset that fits.

For a refused file the report shows the part's extent, the region where every
workspace rule holds at the part's worst height, and an ``--offset X,Y`` that
would fit the part, if one exists. The region is a 1 mm grid over the build
triangle at heights through the part (every 5 mm and both ends); a cell counts
only if its neighbours do too (one cell of margin for the grid). The part is its
outline (`PartExtent.outline`, never smaller than the part); an offset fits when
every outline point lands on an allowed cell at every height. Among the offsets
that fit, the one nearest to the build volume's centre is proposed. Vectorised;
about 0.1 s for a 170 mm machine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.gcode.placement import PartExtent
from cdprhost.kinematics.machine import MachineModel
from cdprhost.preflight.report import PlacementReport, Region

GRID_MM = 1.0
HEIGHT_STEP_MM = 5.0


@dataclass(frozen=True)
class AllowedRegion:
    """Allowed cells (machine frame) of the grid ``xs`` x ``ys`` at every sampled height;
    ``worst_z``: the height with the fewest."""

    xs: np.ndarray
    ys: np.ndarray
    mask: np.ndarray  # (nx, ny): allowed at every height
    worst_z: float
    worst_mask: np.ndarray


def allowed_region(model: MachineModel, z_lo: float, z_hi: float) -> AllowedRegion:
    """Cells allowed at every height in [z_lo, z_hi] (machine frame, mm)."""
    lim = model.limits
    side = lim.build_side
    xs = np.arange(-side / 2, side / 2 + GRID_MM / 2, GRID_MM)
    ys = np.arange(-side / (2 * np.sqrt(3)), side / np.sqrt(3) + GRID_MM / 2, GRID_MM)
    z_lo, z_hi = max(z_lo, lim.z_min), min(max(z_hi, z_lo), lim.z_max)
    n = max(int(np.ceil((z_hi - z_lo) / HEIGHT_STEP_MM)), 0) + 1
    heights = np.linspace(z_lo, z_hi, n)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    all_ok = np.ones(gx.shape, dtype=bool)
    worst, worst_z = None, float(heights[0])
    for z in heights:
        pts = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])
        ok = _eroded(model.check(pts).ok.reshape(gx.shape))
        if worst is None or ok.sum() < worst.sum():
            worst, worst_z = ok, float(z)
        all_ok &= ok
    assert worst is not None
    return AllowedRegion(xs, ys, all_ok, worst_z, worst)


def _eroded(mask: np.ndarray) -> np.ndarray:
    """Cells whose 8 neighbours are allowed too (border cells are not)."""
    out = mask.copy()
    out[0, :] = out[-1, :] = False
    out[:, 0] = out[:, -1] = False
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            out[1:-1, 1:-1] &= mask[
                1 + dx : mask.shape[0] - 1 + dx, 1 + dy : mask.shape[1] - 1 + dy
            ]
    return out


def fit_offset(
    region: AllowedRegion, outline_machine: np.ndarray, target: tuple[float, float] = (0.0, 0.0)
) -> tuple[float, float] | None:
    """Extra X/Y shift (mm, on the grid) that puts every outline point on allowed cells,
    the one bringing the outline's centre nearest to ``target``; None if none fits."""
    if not region.mask.any() or not len(outline_machine):
        return None
    span = outline_machine.max(axis=0) - outline_machine.min(axis=0)
    if not np.isfinite(span).all() or span[0] > np.ptp(region.xs) or span[1] > np.ptp(region.ys):
        return None  # larger than the build volume: nothing to shift
    x0, y0 = region.xs[0], region.ys[0]
    nx, ny = region.mask.shape
    ix = np.rint((outline_machine[:, 0] - x0) / GRID_MM).astype(np.int64)
    iy = np.rint((outline_machine[:, 1] - y0) / GRID_MM).astype(np.int64)
    # shifts (in cells) that keep the outline's box on the grid
    sx = np.arange(-ix.min(), nx - ix.max())
    sy = np.arange(-iy.min(), ny - iy.max())
    if not sx.size or not sy.size:
        return None
    fits = np.ones((sx.size, sy.size), dtype=bool)
    for px, py in zip(ix.tolist(), iy.tolist()):  # outline points: a few hundred
        fits &= region.mask[px + sx[0] : px + sx[-1] + 1, py + sy[0] : py + sy[-1] + 1]
        if not fits.any():
            return None
    cx = (outline_machine[:, 0].min() + outline_machine[:, 0].max()) / 2
    cy = (outline_machine[:, 1].min() + outline_machine[:, 1].max()) / 2
    ax, ay = np.nonzero(fits)
    dx, dy = sx[ax] * GRID_MM, sy[ay] * GRID_MM
    best = int(np.argmin((cx + dx - target[0]) ** 2 + (cy + dy - target[1]) ** 2))
    return (float(dx[best]), float(dy[best]))


def placement_report(
    model: MachineModel,
    extent: PartExtent,
    origin: np.ndarray,
    offset: tuple[float, float],
    *,
    advise: bool,
) -> PlacementReport:
    """The part's extent (G-code frame, placement applied); with ``advise``, the allowed
    region at the worst height and an ``--offset`` that fits (G-code frame)."""
    if extent.empty:
        return PlacementReport(offset=offset, part_min=None, part_max=None)
    lo, hi = extent.lo, extent.hi
    report = PlacementReport(
        offset=(round(offset[0], 3), round(offset[1], 3)),
        part_min=(round(float(lo[0]), 3), round(float(lo[1]), 3), round(float(lo[2]), 3)),
        part_max=(round(float(hi[0]), 3), round(float(hi[1]), 3), round(float(hi[2]), 3)),
    )
    if not advise:
        return report
    region = allowed_region(model, float(lo[2] + origin[2]), float(hi[2] + origin[2]))
    cells = np.argwhere(region.worst_mask)
    if cells.size:
        x = region.xs[cells[:, 0]] - origin[0]
        y = region.ys[cells[:, 1]] - origin[1]
        report.allowed = Region(
            z=round(region.worst_z - float(origin[2]), 3),
            x=(round(float(x.min()), 3), round(float(x.max()), 3)),
            y=(round(float(y.min()), 3), round(float(y.max()), 3)),
            area_mm2=float(cells.shape[0] * GRID_MM * GRID_MM),
        )
    outline = extent.outline() + origin[:2]
    shift = fit_offset(region, outline)
    if shift is not None:
        report.fit_offset = (round(offset[0] + shift[0], 3), round(offset[1] + shift[1], 3))
    return report


@dataclass(frozen=True)
class PrintableBed:
    """What a slicer may use: a polygon (G-code frame, counter-clockwise) that is allowed
    at every height from the bed up to ``height_mm`` (G-code frame)."""

    polygon: tuple[tuple[float, float], ...]
    height_mm: float


def printable_bed(model: MachineModel, origin: np.ndarray, margin_mm: float = 1.0) -> PrintableBed:
    """The build triangle (shrunk about its centre if the bed itself needs it, and by
    ``margin_mm``) and the height up to which all of it passes every workspace rule."""
    lim = model.limits
    inradius = lim.build_side / (2.0 * np.sqrt(3.0)) - margin_mm
    angles = np.deg2rad([90.0, 210.0, 330.0])  # vertex on +y, counter-clockwise
    unit = np.column_stack([np.cos(angles), np.sin(angles)]) * 2.0  # circumradius = 2 r

    def samples(scale: float) -> np.ndarray:
        verts = unit * inradius * scale
        w = np.linspace(0.0, 1.0, 41)
        a, b = np.meshgrid(w, w, indexing="ij")
        keep = a + b <= 1.0
        a, b = a[keep], b[keep]
        return verts[0] + a[:, None] * (verts[1] - verts[0]) + b[:, None] * (verts[2] - verts[0])

    def ok_at(xy: np.ndarray, z: float) -> bool:
        pts = np.column_stack([xy, np.full(len(xy), z)])
        return bool(model.check(pts).ok.all())

    scale = 1.0
    while scale > 0.1 and not ok_at(samples(scale), lim.z_min + 0.2):
        scale -= 0.02
    xy = samples(scale)
    heights = np.arange(lim.z_min, lim.z_max + 1e-9, 1.0)
    pts = np.column_stack([np.tile(xy, (len(heights), 1)), np.repeat(heights, len(xy))])
    good = model.check(pts).ok.reshape(len(heights), len(xy)).all(axis=1)
    bad = np.flatnonzero(~good)
    top = heights[bad[0] - 1] if bad.size else heights[-1]
    verts = unit * inradius * scale - origin[:2]
    polygon = tuple((round(float(x), 3), round(float(y), 3)) for x, y in verts)
    return PrintableBed(polygon, round(float(top - origin[2]), 3))
