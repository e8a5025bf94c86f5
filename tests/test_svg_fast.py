"""The fast SVG reader (issue #32 point 5): the same strokes as svgelements gives, far sooner.

Every document here is read twice: by :func:`cam.formats.svg._parse_fast` (the fast reader, which must take it)
and by :func:`cam.formats.svg._parse_svgelements` (svgelements alone, the reader before); the polylines agree
within 1e-9 mm, with the same closed flags, element and segment counts, layers and page size.  The planner's
compiled steps (:func:`cam.job.svg._cells_many`, :func:`cam.job.svg._order`, the duplicate search) are checked
against the one-stroke numpy version and searches of every stroke or pair.
"""
import math

import numpy as np
import pytest

from conftest import ROOT
from cam.errors import ParseError
from cam.formats import svg as svgmod
from cam.formats.svg import parse_svg
from cam.job import svg as plan
from cam.job._svg_kernels import duplicate_pieces_kernel

NS = 'xmlns="http://www.w3.org/2000/svg" xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"'


def doc(body: str, size: str = 'width="100mm" height="80mm" viewBox="0 0 100 80"') -> bytes:
    return f'<svg {NS} {size}>{body}</svg>'.encode()


def read_both(raw: bytes):
    tree = svgmod._read_tree(raw)
    svgmod._check_walkable(*tree)
    return svgmod._parse_fast(tree[0], "t.svg"), svgmod._parse_svgelements(raw, "t.svg")


def assert_same(fast, old, tol_mm=1e-9):
    assert fast.element_counts == old.element_counts
    assert fast.segment_counts == old.segment_counts
    assert (fast.layer_names, fast.layers_from) == (old.layer_names, old.layers_from)
    assert np.array_equal(fast.layer_of_stroke, old.layer_of_stroke)
    assert np.array_equal(fast.closed, old.closed)
    assert np.allclose(fast.size_mm, old.size_mm, rtol=0, atol=tol_mm)
    a, b = fast.polylines(0.01), old.polylines(0.01)
    assert len(a) == len(b)
    for p, q in zip(a, b):
        assert p.shape == q.shape
        assert np.abs(p - q).max() <= tol_mm


