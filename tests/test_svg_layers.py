"""SVG layers (issue #31 point 6): layers listed with their lengths, chosen and ordered with --layers, a pause
between layers, duplicate segments cut once.

The files are made here in the habits of the programs that write them: an Inkscape 1.x birthday card (the
sodipodi and inkscape namespaces, a named view, layers with transforms and ``style`` attributes, a sublayer,
a hidden layer, a layer with no label), a drawing layered only by stroke colour (Illustrator and online
tools), and a plotter.vision / vpype export (``<line>`` and ``<path>`` segments, many of them repeated, some
reversed, some with the last digit off).  Every cut is checked on the mock: the pin log decoded into
positions, and each position at the cutting depth told to its layer or segment from the geometry written
here.
"""
import math

import numpy as np
import pytest

import cam
from cam.errors import PlanError
from cam.formats.svg import parse_svg
from cam.job.svg import plan_svg, svg_layer_order
from cam.verify.pinlog import read_pin_log

from conftest import SAMPLES, run_cli

S = cam.MachineSettings()
MM = S.mm_per_step_xy

# -- an Inkscape 1.x birthday card: six pens, one line each, 4 mm apart down the page -------------------------

PENS = [("red pen", "#ff0000"), ("orange pen", "#ff6600"), ("yellow pen", "#ffcc00"), ("green pen", "#00aa00"),
        ("blue pen", "#0000ff"), ("violet pen", "#8800aa")]
"""Each layer's label and stroke colour; layer i draws y = 4 + 4 i mm, x 2..(8 + i) mm (lengths differ)."""


def line_y_mm(i: int) -> float:
    return 4.0 + 4.0 * i


def line_len_mm(i: int) -> float:
    return 6.0 + i


def card_svg() -> str:
    """Layer i is translated down by 4 i mm; its path starts at (2, 4).  The last layer's line is drawn as a
    sublayer 'violet pen/outline' of 'violet pen' (which also holds a 2 mm tick of its own).  A hidden layer
    and an empty layer are not cut."""
    layers = []
    for i, (label, colour) in enumerate(PENS[:-1]):
        layers.append(
            f'  <g inkscape:groupmode="layer" id="layer{i + 1}" inkscape:label="{label}" '
            f'transform="translate(0,{4 * i})" style="display:inline">\n'
            f'    <path style="fill:none;stroke:{colour};stroke-width:0.264583px;stroke-linecap:butt;'
            f'stroke-linejoin:miter;stroke-opacity:1" d="m 2,4 h {line_len_mm(i):g}" id="path{i + 1}" '
            f'sodipodi:nodetypes="cc" />\n  </g>\n')
    v = len(PENS) - 1
    layers.append(
        f'  <g inkscape:groupmode="layer" id="layer{v + 1}" inkscape:label="violet pen" '
        f'transform="translate(0,{4 * v})">\n'
        f'    <path style="fill:none;stroke:#8800aa;stroke-width:0.26" d="M 20,4 V 6" id="tick" />\n'
        f'    <g inkscape:groupmode="layer" id="layer{v + 2}" inkscape:label="outline">\n'
        f'      <path style="fill:none;stroke:#8800aa;stroke-width:0.26" d="m 2,4 h {line_len_mm(v):g}" '
        f'id="path{v + 1}" />\n    </g>\n  </g>\n')
    return f"""<?xml version="1.0" encoding="UTF-8" standalone="no"?>
<!-- Created with Inkscape (http://www.inkscape.org/) -->
<svg width="40mm" height="40mm" viewBox="0 0 40 40" version="1.1" id="svg1"
   inkscape:version="1.3.2 (091e20e, 2023-11-25)" sodipodi:docname="birthday-card.svg"
   xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"
   xmlns:sodipodi="http://sodipodi.sourceforge.net/DTD/sodipodi-0.dtd"
   xmlns="http://www.w3.org/2000/svg" xmlns:svg="http://www.w3.org/2000/svg">
  <sodipodi:namedview id="namedview1" pagecolor="#ffffff" bordercolor="#000000" borderopacity="0.25"
     inkscape:showpageshadow="2" inkscape:pageopacity="0.0" inkscape:deskcolor="#d1d1d1"
     inkscape:document-units="mm" inkscape:zoom="4" inkscape:current-layer="layer1" />
  <defs id="defs1" />
  <g inkscape:groupmode="layer" id="layer9" inkscape:label="guides (hidden)" style="display:none">
    <path style="fill:none;stroke:#000000;stroke-width:0.26" d="M 0,0 H 40 V 40" id="hidden1" />
  </g>
  <g inkscape:groupmode="layer" id="layer10" inkscape:label="empty" />
{''.join(layers)}</svg>
"""


