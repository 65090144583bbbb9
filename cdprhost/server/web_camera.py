"""The web page's camera snapshot: one picture from a camera, as JPEG, when asked.

The camera is named as the calibration wizard names it (``serve --camera 0|FILE|URL``:
a device index, a video or image file, or a stream URL; opened by
:func:`cdprhost.calibration.camera.capture.open_capture`). It is opened for each snapshot
and released at once, so it stays free for the calibration wizard between snapshots.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from cdprhost.errors import InputError

STALE_FRAMES = 2  # frames a device may have buffered before the one asked for
JPEG_QUALITY = 80


class CameraSnapshot:
    def __init__(self, spec: str, open_capture: Callable[[str], Any] | None = None):
        if not spec.strip():
            raise InputError("--camera: empty; give a device index, a file or a URL")
        self.spec = spec
        self._open = open_capture
        self._lock = threading.Lock()  # one picture at a time

    def __call__(self) -> tuple[bytes, str]:
        """Blocking: (JPEG bytes, content type); RuntimeError (or InputError) when the camera
        gives no picture."""
        import cv2

        opener = self._open
        if opener is None:
            from cdprhost.calibration.camera.capture import open_capture

            opener = open_capture
        with self._lock:
            capture = opener(self.spec)
            try:
                ok, frame = capture.read()
                for _ in range(STALE_FRAMES):
                    again, newer = capture.read()
                    if not again:
                        break
                    frame = newer
            finally:
                capture.release()
        if not ok or frame is None:
            raise RuntimeError(f"camera {self.spec!r} gave no picture")
        done, buf = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if not done:
            raise RuntimeError("the picture could not be encoded")
        return buf.tobytes(), "image/jpeg"