DOCS = {
    "circles in a moved and scaled group": doc(
        '<g transform="translate(3,4) scale(0.5)" fill="black">'
        + "".join(f'<circle cx="{7 * i % 90}" cy="{3 * i}" r="{0.1 + 0.37 * i}"/>' for i in range(20)) + "</g>"),
    "ellipses, stroked and filled": doc(
        '<ellipse cx="50" cy="40" rx="30" ry="10" stroke="red" fill="none"/>'
        '<ellipse cx="10" cy="10" rx="3" ry="7" fill="#00f"/><circle r="2" cx="90" cy="70" stroke="black"/>'),
    "a circle far from the origin (its closing line)": doc(
        '<circle cx="0.001" cy="0.002" r="5000" stroke="black" fill="none"/>', size='viewBox="0 0 9000 9000"'),
    "every path command, absolute and relative": doc(
        '<path d="M10,10 L20,10 H30 V20 h5 v5 l-3,2 C40,40 50,40 50,30 S60,20 70,30 c1,2 3,4 5,6 s2,2 4,0 '
        'Q80,40 85,30 T90,20 q1,1 2,0 t2,0 Z m5,5 l1,1 z M1 1 2 2 3 1" stroke="black" fill="none"/>'),
    "smooth curves after the other kind, numbers run together": doc(
        '<path d="M0 0Q5 5 10 0S20-5 25 0C30 5 35 5 40 0T50 0 60 0M1.5.5.5.5-1-1e1" stroke="#123456"/>'),
    "transforms: matrix, rotate, skew, nested": doc(
        '<g transform="rotate(30 50 40)"><g transform="skewX(10) matrix(1 0.2 -0.1 0.9 5 6)">'
        '<path d="M0,0 C10,0 10,10 20,10" stroke="black" fill="none" transform="scale(1.5,0.7)"/>'
        '<circle cx="5" cy="5" r="3" stroke="black" fill="none"/></g></g>'
        '<circle cx="5" cy="5" r="3" stroke="black" fill="none" transform="scale(-1,1)"/>'),
    "fill only closes an open outline; visibility and display": doc(
        '<path d="M0,0 L10,0 L10,10" fill="green"/><path d="M20,0 L30,0" stroke="none" fill="none"/>'
        '<g visibility="hidden"><path d="M0,50 L9,50" stroke="black"/>'
        '<path d="M0,60 L9,60" stroke="black" visibility="visible"/></g>'
        '<g style="display:none"><circle cx="5" cy="5" r="2" fill="black"/></g>'
        '<circle cx="5" cy="5" r="2" fill="black" display="none"/>'
        '<line x1="0" y1="0" x2="5" y2="5" fill="black"/>'),
    "styles, currentColor, opacity and inheritance": doc(
        '<g style="stroke:#ff0000;fill:none" color="#00ff00"><path d="M0,0 L5,5"/>'
        '<path d="M1,0 L6,5" stroke="currentColor"/><path d="M2,0 L7,5" style="stroke-opacity:0"/>'
        '<circle cx="50" cy="50" r="4" style="fill:currentColor;stroke:none"/>'
        '<path d="M3,0 L8,5" stroke-width="2mm"/></g>'),
    "inkscape layers with other shapes (rect, line, polyline, polygon, arcs)": doc(
        '<g inkscape:groupmode="layer" inkscape:label="Outline"><rect x="1" y="1" width="20" height="10" '
        'stroke="black" fill="none"/><rect x="30" y="1" width="20" height="10" rx="3" stroke="black" fill="none"/>'
        '<g inkscape:groupmode="layer" inkscape:label="Inner"><line x1="0" y1="0" x2="9" y2="9" stroke="blue"/>'
        '<polyline points="0,20 5,25 10,20" stroke="blue" fill="none"/>'
        '<polygon points="20,20 25,25 30,20" stroke="blue"/></g></g>'
        '<path d="M60,60 A10,5 30 1,0 80,60 a5,5 0 0 1 -10,0" stroke="black" fill="none"/>'
        '<circle cx="40" cy="40" r="3" stroke="black"/>'),
    "no viewBox, physical units, metadata and defs": doc(
        '<metadata><x/></metadata><defs><path id="p" d="M0,0 L100,100"/></defs><title>t</title>'
        '<path d="M10,10 L50,10 L50,50" stroke="black" fill="none"/><circle cx="20" cy="20" r="5" fill="black"/>',
        size='width="4in" height="3in"'),
    "a path whose d is left to svgelements (inline close, odd numbers)": doc(
        '<path d="M0,0 L10,10 20z" stroke="black"/><path d="M5 5 L 6" stroke="black"/>'
        '<path d="M0,0 L10,0" stroke="black"/>'),
}


@pytest.mark.parametrize("name", list(DOCS))
def test_the_fast_reader_gives_the_strokes_svgelements_gives(name):
    fast, old = read_both(DOCS[name])
    assert fast.n_strokes > 0 or name.startswith("a path whose")
    assert_same(fast, old)


def test_the_sample_logo_reads_the_same():
    raw = (ROOT / "samples" / "logo.svg").read_bytes()
    assert_same(*read_both(raw))


def random_path(rng: np.random.Generator) -> str:
    parts = [f"M{rng.uniform(-50, 50):.3f},{rng.uniform(-50, 50):.3f}"]
    arity = {"L": 2, "H": 1, "V": 1, "C": 6, "S": 4, "Q": 4, "T": 2, "M": 2}
    for _ in range(rng.integers(1, 12)):
        c = rng.choice(list("LHVCSQTMZ"))
        if c == "Z":
            parts.append(rng.choice(["Z", "z"]))
            continue
        c = c.lower() if rng.random() < 0.5 else c
        nums = rng.uniform(-30, 30, arity[c.upper()] * rng.integers(1, 3))
        parts.append(c + " ".join(f"{v:.4g}" for v in nums))
    return " ".join(parts)


def test_random_paths_and_transforms_read_the_same():
    rng = np.random.default_rng(7)
    for _ in range(60):
        transform = rng.choice(["", ' transform="translate(3,-2)"', ' transform="rotate(17) scale(1.3,0.4)"',
                                ' transform="matrix(0.8,0.3,-0.2,1.1,4,5)"'])
        fill = rng.choice(['fill="none" stroke="black"', 'fill="red"', 'stroke="blue"'])
        fast, old = read_both(doc(f'<path d="{random_path(rng)}" {fill}{transform}/>'))
        assert_same(fast, old)