CARD_NAMES = [label for label, _ in PENS[:-1]] + ["violet pen", "violet pen/outline"]
"""The card's layers in file order (the order of their first strokes: the tick comes before the sublayer)."""


def write(tmp_path, name: str, text: str):
    p = tmp_path / name
    p.write_text(text)
    return p


def cut_sequence(job: cam.Job, on_pause=None) -> np.ndarray:
    """The ``(K, 2)`` machine (x, y) steps the decoded pin log visits at the cutting depth, in order (repeats of
    one position in a row counted once)."""
    result = cam.run(job, on_pause=on_pause)
    assert result.status == "finished"
    return positions_at_depth(cam.decode_pin_log(result.pin_log(), job.settings), job)


def positions_at_depth(motion: cam.Motion, job) -> np.ndarray:
    pos = motion.position_steps
    depth = int(round(0.5 / S.mm_per_step_z)) if job is None else int(job.points_steps[job.target][:, 2].max())
    assert motion.final_steps == (0, 0, 0)
    at = pos[pos[:, 2] == depth, :2]
    keep = np.ones(len(at), bool)
    keep[1:] = np.any(at[1:] != at[:-1], axis=1)
    return at[keep]


def card_layer_of(xy_steps: np.ndarray) -> np.ndarray:
    """The card layer (index in PENS) each cut position belongs to, from its y (lines are 4 mm apart); the
    violet tick at x = 20 mm is 'violet pen' too.  Planned with offset (0, 0): machine mm = page mm."""
    y_mm = xy_steps[:, 1] * MM
    i = np.rint((y_mm - 4.0) / 4.0).astype(int)
    tick = np.abs(xy_steps[:, 0] * MM - 20.0) < 0.1
    i[tick] = len(PENS) - 1
    return i


def runs(values: np.ndarray) -> list[int]:
    """``values`` with repeats in a row collapsed: the order things were visited in."""
    out: list[int] = []
    for v in values.tolist():
        if not out or out[-1] != v:
            out.append(v)
    return out


def test_info_lists_the_inkscape_layers_with_their_lengths(tmp_path):
    card = write(tmp_path, "birthday-card.svg", card_svg())
    out = run_cli("info", card)
    assert out.returncode == 0, out.stderr
    assert "7 layer(s), Inkscape layers" in out.stdout
    listed = [line.strip() for line in out.stdout.splitlines() if line.startswith("    '")]
    want = [f"'{label}': 1 strokes, {line_len_mm(i):.1f} mm" for i, (label, _) in enumerate(PENS[:-1])]
    want += ["'violet pen': 1 strokes, 2.0 mm", f"'violet pen/outline': 1 strokes, {line_len_mm(5):.1f} mm"]
    assert listed == want
    assert "guides" not in out.stdout and "empty" not in out.stdout  # hidden and empty layers are not cut
    d = parse_svg(card.read_text())
    assert d.layers() == CARD_NAMES and d.layers_from == "inkscape"


def test_info_lists_colour_layers_when_the_file_has_none(tmp_path):
    text = ('<svg xmlns="http://www.w3.org/2000/svg" width="30mm" height="30mm" viewBox="0 0 30 30">'
            '<g fill="none" stroke-width="0.3"><path d="M2,2 H12" stroke="#FF0000"/>'
            '<rect x="2" y="5" width="4" height="3" stroke="blue"/>'
            '<path d="M2,12 H7" style="stroke:rgb(255,0,0)"/><circle cx="20" cy="20" r="2" fill="#000"/></g></svg>')
    out = run_cli("info", write(tmp_path, "colours.svg", text))
    assert out.returncode == 0, out.stderr
    listed = [line.strip() for line in out.stdout.splitlines() if line.startswith("    '")]
    assert listed == ["'#ff0000': 2 strokes, 15.0 mm", "'#0000ff': 1 strokes, 14.0 mm",
                      f"'#000000': 1 strokes, {2 * math.pi * 2:.1f} mm"]
    assert "3 layer(s), by stroke colour" in out.stdout


