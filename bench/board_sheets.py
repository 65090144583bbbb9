"""Printable boards: how exact the sheets of `cdprhost calibrate boards` are on a raster.

Writes the sample boards for A4 and Letter, rasterises each PDF with PDFium (pypdfium2, the
test extra) at ``--dpi`` and gives the project's own detector the page: corners found of
all, the similarity scale between the corners found and the board's stated geometry as
a ratio to the raster's pixels per mm (0.0 % is exact; the acceptance is 0.1 %), the
worst corner's misfit (px), and the scale bar's measured length against its stated one.
The PNG written at the same DPI is measured the same way.

Run: python bench/board_sheets.py [--dpi 300]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def scale_error(board, image: np.ndarray, dpi: float) -> tuple[int, int, float, float]:
    from cdprhost.calibration.camera.detection import detect_board

    det = detect_board(image, board)
    total = len(board.corners_mm)
    if det is None:
        return 0, total, float("nan"), float("nan")
    mm = board.corners_mm[det.ids, :2]
    mm0, px0 = mm - mm.mean(axis=0), det.corners_px - det.corners_px.mean(axis=0)
    scale = float(np.sqrt((px0**2).sum() / (mm0**2).sum()))
    rot, *_ = np.linalg.lstsq(mm0 * scale, px0, rcond=None)
    misfit = float(np.abs(mm0 * scale @ rot - px0).max())
    return len(det), total, scale / (dpi / 25.4) - 1, misfit


def bar_error(layout, image: np.ndarray, dpi: float) -> float:
    ppmm = dpi / 25.4
    bar = layout.scale_bar
    row = int(round((layout.page_mm[1] - bar.y - bar.height / 2) * ppmm))
    v = image[row].astype(float)
    dark = np.flatnonzero(v < 128)
    i0, i1 = int(dark[0]), int(dark[-1])  # half-grey crossings between pixel centres
    left = i0 - 0.5 + (v[i0 - 1] - 128) / (v[i0 - 1] - v[i0])
    right = i1 + 0.5 + (v[i1] - 128) / (v[i1] - v[i1 + 1])
    return (right - left) / ppmm / layout.scale_bar_mm - 1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dpi", type=int, default=300)
    args = ap.parse_args()
    try:
        import pypdfium2 as pdfium
    except ImportError:
        raise SystemExit(
            "bench/board_sheets.py needs pypdfium2: pip install -e '.[test]'"
        ) from None
    import cv2

    from cdprhost.calibration.camera.printable import PAPERS, sheet_layout
    from cdprhost.cli.board_printing import load_boards
    from cdprhost.cli.main import main as cli

    boards = load_boards(None, None)
    print(f"raster {args.dpi} dpi (PDF by PDFium, PNG as written); scale error = corners vs size")
    print(f"{'sheet':<26}{'corners':>9}{'scale err %':>13}{'misfit px':>11}{'bar err %':>11}")
    with tempfile.TemporaryDirectory() as tmp:
        for paper in PAPERS:
            out = Path(tmp) / paper
            argv = ["calibrate", "boards", "--out", str(out), "--paper", paper]
            with contextlib.redirect_stdout(io.StringIO()):
                code = cli([*argv, "--png-dpi", str(args.dpi)])
            if code:
                raise SystemExit(f"calibrate boards failed ({code})")
            for item in boards:
                layout = sheet_layout(item.board, PAPERS[paper])
                stem = out / f"{item.name}-board-{paper}"
                page = pdfium.PdfDocument(str(stem.with_suffix(".pdf")))[0]
                pdf = page.render(scale=args.dpi / 72, grayscale=True).to_numpy()
                pdf = np.ascontiguousarray(pdf[..., 0] if pdf.ndim == 3 else pdf)
                png = cv2.imread(str(stem.with_suffix(".png")), cv2.IMREAD_GRAYSCALE)
                for kind, image in (("pdf", pdf), ("png", png)):
                    found, total, err, misfit = scale_error(item.board, image, args.dpi)
                    bar = bar_error(layout, image, args.dpi)
                    print(
                        f"{stem.name + '.' + kind:<26}{f'{found}/{total}':>9}{100 * err:>13.4f}"
                        f"{misfit:>11.3f}{100 * bar:>11.4f}"
                    )


if __name__ == "__main__":
    main()