@pytest.mark.parametrize("body", [
    '<defs><circle id="c" r="2" cx="5" cy="5"/></defs><use href="#c" stroke="black"/>',
    '<style>.a{stroke:red}</style><path class="a" d="M0,0 L5,5"/>',
])
def test_documents_the_fast_reader_leaves_read_as_before(body):
    raw = doc(body)
    with pytest.raises(svgmod._Unsupported):
        svgmod._check_walkable(*svgmod._read_tree(raw))
    assert_same(parse_svg(raw), svgmod._parse_svgelements(raw, "t.svg"))


def test_text_and_bad_coordinates_are_still_one_line_errors():
    with pytest.raises(ParseError, match="convert the text to paths"):
        parse_svg(doc('<circle r="2" fill="black"/><text>hi</text>'))
    with pytest.raises(ParseError, match="not a finite number within 1 km"):
        parse_svg(doc('<circle cx="1e12" r="2" fill="black"/>'))
    with pytest.raises(ParseError, match="not a finite number within 1 km"):
        parse_svg(doc('<path d="M0,0 L1e12,0" stroke="black"/>'))


def test_a_path_not_starting_with_a_move_reads_without_a_traceback():
    d = parse_svg(doc('<path d="L1 2 L5 5 L9 2" stroke="black" fill="none"/>'))
    assert d.n_strokes == 1
    assert np.allclose(d.polylines(0.1)[0], [[1, 2], [5, 5], [9, 2]], atol=1e-4)  # from its first point on


def test_polylines_are_the_segments_flattened_one_by_one():
    d = parse_svg(DOCS["every path command, absolute and relative"] + b"")
    d2 = parse_svg(DOCS["inkscape layers with other shapes (rect, line, polyline, polygon, arcs)"])
    for drawing in (d, d2):
        for tol in (0.5, 0.01, 1e-4):
            one_by_one = [np.concatenate([s[0][:1]] + [svgmod._flatten_segment(seg, tol)[1:] for seg in s])
                          for s in drawing.strokes]
            for p, q in zip(drawing.polylines(tol), one_by_one):
                assert np.array_equal(p, q)


def halftone(n: int, seed: int = 3) -> bytes:
    rng = np.random.default_rng(seed)
    side = math.ceil(math.sqrt(n))
    dots = "".join(f'<circle cx="{i % side * 0.8:.2f}" cy="{i // side * 0.8:.2f}" r="{rng.uniform(0.05, 0.35):.3f}"/>'
                   for i in range(n))
    return doc(f'<g transform="translate(2,2)" fill="black">{dots}</g>', size='width="200mm" height="200mm" '
               'viewBox="0 0 200 200"')


def test_a_halftone_reads_as_before_and_plans():
    raw = halftone(400)
    fast, old = read_both(raw)
    assert_same(fast, old)
    job = plan.plan_svg(parse_svg(raw), cut_depth_mm=0.3)
    assert int(job.target.sum()) > 400


@pytest.mark.slow
def test_a_50000_circle_halftone_reads_and_plans():
    d = parse_svg(halftone(50_000))
    assert d.n_strokes == 50_000 and d.element_counts == {"circle": 50_000}
    assert d.segment_counts["cubic"] == 12 * 50_000
    job = plan.plan_svg(d, cut_depth_mm=0.3)
    starts = np.flatnonzero(job.target[1:] & ~job.target[:-1])
    assert len(starts) >= 50_000 // 2  # strokes touching each other are cut on without a lift


def test_batched_cells_are_the_one_stroke_cells():
    rng = np.random.default_rng(1)
    for _ in range(150):
        polys = []
        for _ in range(rng.integers(1, 8)):
            m = int(rng.integers(1, 12))
            kind = rng.integers(0, 4)
            if kind == 0:
                p = rng.normal(0, 3, (m, 2))
            elif kind == 1:
                p = rng.integers(0, 4, (m, 2)).astype(float)
            elif kind == 2:
                p = np.cumsum(rng.normal(0, 0.4, (m, 2)), axis=0)
            else:
                a = np.linspace(0, 2 * np.pi, m + 1)
                p = np.c_[5 + rng.uniform(0.2, 20) * np.cos(a), 5 + rng.uniform(0.2, 20) * np.sin(a)]
            polys.append(p)
        for got, want in zip(plan._cells_many(polys), [plan._cells(p) for p in polys], strict=True):
            assert np.array_equal(got, want)


