"""Calibration views: a board held in front of the camera, as a user would for intrinsics.

:func:`view_poses` places the calibration board across the image (a grid of places,
near and far) and tilted about both axes, the way a good calibration is taken
(``coverage="good"``), or only face-on in the middle of the image (``"poor"``: the
set a coverage check must refuse). Poses are in the camera's own frame; every view
shows the whole sheet. ``"printed"`` is what a user with a sheet of paper on a board
gets: the sheet bowed by ``bow_mm``, some views cut by the image's edge, one image corner
(``empty_corner``) never reached, and ``n_lost`` views in which the board cannot be found
(turned almost edge-on to the camera). :func:`render_views` renders them (stored bytes,
one per view).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard, rotation_matrix
from cdprhost.sim.camera.imaging import Imaging, encode, expose
from cdprhost.sim.camera.optics import PinholeCamera
from cdprhost.sim.camera.render import PlacedBoard, Renderer
from cdprhost.sim.camera.scene import CALIBRATION_BOARD

Coverage = Literal["good", "poor", "printed"]


def _facing(tilt_x_deg: float, tilt_y_deg: float) -> np.ndarray:
    """Board -> camera rotation: face toward the camera (board z along the optical axis),
    then tilted about the board's x and y axes."""
    return rotation_matrix((tilt_x_deg, tilt_y_deg, 0.0))


def view_poses(
    camera: PinholeCamera,
    board: CharucoBoard = CALIBRATION_BOARD,
    n_views: int = 18,
    coverage: Coverage = "good",
    seed: int = 0,
    fill: float = 0.45,
    *,
    bow_mm: tuple[float, float] = (0.0, 0.0),
    n_lost: int = 2,
    empty_corner: int = 3,
) -> list[PlacedBoard]:
    """Board placements (camera frame) for ``n_views`` calibration pictures, each showing
    the whole sheet (but ``"printed"``'s, see the module doc; ``empty_corner`` 0..3 is
    top-left, top-right, bottom-left, bottom-right). ``fill``: the board's width as a
    fraction of the image's (at the middle distance)."""
    if coverage == "printed":
        return _printed_poses(camera, board, n_views, seed, fill, bow_mm, n_lost, empty_corner)
    rng = np.random.default_rng(seed)
    w, h = camera.image_size
    fx = camera.matrix[0, 0]
    width_mm = board.size_mm[0]
    base_depth = fx * width_mm / (fill * w)
    eye = PinholeCamera(camera.image_size, camera.matrix, camera.distortion)
    out: list[PlacedBoard] = []
    tries = 0
    while len(out) < n_views and tries < 50 * n_views:
        tries += 1
        if coverage == "good":
            u = rng.uniform(0.12, 0.88) * w
            v = rng.uniform(0.12, 0.88) * h
            k = len(out)
            if k < 4:  # the image's corners first
                u = (0.15 if k % 2 == 0 else 0.85) * w
                v = (0.18 if k < 2 else 0.82) * h
            depth = base_depth * rng.uniform(0.75, 1.3)
            ax = rng.choice([-1.0, 1.0]) * rng.uniform(15.0, 40.0)
            ay = rng.choice([-1.0, 1.0]) * rng.uniform(15.0, 40.0)
            if k % 3 == 2:
                ax *= 0.2
            elif k % 3 == 1:
                ay *= 0.2
        else:
            u = (0.5 + rng.uniform(-0.05, 0.05)) * w
            v = (0.5 + rng.uniform(-0.05, 0.05)) * h
            depth = base_depth * rng.uniform(0.95, 1.05) * 1.4
            ax, ay = rng.uniform(-3.0, 3.0, 2)
        rot = _facing(float(ax), float(ay)) @ rotation_matrix((0.0, 0.0, rng.uniform(-8, 8)))
        half = np.array([board.size_mm[0] / 2, board.size_mm[1] / 2, 0.0])
        for _ in range(12):  # slide toward the image's centre until the sheet fits
            ray = eye.rays(np.array(u), np.array(v))
            centre = np.array([ray[0], ray[1], 1.0]) * depth
            placed = PlacedBoard(board, rot, centre - rot @ half, bow_mm=bow_mm)
            px = eye.project(placed.outline())
            if np.isfinite(px).all() and eye.in_image(px, 8.0).all():
                out.append(placed)
                break
            u, v = u + 0.1 * (w / 2 - u), v + 0.1 * (h / 2 - v)
    return out


