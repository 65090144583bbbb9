"""`cdprhost calibrate boards`: the sheets a user prints. Each PDF, rasterised by another
renderer (PDFium), must give the project's own detector every inner corner at the
board's stated size within 0.1 %, its scale bar its stated length; the PNG the same at
its stated DPI; a board too large for the paper is refused with the size it needs."""

from __future__ import annotations

import tomllib
from pathlib import Path

import cv2
import numpy as np
import pypdfium2 as pdfium
import pytest
from PIL import Image

from cdprhost.calibration.camera.boards import CharucoBoard
from cdprhost.calibration.camera.config import CameraConfig
from cdprhost.calibration.camera.detection import detect_board
from cdprhost.calibration.camera.printable import (
    MM_PER_INCH,
    PAPERS,
    DoesNotFit,
    board_pixels,
    board_rectangles,
    sheet_layout,
)
from cdprhost.cli.board_printing import load_boards, sample_text
from cdprhost.cli.main import main

DPI = 300
NAMES = ("reference", "effector", "calibration")


@pytest.fixture(scope="module", params=["a4", "letter"])
def sheets(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(f"boards-{request.param}")
    assert main(["calibrate", "boards", "--out", str(out), "--paper", request.param]) == 0
    return request.param, out


def _raster(pdf_path: Path, dpi: int) -> np.ndarray:
    page = pdfium.PdfDocument(str(pdf_path))[0]
    img = page.render(scale=dpi / 72, grayscale=True).to_numpy()
    return np.ascontiguousarray(img[..., 0] if img.ndim == 3 else img)


def _scale_px_per_mm(board: CharucoBoard, image: np.ndarray) -> tuple[float, int, int]:
    """The similarity scale between the board's corners (mm) and where the detector finds
    them in ``image``, and how many corners were found of how many."""
    det = detect_board(image, board)
    assert det is not None, "board not found"
    mm = board.corners_mm[det.ids, :2]
    px = det.corners_px
    mm0, px0 = mm - mm.mean(axis=0), px - px.mean(axis=0)
    scale = float(np.sqrt((px0**2).sum() / (mm0**2).sum()))
    # a similarity explains the corners to a small fraction of a pixel: nothing is skewed
    rot, *_ = np.linalg.lstsq(mm0 * scale, px0, rcond=None)
    assert np.abs(mm0 * scale @ rot - px0).max() < 0.3
    return scale, len(det), len(board.corners_mm)


def _boards() -> dict[str, CharucoBoard]:
    return {b.name: b.board for b in load_boards(None, None)}


@pytest.mark.parametrize("name", NAMES)
def test_pdf_raster_has_every_corner_at_the_stated_size(sheets, name):
    paper, out = sheets
    board = _boards()[name]
    image = _raster(out / f"{name}-board-{paper}.pdf", DPI)
    scale, found, total = _scale_px_per_mm(board, image)
    assert found == total
    assert abs(scale / (DPI / MM_PER_INCH) - 1) < 1e-3


@pytest.mark.parametrize("name", NAMES)
def test_pdf_page_and_scale_bar_are_their_stated_size(sheets, name):
    paper, out = sheets
    layout = sheet_layout(_boards()[name], PAPERS[paper])
    dpi = 600  # PDFium fills thin shapes without antialiasing, to whole pixels: finer pixels
    image = _raster(out / f"{name}-board-{paper}.pdf", dpi)
    ppmm = dpi / MM_PER_INCH
    page_w, page_h = layout.page_mm
    assert abs(image.shape[1] - page_w * ppmm) <= 1 and abs(image.shape[0] - page_h * ppmm) <= 1
    bar = layout.scale_bar
    row = int(round((page_h - bar.y - bar.height / 2) * ppmm))
    left, right = _dark_extent_px(image[row].astype(float))
    assert abs((right - left) / ppmm / layout.scale_bar_mm - 1) < 1e-3
    # nothing else on that row: the bar is where the layout says
    assert left / ppmm == pytest.approx(bar.x, abs=0.2)


def _dark_extent_px(row: np.ndarray) -> tuple[float, float]:
    """Where a row's ink begins and ends, to a fraction of a pixel: the half-grey crossing
    interpolated between the pixel centres on either side of the outermost dark pixels."""
    dark = np.flatnonzero(row < 128)
    i0, i1 = int(dark[0]), int(dark[-1])
    left = i0 - 0.5 + (row[i0 - 1] - 128) / (row[i0 - 1] - row[i0])
    right = i1 + 0.5 + (row[i1] - 128) / (row[i1] - row[i1 + 1])
    return left, right


def test_png_is_at_the_stated_dpi_with_every_corner(tmp_path):
    dpi = 200
    assert main(["calibrate", "boards", "--out", str(tmp_path), "--png-dpi", str(dpi)]) == 0
    board = _boards()["effector"]
    png = tmp_path / "effector-board-a4.png"
    with Image.open(png) as im:
        assert im.info["dpi"] == pytest.approx((dpi, dpi), abs=0.01)
        assert abs(im.size[0] - 210 / MM_PER_INCH * dpi) <= 1
        assert abs(im.size[1] - 297 / MM_PER_INCH * dpi) <= 1
    image = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    scale, found, total = _scale_px_per_mm(board, image)
    assert found == total
    assert abs(scale / (dpi / MM_PER_INCH) - 1) < 1e-3


def test_the_tables_written_describe_the_boards_printed(sheets):
    _, out = sheets
    text = (out / "boards.toml").read_text()
    camera = tomllib.loads(text)["camera"]  # a whole [camera] section
    config = CameraConfig.model_validate(camera)
    boards = _boards()
    assert config.reference_board.board() == boards["reference"]
    assert config.effector_board.board() == boards["effector"]
    assert config.calibration_board is not None
    assert config.calibration_board.board() == boards["calibration"]
    assert "measure after mounting" in text


def test_the_shipped_sample_is_a_valid_camera_section():
    config = CameraConfig.model_validate(tomllib.loads(sample_text())["camera"])
    assert config.calibration_board is not None
    for board in (config.reference_board, config.effector_board, config.calibration_board):
        for paper in PAPERS.values():
            sheet_layout(board.board(), paper)  # every sample board fits A4 and Letter


def test_a_board_larger_than_the_paper_is_refused_with_the_size_it_needs(tmp_path, capsys):
    config = tmp_path / "big.toml"
    config.write_text("[camera.calibration_board]\nsquares = [12, 9]\nsquare_mm = 25.0\n")
    config.write_text(config.read_text() + "marker_mm = 18.0\n")
    out = tmp_path / "out"
    code = main(["calibrate", "boards", "--config", str(config), "--out", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    assert "does not fit A4" in err and "300 x 225 mm" in err and "needs 312.0 x 265.0 mm" in err
    assert not out.exists()  # nothing written
    with pytest.raises(DoesNotFit) as exc:
        sheet_layout(CharucoBoard((12, 9), 25.0, 18.0), PAPERS["letter"])
    assert exc.value.need_mm == pytest.approx((312.0, 265.0))


def test_landscape_only_when_portrait_does_not_fit():
    small = sheet_layout(CharucoBoard((5, 4), 16.0, 12.0), PAPERS["a4"])
    wide = sheet_layout(CharucoBoard((9, 6), 25.0, 18.0), PAPERS["a4"])
    assert not small.landscape and wide.landscape
    for layout in (small, wide):
        page_w, page_h = layout.page_mm
        b = layout.board
        assert b.x >= 10 and b.x + b.width <= page_w - 10
        assert layout.scale_bar.y >= 10 and layout.title_xy[1] <= page_h - 10


def test_the_rectangles_redraw_the_boards_pixels_exactly():
    board = CharucoBoard((5, 4), 16.0, 12.0, first_marker_id=100)
    img = board_pixels(board, 150.0)
    pitch = board.square_mm / (img.shape[1] // 5)
    redrawn = np.zeros(img.shape, dtype=bool)
    for x, y, w, h in np.rint(board_rectangles(board, 150.0) / pitch).astype(int):
        redrawn[y : y + h, x : x + w] = True
    assert np.array_equal(redrawn, img < 128)


def test_colliding_marker_ids_are_refused(tmp_path, capsys):
    config = tmp_path / "s.toml"
    config.write_text(
        "[camera.effector_board]\nsquares = [5, 4]\nsquare_mm = 16.0\nmarker_mm = 12.0\n"
        "first_marker_id = 100\noffset = [0.0, 0.0, 50.0]\n"
        "[camera.calibration_board]\nsquares = [9, 6]\nsquare_mm = 25.0\nmarker_mm = 18.0\n"
        "first_marker_id = 105\n"
    )
    code = main(["calibrate", "boards", "--config", str(config), "--out", str(tmp_path / "o")])
    assert code == 2
    assert "share marker ids" in capsys.readouterr().err
