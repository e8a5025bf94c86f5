"""G-code out keeps a job's pauses (issue #31: export dropped them): a drawing's Pause At points and the pauses
between SVG layers are written as ``M0`` with their note, the tool lifted and the spindle stopped first, and
LinuxCNC's interpreter stops the program there; tool changes stay ``T<n> M6`` (LinuxCNC) or a comment and ``M0``
(grbl)."""
from __future__ import annotations

import re

import pytest

from conftest import SAMPLES, run_cli
from support.lcnc import run_rs274
from test_svg_layers import card_svg, write


def test_a_drawings_pause_at_point_is_an_m0_that_rs274_stops_at(tmp_path):
    out = tmp_path / "e.ngc"
    r = run_cli("export", SAMPLES / "ellipse.png", "--depth", "2", "--pause-at", "135,7", "--post", "linuxcnc",
                "--spindle-rpm", "9000", "-o", out)
    assert r.returncode == 0, r.stderr
    assert "1 pause(s)" in r.stdout
    text = out.read_text()
    lines = text.splitlines()
    k = lines.index("M0")
    assert lines[k - 1].startswith("(pause: Pause At")
    assert "M5" in lines[k - 3:k] and any(ln.startswith("G0 Z") for ln in lines[k - 4:k])  # lifted, spindle off
    assert "M3 S9000" in lines[k + 1:]  # the spindle starts again before the next cut
    canon = run_rs274(str(out))
    assert "PROGRAM_STOP" in canon


@pytest.mark.parametrize("post", ["grbl", "linuxcnc"])
def test_pauses_between_svg_layers_are_written(tmp_path, post):
    card = write(tmp_path, "card.svg", card_svg())
    out = tmp_path / "card.ngc"
    r = run_cli("export", card, "--layers", "yellow pen,red pen", "--pause-between-layers", "--post", post,
                "-o", out)
    assert r.returncode == 0, r.stderr
    text = out.read_text()
    pauses = re.findall(r"^\(pause: (.*), then cycle start\)\nM0$", text, re.M)
    assert len(pauses) == 1 and "red pen" in pauses[0], pauses
    if post == "linuxcnc":
        assert "PROGRAM_STOP" in run_rs274(str(out))


def test_without_pauses_there_is_no_m0(tmp_path):
    out = tmp_path / "e.ngc"
    r = run_cli("export", SAMPLES / "ellipse.png", "--depth", "2", "-o", out)
    assert r.returncode == 0, r.stderr
    assert "M0" not in out.read_text().splitlines()


def test_tool_changes_stay_tool_changes_and_a_mill_bit_is_a_pause(tmp_path):
    drl = tmp_path / "slot.drl"
    drl.write_text("M48\nMETRIC\nT1C1.0\nT3C2.0\n%\nT1\nX5.0Y5.0\nX10.0Y5.0G85X15.0Y5.0\nT3\nX30.0Y10.0\nM30\n")
    out = tmp_path / "slot.ngc"
    r = run_cli("export", drl, "--mill-holes-over", "1.5", "--post", "linuxcnc", "-o", out)
    assert r.returncode == 0, r.stderr
    text = out.read_text()
    assert re.search(r"^T1 M6 \(tool change: T1\b", text, re.M), text
    assert re.search(r"^\(pause: tool change: mill bit 1\.500 mm.*\)\nM0$", text, re.M), text
    plt = tmp_path / "pens.plt"
    plt.write_text("IN;SP1;PU0,0;PD400,0;SP2;PU0,400;PD400,400;PU;")
    r = run_cli("export", plt, "--post", "linuxcnc", "-o", out)
    assert r.returncode == 0, r.stderr
    assert re.findall(r"^T(\d) M6", out.read_text(), re.M) == ["1", "2"]
    run_rs274(str(out))


@pytest.mark.parametrize("post", ["grbl", "linuxcnc", "generic"])
def test_after_a_pause_the_program_goes_back_over_the_cut_before_cutting_on(tmp_path, post):
    """Issue #43 point 9: after a pause (M0) the tool may have been moved (a jog, a look at the work); the program
    goes up to the safe height and back over where it stopped with rapids before its next cut."""
    out = tmp_path / "e.ngc"
    r = run_cli("export", SAMPLES / "ellipse.png", "--depth", "2", "--pause-at", "135,7", "--post", post, "-o", out)
    assert r.returncode == 0, r.stderr
    code = [ln for ln in (re.sub(r"\(.*?\)", "", ln).strip() for ln in out.read_text().splitlines()) if ln]
    k = code.index("M0")
    xy = {}
    for ln in code[:k]:  # where the program stood at the pause
        xy.update(re.findall(r"([XY])(-?[\d.]+)", ln))
    after = code[k + 1:]
    assert after[0].startswith("G0 Z") and float(after[0][4:]) > 0, after[:3]  # up to the safe height first
    first_cut = next(i for i, ln in enumerate(after) if ln.startswith(("G1", "G2", "G3")))
    rapids = [dict(re.findall(r"([XY])(-?[\d.]+)", ln)) for ln in after[:first_cut] if ln.startswith("G0 X")]
    assert rapids and rapids[0] == xy, (xy, after[:first_cut + 1])  # back over where it stopped, at the safe height
