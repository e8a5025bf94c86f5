import numpy as np
import pytest

import cam
from cam.digitize.digitized import format_digitized

from conftest import drawing_from_rows

IMG = drawing_from_rows(["........", ".###....", "........", "....###.", "........"])


def test_round_trip_exact(tmp_path):
    d = cam.digitize(IMG, start="min-distance")
    path = tmp_path / "m.txt"
    cam.save_digitized(d, path)
    back = cam.load_digitized(path)
    assert back.mode == "2d" and (back.width_px, back.height_px) == (8, 5)
    assert np.array_equal(back.to_array(), d.to_array())
    text = path.read_text().splitlines()
    assert text[0] == "# cam digitized matrix v1"
    assert text[1] == "# mode=2d width_px=8 height_px=5 objects=2 points=6"
    assert text[2] == "object,x,y,level"
    assert text[3] == "1,1,1,1"


@pytest.mark.parametrize(
    "mangle, line, message",
    [
        (lambda L: L.__setitem__(4, "1,2,x,1"), 5, "expected 4 integers"),
        (lambda L: L.__setitem__(4, "1,2,1"), 5, "4 comma-separated"),
        (lambda L: L.__setitem__(4, "1,99,1,1"), 5, "outside the 8x5 image"),
        (lambda L: L.__setitem__(4, "3,2,1,1"), 5, "count up from 1"),
        (lambda L: L.__setitem__(4, "1,2,1,7"), 5, "level changes within object 1"),
        (lambda L: L.__setitem__(0, "hello"), 1, "not a cam digitized matrix"),
        (lambda L: L.__setitem__(1, "# mode=5d width_px=8 height_px=5 objects=2 points=6"), 2, "mode must be"),
        (lambda L: L.__delitem__(slice(5, 6)), 8, "header says 6 points"),
    ],
)
def test_corrupt_file_names_the_line(tmp_path, mangle, line, message):
    lines = format_digitized(cam.digitize(IMG)).splitlines()
    mangle(lines)
    path = tmp_path / "bad.txt"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(cam.ParseError) as info:
        cam.load_digitized(path)
    assert f"bad.txt:{line}:" in str(info.value)
    assert message in str(info.value)


def test_failed_save_keeps_old_file(tmp_path, monkeypatch):
    path = tmp_path / "m.txt"
    cam.save_digitized(cam.digitize(IMG), path)
    before = path.read_bytes()
    import cam.fileio as fileio

    def broken_replace(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(fileio.os, "replace", broken_replace)
    with pytest.raises(cam.CamError, match="cannot write"):
        cam.save_digitized(cam.digitize(IMG, start="min-distance"), path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["m.txt"]  # no temp file left behind


def test_parse_rejects_binary(tmp_path):
    path = tmp_path / "x.txt"
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(cam.ParseError, match="x.txt:1"):
        cam.load_digitized(path)
