"""From light to a stored picture: lens blur, motion blur, sensor noise, gain, gamma, JPEG.

:class:`Imaging` describes one camera's image chain (all optional): a Gaussian lens
spread ``psf_px``, a defocus disc of radius ``defocus_px``, a straight motion smear of
``motion_px`` at ``motion_deg``; a sensor with ``full_well_e`` electrons at white, shot
noise and ``read_noise_e``, exposed at ``light`` (1 = well lit; less is darker, and the
auto gain that brings it back amplifies the noise); gamma 2.2; colour (three channels
with their own noise) or grey; JPEG at ``jpeg_quality`` (None: lossless PNG).
Occluders (polygons in pixels) are painted onto the scene before the lens.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class Imaging:
    psf_px: float = 0.7
    defocus_px: float = 0.0
    motion_px: float = 0.0
    motion_deg: float = 0.0
    full_well_e: float = 8000.0
    read_noise_e: float = 6.0
    light: float = 1.0
    color: bool = True
    jpeg_quality: int | None = 92

    @property
    def extension(self) -> str:
        return ".png" if self.jpeg_quality is None else ".jpg"


def _disc(radius: float) -> np.ndarray:
    r = int(math.ceil(radius))
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    k = np.clip(radius + 0.5 - np.hypot(xx, yy), 0.0, 1.0).astype(np.float32)
    return k / k.sum()


def _line(length: float, degrees: float) -> np.ndarray:
    n = int(math.ceil(length)) | 1
    k = np.zeros((n, n), np.float32)
    c = n // 2
    a = math.radians(degrees)
    for t in np.linspace(-length / 2, length / 2, 4 * n):
        k[int(round(c + t * math.sin(a))), int(round(c + t * math.cos(a)))] += 1.0
    return k / k.sum()


def blur(radiance: np.ndarray, imaging: Imaging) -> np.ndarray:
    out = radiance
    if imaging.psf_px > 0:
        out = cv2.GaussianBlur(out, (0, 0), imaging.psf_px)
    if imaging.defocus_px > 0.3:
        out = cv2.filter2D(out, -1, _disc(imaging.defocus_px), borderType=cv2.BORDER_REFLECT)
    if imaging.motion_px > 0.5:
        kernel = _line(imaging.motion_px, imaging.motion_deg)
        out = cv2.filter2D(out, -1, kernel, borderType=cv2.BORDER_REFLECT)
    return out


def occlude(radiance: np.ndarray, polygons: Sequence[np.ndarray], value: float = 0.12) -> None:
    """Paint ``polygons`` (each (n, 2) pixels) onto the scene, in place."""
    for poly in polygons:
        cv2.fillPoly(radiance, [np.round(poly).astype(np.int32)], float(value))


def expose(radiance: np.ndarray, imaging: Imaging, rng: np.random.Generator) -> np.ndarray:
    """The sensor's 8-bit picture (height, width, 3) or (height, width) of blurred radiance."""
    light = blur(radiance, imaging) * imaging.light
    if imaging.color:
        light = np.repeat(light[..., None], 3, axis=2) * np.array([0.97, 1.0, 1.03], np.float32)
    electrons = light * imaging.full_well_e
    sigma = np.sqrt(np.maximum(electrons, 0.0) + imaging.read_noise_e**2)
    electrons = electrons + rng.standard_normal(electrons.shape, dtype=np.float32) * sigma
    gain = 1.0 / (imaging.full_well_e * max(min(imaging.light, 1.0), 1e-3))  # auto gain
    signal = np.clip(electrons * gain, 0.0, 1.0)
    return np.round(255.0 * signal ** (1 / 2.2)).astype(np.uint8)


def encode(picture: np.ndarray, imaging: Imaging) -> bytes:
    """The picture as stored: JPEG at the imaging's quality, or PNG."""
    if imaging.jpeg_quality is None:
        ok, data = cv2.imencode(".png", picture)
    else:
        ok, data = cv2.imencode(".jpg", picture, [cv2.IMWRITE_JPEG_QUALITY, imaging.jpeg_quality])
    if not ok:  # pragma: no cover - OpenCV always encodes 8-bit images
        raise RuntimeError("image encoding failed")
    return bytes(data.tobytes())


def decode(data: bytes) -> np.ndarray:
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ValueError("not a picture OpenCV can decode")
    return np.asarray(image)
