import numpy as np
import pytest

import cam
from cam.digitize.drawing import BLACK, BLUE, RED, WHITE, classify

from conftest import drawing_from_rows


def rgb(*colours):
    return np.array([colours], np.uint8)


def test_classify_pure_and_noisy_colours():
    px = rgb(
        (255, 255, 255), (0, 0, 0), (255, 0, 0), (0, 0, 255),
        (240, 236, 250),  # JPEG-ish white
        (30, 22, 41),     # JPEG-ish black
        (120, 120, 120),  # anti-aliased grey, dark side -> black
        (150, 150, 150),  # light grey -> white
        (200, 40, 50),    # noisy red
        (30, 40, 210),    # noisy blue
        (255, 190, 190),  # pale anti-aliased red edge -> white (neutral)
    )
    assert classify(px).tolist() == [[WHITE, BLACK, RED, BLUE, WHITE, BLACK, BLACK, WHITE, RED, BLUE, WHITE]]


def test_out_of_palette_names_count_and_pixel():
    img = np.full((4, 5, 3), 255, np.uint8)
    img[2, 3] = (0, 200, 0)
    img[3, 4] = (0, 200, 0)
    img[1, 1] = 0
    with pytest.raises(cam.DrawingError, match=r"2 pixel\(s\).*\(x=3, y=2\).*RGB \(0, 200, 0\)"):
        cam.load_image(img)


def test_rule_warnings_with_coordinates():
    img = drawing_from_rows([
        "#......",
        ".......",
        "..###..",
        "...#...",
        ".......",
        ".....#.",
        ".......",
    ])
    d = cam.load_image(img)
    text = " | ".join(d.warnings)
    assert "more than two black neighbours" in text and "(3, 2)" in text
    assert "border" in text and "(0, 0)" in text
    assert "isolated" in text and "(5, 5)" in text


def test_clean_drawing_has_no_warnings():
    d = cam.load_image(drawing_from_rows([".....", ".###.", "....."]))
    assert d.warnings == []
    assert d.kind == "2d"


def test_empty_drawing_is_an_error():
    with pytest.raises(cam.DrawingError, match="empty"):
        cam.load_image(np.full((5, 5), 255, np.uint8))


def test_rgba_composites_over_white(tmp_path):
    img = np.zeros((5, 5, 4), np.uint8)  # fully transparent = paper
    img[2, 1:4] = (0, 0, 0, 255)
    d = cam.load_image(img)
    assert int(d.black.sum()) == 3


def test_unreadable_and_missing_files(tmp_path):
    bad = tmp_path / "junk.png"
    bad.write_bytes(b"this is not a png")
    with pytest.raises(cam.DrawingError, match="junk.png: not a readable image"):
        cam.load_image(bad)
    with pytest.raises(cam.DrawingError, match="file not found"):
        cam.load_image(tmp_path / "missing.png")


def test_reads_files_in_bgr_order(tmp_path):
    import cv2
    img = np.full((5, 5, 3), 255, np.uint8)
    img[1:4, 1:4] = (0, 0, 255)  # BGR red
    img[1, 1:4] = img[3, 1:4] = img[1:4, 1] = img[1:4, 3] = 0
    cv2.imwrite(str(tmp_path / "r.png"), img)
    d = cam.load_image(tmp_path / "r.png")
    assert d.classes[2, 2] == RED and d.kind == "3d"