def _printed_poses(
    camera: PinholeCamera,
    board: CharucoBoard,
    n_views: int,
    seed: int,
    fill: float,
    bow_mm: tuple[float, float],
    n_lost: int,
    empty_corner: int,
) -> list[PlacedBoard]:
    """A user's views of a bowed sheet (module doc)."""
    rng = np.random.default_rng(seed)
    w, h = camera.image_size
    fx = camera.matrix[0, 0]
    width_mm = board.size_mm[0]
    base_depth = fx * width_mm / (fill * w)
    eye = PinholeCamera(camera.image_size, camera.matrix, camera.distortion)
    half = np.array([board.size_mm[0] / 2, board.size_mm[1] / 2, 0.0])
    corners = [(0.1, 0.12), (0.9, 0.12), (0.1, 0.88), (0.9, 0.88)]
    far = corners[empty_corner]
    out: list[PlacedBoard] = []
    tries = 0
    while len(out) < n_views and tries < 80 * n_views:
        tries += 1
        k = len(out)
        lost = k >= n_views - n_lost
        cut = k % 4 == 3 and not lost  # a view that runs off the image's edge
        u, v = rng.uniform(0.1, 0.9) * w, rng.uniform(0.12, 0.88) * h
        if k < 4 and k != empty_corner:
            u, v = corners[k][0] * w, corners[k][1] * h
        depth = base_depth * rng.uniform(0.8, 1.3)
        ax = rng.choice([-1.0, 1.0]) * rng.uniform(15.0, 40.0)
        ay = rng.choice([-1.0, 1.0]) * rng.uniform(15.0, 40.0)
        if k % 3 == 2:
            ax *= 0.2
        elif k % 3 == 1:
            ay *= 0.2
        if lost:
            ax, ay = 84.0, 0.0  # nearly edge-on: the markers cannot be decoded
        rot = _facing(float(ax), float(ay)) @ rotation_matrix((0.0, 0.0, rng.uniform(-8, 8)))
        if cut:  # push the sheet a third of its width over the nearest side edge
            u = -0.05 * w if u < w / 2 else 1.05 * w
        for _ in range(12):  # slide toward the image's centre until the sheet fits
            ray = eye.rays(np.array(u), np.array(v))
            centre = np.array([ray[0], ray[1], 1.0]) * depth
            placed = PlacedBoard(board, rot, centre - rot @ half, bow_mm=bow_mm)
            px = eye.project(placed.outline())
            if np.isfinite(px).all() and (cut or eye.in_image(px, 8.0).all()):
                break
            u, v = u + 0.1 * (w / 2 - u), v + 0.1 * (h / 2 - v)
        else:
            continue
        # the corner cell left empty: no part of the sheet may reach it
        cell = np.array([far[0] < 0.5, far[1] < 0.5])
        lo = np.where(cell, 0.0, 0.75) * [w, h]
        hi = np.where(cell, 0.25, 1.0) * [w, h]
        if (px.max(axis=0) > lo).all() and (px.min(axis=0) < hi).all():
            continue
        out.append(placed)
    return out


def render_views(
    camera: PinholeCamera,
    imaging: Imaging,
    board: CharucoBoard = CALIBRATION_BOARD,
    n_views: int = 18,
    coverage: Coverage = "good",
    seed: int = 0,
    supersample: int = 2,
    *,
    bow_mm: tuple[float, float] = (0.0, 0.0),
) -> list[bytes]:
    """Stored pictures (``imaging.extension``) of the calibration views."""
    eye = PinholeCamera(camera.image_size, camera.matrix, camera.distortion)
    renderer = Renderer(eye, supersample=supersample, seed=seed + 1)
    rng = np.random.default_rng(seed + 2)
    return [
        encode(expose(renderer.radiance([p]), imaging, rng), imaging)
        for p in view_poses(camera, board, n_views, coverage, seed, bow_mm=bow_mm)
    ]


def tilt_of(placed: PlacedBoard) -> float:
    """How far a placed board is turned from facing the camera (degrees)."""
    return math.degrees(math.acos(float(np.clip(placed.rotation[2, 2], -1.0, 1.0))))
