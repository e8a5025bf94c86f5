"""SVG bounded before work (issue #32 points 3 and 5): <use> expansion is counted on the XML tree and refused past
MAX_SVG_ELEMENTS in one line before svgelements expands anything."""
import pytest

from cam.errors import ParseError
from cam.formats.svg import MAX_SVG_ELEMENTS, expanded_size, parse_svg

from conftest import run_cli

HEAD = ('<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="100mm" '
        'height="100mm" viewBox="0 0 100 100">')


def fan_out(levels: int, ways: int = 4) -> str:
    """A path cloned ``ways`` times per level through ``levels`` levels of <use> (``ways ** levels`` copies)."""
    lines = [HEAD, "<defs>", '<path id="l0" d="M1 1 L2 2" stroke="black" fill="none"/>']
    for k in range(1, levels + 1):
        uses = "".join(f'<use xlink:href="#l{k - 1}" x="{i * 0.01}"/>' for i in range(ways))
        lines.append(f'<g id="l{k}">{uses}</g>')
    lines += ["</defs>", f'<use xlink:href="#l{levels}"/>', "</svg>"]
    return "\n".join(lines)


def test_a_ten_level_fan_out_is_refused_from_its_count(tmp_path):
    path = tmp_path / "fan.svg"
    path.write_text(fan_out(10))  # 1.6 kB, 4^10 = 1,048,576 copies: over a minute of cam info before
    assert path.stat().st_size < 2000
    r = run_cli("info", path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert f"expand to more than {MAX_SVG_ELEMENTS:,} elements" in r.stderr


def test_a_moderate_fan_out_is_read_and_counted_exactly():
    text = fan_out(4)  # 256 copies of the path
    drawing = parse_svg(text)
    assert drawing.n_strokes == 4 ** 4
    # svg + defs + the path + 4 levels of (g + 4 uses) + the top use, with each use counting what it copies
    assert expanded_size(text.encode()) > 4 ** 4


def test_a_reference_cycle_is_refused_in_one_line(tmp_path):
    text = HEAD + '<g id="a"><use xlink:href="#b"/></g><g id="b"><use xlink:href="#a"/></g><use xlink:href="#a"/></svg>'
    with pytest.raises(ParseError, match=r"^c\.svg: a <use> refers to an element that holds it \(#a\)"):
        expanded_size(text.encode(), "c.svg")
    with pytest.raises(ParseError):
        expanded_size(fan_out(10).encode(), "fan.svg")
    # a group that uses itself four times over, behind ten levels of fan-out (a fuzzed potrace file): svgelements
    # expanded it for over a minute; now one line at once
    levels = "".join(f'<g id="u{i}">' + f'<use xlink:href="#u{i - 1}"/>' * 4 + "</g>" for i in range(1, 11))
    selfish = HEAD + '<defs><path id="u0" d="M0 0 L1 1"/>' + levels.replace(
        '<g id="u5">', '<g id="u5"><use xlink:href="#u5"/>') + '</defs><use xlink:href="#u10"/></svg>'
    path = tmp_path / "selfish.svg"
    path.write_text(selfish)
    r = run_cli("info", path)
    assert r.returncode == 2 and "reference cycle" in r.stderr and "Traceback" not in r.stderr