@pytest.mark.parametrize("chosen", [
    ["blue pen", "red pen"],
    ["violet pen/outline", "green pen", "orange pen"],
    None,
])
def test_layers_choose_and_order_what_is_cut(tmp_path, chosen):
    d = parse_svg(card_svg())
    job = plan_svg(d, offset_mm=(0.0, 0.0), layers=None if chosen is None else ",".join(chosen))
    order = runs(card_layer_of(cut_sequence(job)))
    if chosen is None:  # file order
        assert order == list(range(len(PENS)))
    else:
        want = [[label for label, _ in PENS].index(name.split("/")[0]) for name in chosen]
        assert order == want
    # each chosen line is cut whole: every x step of it at its y
    seq = cut_sequence(job)
    for i in set(order):
        xs = seq[(card_layer_of(seq) == i) & (np.abs(seq[:, 0] * MM - 20) > 0.1), 0]
        x0, x1 = round(2.0 / MM), round((2.0 + line_len_mm(i)) / MM)
        assert set(range(x0, x1 + 1)) <= set(xs.tolist())
    tick = np.abs(seq[:, 0] * MM - 20) < 0.1
    assert tick.any() == (chosen is None)  # the violet pen's own tick only when 'violet pen' is chosen


def test_a_layer_selects_its_sublayers_and_a_colour_any_spelling():
    d = parse_svg(card_svg())
    assert svg_layer_order(d, "violet pen") == [5, 6]
    assert svg_layer_order(d, ["violet pen/outline", "red pen"]) == [6, 0]
    colours = parse_svg('<svg xmlns="http://www.w3.org/2000/svg" width="9mm" height="9mm" viewBox="0 0 9 9">'
                        '<path d="M1,1 H8" stroke="black"/><path d="M1,4 H8" stroke="#f00"/></svg>')
    assert colours.layers() == ["#000000", "#ff0000"]
    assert svg_layer_order(colours, "red,black") == [1, 0]
    job = plan_svg(colours, offset_mm=(0.0, 0.0), layers="rgb(255,0,0)")
    ys = set((cut_sequence(job)[:, 1] * MM).round(1).tolist())
    assert ys == {4.0}  # only the red line


def test_pause_between_layers_names_the_layer_and_stops_above_the_last_cut():
    d = parse_svg(card_svg())
    job = plan_svg(d, offset_mm=(0.0, 0.0), layers="green pen,red pen,blue pen", pause_between_layers=True)
    assert job.pause_notes == ["layer 'red pen': change the pen", "layer 'blue pen': change the pen"]
    pauses = []
    seq = cut_sequence(job, on_pause=lambda pos, note: pauses.append((pos, note)))
    assert [n for _, n in pauses] == job.pause_notes
    order = runs(card_layer_of(seq))
    assert order == [3, 0, 4]
    for (x, y, z), layer_before in zip((p for p, _ in pauses), (3, 0)):
        assert z < 0  # lifted above the surface
        assert round(y * MM) == line_y_mm(layer_before)  # above the layer just finished
    # no pause without the option
    assert plan_svg(d, offset_mm=(0.0, 0.0)).pause_notes == []


def test_cli_prompts_between_layers_and_yes_goes_on(tmp_path):
    card = write(tmp_path, "birthday-card.svg", card_svg())
    pins = tmp_path / "pins.csv"
    out = run_cli("drill", card, "--layers", "yellow pen,red pen", "--pause-between-layers", "--yes",
                  "--offset", "0,0", "--pin-log", pins)
    assert out.returncode == 0, out.stderr
    prompts = [line for line in out.stderr.splitlines() if "going on (--yes)" in line]
    assert len(prompts) == 1 and prompts[0].startswith("layer 'red pen': change the pen: at X=")
    assert "press Enter" not in out.stderr  # nobody is asked to press anything: --yes answers
    seq = positions_at_depth(cam.decode_pin_log(read_pin_log(pins), S), None)
    assert runs(card_layer_of(seq)) == [2, 0]
    # nobody at the keyboard (no --yes, stdin closed): the job stops at the pause, before the red pen's line
    out = run_cli("drill", card, "--layers", "yellow pen,red pen", "--pause-between-layers", "--offset", "0,0")
    assert out.returncode != 0 and "layer 'red pen': change the pen" in out.stderr
    assert "stopping" in out.stderr