def test_batched_cells_of_long_strokes_and_repeated_vertices():
    """Strokes of thousands of positions (the compiled pass grows its buffers), single points between them, and
    vertices repeated (zero-length segments) or on a staircase."""
    rng = np.random.default_rng(2)
    for _ in range(30):
        polys = []
        for _ in range(int(rng.integers(1, 6))):
            m = int(rng.integers(1, 400))
            walk = [rng.normal(0, 3, (m, 2)), rng.integers(-3, 4, (m, 2)).astype(float), rng.normal(0, 0.7, (m, 2)),
                    np.repeat(rng.normal(0, 2, (m, 2)), 2, axis=0)][int(rng.integers(0, 4))]
            polys.append(np.cumsum(walk, axis=0) + rng.uniform(-100, 100, 2))
        for got, want in zip(plan._cells_many(polys), [plan._cells(p) for p in polys], strict=True):
            assert np.array_equal(got, want)


def duplicates_by_search(a, b, near):
    """Which pieces trace an earlier piece that is kept, by comparing every pair (the rule of
    :func:`cam.job._svg_kernels.duplicate_pieces_kernel`)."""
    gone = np.zeros(len(a), bool)
    for h in range(1, len(a)):
        fwd = np.all(np.abs(a[:h] - a[h]) <= near, axis=1) & np.all(np.abs(b[:h] - b[h]) <= near, axis=1)
        rev = np.all(np.abs(b[:h] - a[h]) <= near, axis=1) & np.all(np.abs(a[:h] - b[h]) <= near, axis=1)
        gone[h] = np.any((fwd | rev) & ~gone[:h])
    return gone


@pytest.mark.parametrize("spread", [0.3, 2.0, 1e6])
def test_the_duplicate_search_is_the_search_of_every_pair(spread):
    rng = np.random.default_rng(int(spread * 10))
    for _ in range(40):
        k = int(rng.integers(1, 300))
        a = np.round(rng.uniform(0, spread, (k, 2)) * 8) / 8  # ends on the cells' edges too
        b = a + rng.choice([0.0, 0.125, 0.25, 0.375, 1.0], (k, 2)) * rng.choice([-1, 1], (k, 2))
        swap = rng.random(k) < 0.5
        a[swap], b[swap] = b[swap].copy(), a[swap].copy()
        chain = rng.normal(0, 0.1, (k, 2)).cumsum(axis=0)  # runs of pieces each near the one before
        if rng.random() < 0.5:
            a, b = a + chain, b + chain
        got = duplicate_pieces_kernel(np.ascontiguousarray(a), np.ascontiguousarray(b), 0.25)
        assert np.array_equal(got, duplicates_by_search(a, b, 0.25))


def order_by_search(strokes, at=None):
    """The cutting order as a search of every stroke at every step finds it (the order before the KD-tree)."""
    starts = np.array([s[0] for s in strokes], float)
    ends = np.array([s[-1] for s in strokes], float)
    left = np.ones(len(strokes), bool)
    at = np.zeros(2) if at is None else np.asarray(at, float)
    out = []
    for _ in range(len(strokes)):
        ds, de = np.hypot(*(starts - at).T), np.hypot(*(ends - at).T)
        ds[~left] = de[~left] = np.inf
        i = int(np.argmin(np.minimum(ds, de)))
        left[i] = False
        out.append(strokes[i][::-1] if de[i] < ds[i] else strokes[i])
        at = out[-1][-1].astype(float)
    return out


@pytest.mark.parametrize("span", [3, 10, 1000])
def test_the_cutting_order_is_the_nearest_stroke_search(span):
    rng = np.random.default_rng(span)
    for _ in range(40):
        strokes = [rng.integers(0, span, (int(rng.integers(1, 4)), 2)) for _ in range(int(rng.integers(1, 150)))]
        at = [None, np.array([-5.0 * span, 2.0]), rng.uniform(0, span, 2)][int(rng.integers(0, 3))]
        got, want = plan._order(strokes, at), order_by_search(strokes, at)
        assert len(got) == len(want)
        assert all(np.array_equal(g, w) for g, w in zip(got, want))