def test_a_layer_that_is_not_there_is_a_one_line_error(tmp_path):
    card = write(tmp_path, "birthday-card.svg", card_svg())
    out = run_cli("drill", card, "--layers", "red pen,gold pen", "--pin-log", tmp_path / "pins.csv")
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "no layer 'gold pen'" in lines[0] and "birthday-card.svg" in lines[0]
    assert all(f"'{name}'" in lines[0] for name in CARD_NAMES)
    assert not (tmp_path / "pins.csv").exists()
    with pytest.raises(PlanError, match="the layers are '#000000'"):
        plan_svg(parse_svg('<svg xmlns="http://www.w3.org/2000/svg" width="9mm" height="9mm" viewBox="0 0 9 9">'
                           '<path d="M1,1 H8" stroke="black"/></svg>'), layers="red")


# -- a plotter.vision / vpype export: segments repeated, reversed, off in the last digit --------------------

SEGMENTS_MM = [((2.0, 2.0), (12.0, 2.0)), ((2.0, 5.0), (9.0, 5.0)), ((15.0, 2.0), (15.0, 10.0)),
               ((4.0, 8.0), (11.0, 8.0)), ((2.0, 11.0), (8.0, 11.0))]
"""Horizontal and vertical segments that do not cross, so each one's middle cell is its own."""
COPIES = [3, 1, 2, 4, 2]
"""How many times each is written."""


def export_svg() -> str:
    rng = np.random.default_rng(31)
    items = []
    for n, ((x1, y1), (x2, y2)) in zip(COPIES, SEGMENTS_MM):
        for c in range(n):
            a, b = ((x1, y1), (x2, y2)) if c % 2 == 0 else ((x2, y2), (x1, y1))  # every other copy reversed
            noise = rng.uniform(-2e-4, 2e-4, 4) if c else np.zeros(4)  # a few decimals off, far under a step
            (ax, ay), (bx, by) = np.add(a, noise[:2]), np.add(b, noise[2:])
            if c % 2:
                items.append(f'<line x1="{ax:.4f}" y1="{ay:.4f}" x2="{bx:.4f}" y2="{by:.4f}" />')
            else:
                items.append(f'<path d="M{ax:.4f},{ay:.4f} L{bx:.4f},{by:.4f}" />')
    shuffled = [items[i] for i in rng.permutation(len(items))]
    body = "\n    ".join(shuffled)
    return f"""<?xml version="1.0" encoding="utf-8" ?>
<svg xmlns="http://www.w3.org/2000/svg" xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"
     xmlns:xlink="http://www.w3.org/1999/xlink" width="20mm" height="15mm" viewBox="0 0 20 15">
  <metadata><rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#"/></metadata>
  <g id="layer1" inkscape:groupmode="layer" inkscape:label="1" style="display:inline" fill="none"
     stroke="#000000" stroke-width="0.3">
    {body}
  </g>
</svg>
"""


def visits(seq: np.ndarray) -> list[int]:
    """How many times the cut enters the middle cell of each segment."""
    out = []
    for (x1, y1), (x2, y2) in SEGMENTS_MM:
        mid = np.rint(np.array([(x1 + x2) / 2, (y1 + y2) / 2]) / MM).astype(np.int64)
        out.append(int(np.all(seq == mid, axis=1).sum()))
    return out


def test_duplicate_segments_are_cut_once_and_kept_on_request(tmp_path):
    export = write(tmp_path, "plotter-vision.svg", export_svg())
    d = cam.load_svg(export)
    assert d.n_strokes == sum(COPIES) and d.layers() == ["1"]
    job = plan_svg(d, offset_mm=(0.0, 0.0))
    assert visits(cut_sequence(job)) == [1] * len(SEGMENTS_MM)
    dropped = sum(COPIES) - len(SEGMENTS_MM)
    assert any(w.startswith(f"{dropped} duplicate segment(s)") for w in job.warnings), job.warnings
    kept = plan_svg(d, offset_mm=(0.0, 0.0), keep_duplicates=True)
    assert visits(cut_sequence(kept)) == COPIES
    assert not any("duplicate" in w for w in kept.warnings)
    # the command line: the same, and the warning said
    pins = tmp_path / "pins.csv"
    out = run_cli("drill", export, "--offset", "0,0", "--pin-log", pins)
    assert out.returncode == 0 and f"{dropped} duplicate segment(s)" in out.stderr, out.stderr
    assert visits(positions_at_depth(cam.decode_pin_log(read_pin_log(pins), S), None)) == [1] * len(SEGMENTS_MM)
    out = run_cli("drill", export, "--offset", "0,0", "--pin-log", pins, "--keep-duplicates")
    assert out.returncode == 0, out.stderr
    assert visits(positions_at_depth(cam.decode_pin_log(read_pin_log(pins), S), None)) == COPIES


def test_a_partial_duplicate_leaves_the_rest_of_its_stroke_and_curves_are_compared_piece_by_piece():
    """A polyline that retraces one side of a square and goes on: only the new part is cut; a circle drawn
    twice (a path and a <circle>, flattened alike) is cut once; a stroke made of short pieces is not split."""
    text = ('<svg xmlns="http://www.w3.org/2000/svg" width="30mm" height="30mm" viewBox="0 0 30 30" '
            'fill="none" stroke="black">'
            '<rect x="2" y="2" width="8" height="8"/>'
            '<polyline points="10,10 2,10 2,20"/>'  # the square's bottom side, backwards, then on down
            '<circle cx="20" cy="20" r="4"/><circle cx="20" cy="20" r="4"/>'
            '<polyline points="2,25 2.01,25 2.02,25.01 2.03,25"/></svg>')
    d = parse_svg(text)
    job = plan_svg(d, offset_mm=(0.0, 0.0))
    seq = cut_sequence(job)
    bottom_mid = np.rint(np.array([6.0, 10.0]) / MM).astype(np.int64)
    assert int(np.all(seq == bottom_mid, axis=1).sum()) == 1
    down = np.rint(np.array([2.0, 15.0]) / MM).astype(np.int64)
    assert int(np.all(seq == down, axis=1).sum()) == 1  # the new part is cut
    south = np.rint(np.array([20.0, 24.0]) / MM).astype(np.int64)  # not where the circle starts and ends
    assert int(np.all(seq == south, axis=1).sum()) == 1  # the circle once
    kept = cut_sequence(plan_svg(d, offset_mm=(0.0, 0.0), keep_duplicates=True))
    assert int(np.all(kept == south, axis=1).sum()) == 2
    assert "73 duplicate segment(s)" in job.warnings[-1]  # the circle's 72 pieces and the square's side


def test_the_page_options_reach_the_job(tmp_path):
    """The page sends its form as a mapping (JobOptions.from_mapping): the layers, their pauses (the job's tool
    changes, which the page lists) and the report's layers."""
    from cam.kinds.jobs import JobOptions, prepare_job

    card = write(tmp_path, "birthday-card.svg", card_svg())
    opts = JobOptions.from_mapping({"layers": "blue pen, red pen", "pause_between_layers": "on", "offset_mm": "0,0"})
    job = prepare_job(card, opts)
    assert job.tool_changes == ["layer 'red pen': change the pen"]
    assert [layer["name"] for layer in job.report["layers"]] == CARD_NAMES
    result = cam.run(job.toolpath, on_pause=lambda pos, note: None)
    assert runs(card_layer_of(positions_at_depth(cam.decode_pin_log(result.pin_log(), S), None))) == [4, 0]
    with pytest.raises(cam.CamError, match="does not apply"):
        prepare_job(SAMPLES / "extended.plt", JobOptions(layers="red pen"))


def test_a_segment_in_two_layers_is_cut_by_both_pens():
    """Duplicates are looked for within a layer: the same line in the red and the blue layer is two pens'
    lines, cut in each; a second copy within the blue layer is cut once."""
    text = ('<svg xmlns="http://www.w3.org/2000/svg" width="20mm" height="20mm" viewBox="0 0 20 20" fill="none">'
            '<path d="M2,2 H12" stroke="red"/><path d="M2,2 H12" stroke="blue"/>'
            '<path d="M12,2 H2" stroke="blue"/></svg>')
    job = plan_svg(parse_svg(text), offset_mm=(0.0, 0.0))
    mid = np.rint(np.array([7.0, 2.0]) / MM).astype(np.int64)
    assert int(np.all(cut_sequence(job) == mid, axis=1).sum()) == 2
    assert any(w.startswith("1 duplicate segment(s)") for w in job.warnings)
