"""File kinds: one module per kind of input file, registered in one table (issue #48 point 1).

Each kind of file `cam` reads (a drawing, a saved digitized matrix, G-code, an
Excellon drill file, HPGL, SVG, DXF) is one module of this package, which
defines ``KIND``, a :class:`Kind`: how to recognise the file (its suffixes and
a sniffer of its first bytes), what messages call it, its traits (which
options apply to it and which defaults it takes: :mod:`cam.options` declares
every option once, for traits), and its hooks: how to plan it into a job
(:func:`cam.kinds.jobs.prepare_job` calls ``prepare``), what ``cam info`` says
of it, and the exact positions ``cam export`` writes.  The command line
(``cam info``, ``preview``, ``drill``, ``export``, the checks of every flag),
the page and the sniffer work from :data:`KIND_MODULES` alone, so a new kind is
its module and one line in that table (``tests/test_kinds.py`` adds one).

This package is light: the standard library and cam's core modules at import
(``cam --help`` and the sniffer read it before numpy loads); a kind's hooks load
its reader and planner when they are called.
"""
from __future__ import annotations

import importlib
import os
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Optional

from ..errors import CamError
from .. import options as _options
from ..options import Option
from ..options import schema_json as _records
from ..sniff import GENERIC_SUFFIXES, HEAD_BYTES, read_head

__all__ = [
    "KIND_MODULES", "Kind", "Head", "kinds", "kind", "kind_names", "has", "suffixes", "job_kind", "sniff_kind",
    "decide_kind", "forced_kind", "forced_names", "kind_noun", "job_options", "option_kinds", "kind_defaults",
    "schema_json", "register",
]

KIND_MODULES: tuple[str, ...] = (
    "drawing",
    "digitized",
    "gcode",
    "excellon",
    "hpgl",
    "svg",
    "dxf",
)
"""The registry: the modules of :mod:`cam.kinds` that are file kinds, one line each, in the order suffixes are
looked up and kinds are listed."""

TRAITS = ("every", "pixels", "placed", "holes", "strokes", "layers")
"""What options are declared for besides a kind's own name (:attr:`cam.options.Option.traits`): every kind;
drawings in pixels; files placed at the work zero by their extent or their own zero (drill, plotter and vector
files); drill holes; pen strokes (vector files); named layers."""


@dataclass(frozen=True)
class Head:
    """A file's first bytes as the sniffers read them.

    Attributes:
        raw: the bytes, a UTF-8 byte order mark removed.
        text: the bytes as latin-1 text, None when they hold a NUL (binary).
        lines: the non-empty lines of ``text``, stripped and upper case; the last one dropped when the file goes
            on (cut in the middle).
    """

    raw: bytes
    text: Optional[str]
    lines: tuple[str, ...]

    @property
    def plain_text(self) -> bool:
        """Whether the head is text with lines that is not markup (what the line-based sniffers read)."""
        return self.text is not None and bool(self.lines) and not self.text.lstrip().startswith("<")

    @classmethod
    def of(cls, head: bytes, truncated: Optional[bool] = None) -> "Head":
        """The head of a file from its first bytes (``truncated``: it goes on; default when ``head`` is
        :data:`cam.sniff.HEAD_BYTES` long)."""
        if truncated is None:
            truncated = len(head) >= HEAD_BYTES
        raw = head[3:] if head.startswith(b"\xef\xbb\xbf") else head
        if b"\0" in raw:
            return cls(raw, None, ())
        text = raw.decode("latin-1")
        lines = text.splitlines()
        if truncated and lines:
            lines.pop()  # cut in the middle
        return cls(raw, text, tuple(ln.strip().upper() for ln in lines if ln.strip()))


Prepare = Callable[..., Any]
"""``prepare(path, options, settings, *, home, progress, machine_state) -> PreparedJob`` (see
:func:`cam.kinds.jobs.prepare_job`)."""


@dataclass(frozen=True)
class Kind:
    """One kind of input file.

    Attributes:
        name: the kind's name (``job.kind``, ``--kind``'s value unless ``forced_as`` says another).
        noun: what messages call a file of it ("an Excellon drill file").
        title: its name in lists and on the page ("Excellon drill file").
        suffixes: its file name suffixes, lower case with the dot.
        traits: what it is, besides its name (:data:`TRAITS`): which options apply to it and which per-kind
            defaults it takes (:attr:`cam.options.Option.traits`, :attr:`~cam.options.Option.trait_defaults`).
        sniff: whether a file's first bytes (a :class:`Head`) are of this kind; None: by suffix only.
        sniff_rank: the order sniffers are asked in (lower first: the more certain signatures).
        prepare: plans a file of it (:data:`Prepare`).
        info: ``info(path, options, settings, *, prepare, progress) -> dict``: what ``cam info --json`` prints
            (``prepare()``: the file planned where it would run, as the command plans it; ``progress(done,
            total)``: bytes read); None: ``cam info`` does not read it.
        info_lines: ``info_lines(report, name) -> list[str]``: what ``cam info`` prints of that report, the file
            called ``name``.
        exact_geometry: ``(prepared, cut_depth_mm, options) -> (exact_xy_mm, exact_z_mm)`` for ``cam export``
            (:func:`cam.kinds.gcode_export.exact_geometry`); None: its points are the job's own.
        picture: ``picture(prepared) -> (H, W, 3) uint8 RGB array or None``: its preview (the page's and
            ``cam preview``'s picture; a drawing's toolpath over the drawing); None, or a hook returning None: the
            job's moves seen from above (:func:`cam.kinds.jobs.motion_picture`, holes marked on a kind with the
            ``holes`` trait).
        forced_as: its ``--kind`` name (default ``name``).
        job_noun: what placement messages call its job ("drill job"); None: it is not placed at the work zero
            (a G-code program runs in its own work offsets).
        default_origin: the point of its job placed at the work zero when ``--origin`` is not given.
        export_refusal: why ``cam export`` does not write it (G-code is G-code already); None: it does.
        help: one sentence for ``cam drill --help``.
        listed_as: how lists of files in ``--help`` name it (default :attr:`noun`).
    """

    name: str
    noun: str
    title: str
    suffixes: tuple[str, ...]
    traits: frozenset[str]
    prepare: Prepare
    sniff: Optional[Callable[[Head], bool]] = None
    sniff_rank: int = 50
    info: Optional[Callable[..., dict]] = None
    info_lines: Optional[Callable[[dict, str], list[str]]] = None
    exact_geometry: Optional[Callable[..., Any]] = None
    picture: Optional[Callable[[Any], Any]] = None
    forced_as: str = ""
    job_noun: Optional[str] = None
    default_origin: str = "upper-left"
    export_refusal: Optional[str] = None
    help: str = ""
    listed_as: str = ""
    all_traits: frozenset[str] = field(default=frozenset(), init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "all_traits", frozenset(self.traits) | {self.name, "every"})
        if not self.forced_as:
            object.__setattr__(self, "forced_as", self.name)
        if not self.listed_as:
            object.__setattr__(self, "listed_as", self.noun)

    @property
    def runs_in_place(self) -> bool:
        """Whether its job runs from where the tool stands, in the machine state's work offsets (a G-code program),
        instead of being placed at the work zero (no :attr:`job_noun`)."""
        return self.job_noun is None

    def default(self, option: str) -> Any:
        """The value option ``option`` takes on this kind when it is not given (its per-trait default, else its
        default): ``kind("excellon").default("cut_depth_mm")`` is 2.0."""
        return _options_by_name()[option].default_for(self.all_traits)


_EXTRA: list[Kind] = []


def register(new: Kind) -> None:
    """Add a kind at run time, after the table's (a plug-in, or a test proving a new kind needs only its
    module): every list and lookup of this package sees it from then on."""
    if any(k.name == new.name for k in kinds()):
        raise CamError(f"a file kind named {new.name!r} exists already")
    _EXTRA.append(new)


def unregister(name: str) -> None:
    """Remove a kind :func:`register` added."""
    _EXTRA[:] = [k for k in _EXTRA if k.name != name]


@lru_cache(maxsize=None)
def _table() -> tuple[Kind, ...]:
    return tuple(importlib.import_module(f"{__name__}.{m}").KIND for m in KIND_MODULES)


def kinds() -> tuple[Kind, ...]:
    """Every kind, the table's in its order, then those :func:`register` added."""
    return _table() + tuple(_EXTRA)


def kind_names() -> tuple[str, ...]:
    """The kinds' names, in :func:`kinds` order."""
    return tuple(k.name for k in kinds())


def kind(name: str) -> Kind:
    """The kind named ``name``.

    Raises:
        CamError: no kind has that name.
    """
    for k in kinds():
        if k.name == name:
            return k
    raise CamError(f"unknown file kind {name!r} (known: {', '.join(kind_names())})")


def has(name: Optional[str], trait: str) -> bool:
    """Whether kind ``name`` has ``trait`` (or is that kind); False for None or an unknown name."""
    return any(k.name == name and trait in k.all_traits for k in kinds())


def kind_noun(name: str) -> str:
    """What messages call a file of kind ``name`` ("an SVG drawing")."""
    return next((k.noun for k in kinds() if k.name == name), name)


def suffixes() -> dict[str, tuple[str, ...]]:
    """Suffixes of each kind, in :func:`kinds` order (lower case, with the dot)."""
    return {k.name: k.suffixes for k in kinds()}


def forced_names() -> tuple[str, ...]:
    """The values ``--kind`` takes (issue #31 point 1): each kind's :attr:`Kind.forced_as`."""
    return tuple(k.forced_as for k in kinds())


def forced_kind(name: Optional[str]) -> Optional[str]:
    """The kind ``--kind NAME`` forces, or None when not given.

    >>> forced_kind("matrix"), forced_kind(None)
    ('digitized', None)

    Raises:
        CamError: no kind is forced by that name.
    """
    if name is None:
        return None
    for k in kinds():
        if k.forced_as == name:
            return k.name
    raise CamError(f"--kind {name}: not a file kind (one of {', '.join(forced_names())})")


def sniff_kind(head: bytes, *, truncated: Optional[bool] = None) -> Optional[str]:
    """The kind the first bytes of a file show, or None when they show none: each kind's sniffer, in
    :attr:`Kind.sniff_rank` order.

    >>> sniff_kind(b"M48\\nMETRIC\\nT1C0.8\\n%\\nT1\\nX1.0Y2.0\\nM30\\n")
    'excellon'
    >>> sniff_kind(b"IN;SP1;PU0,0;PD100,0;"), sniff_kind(b"G21\\nG1 X1 Y2 F100\\n"), sniff_kind(b"hello")
    ('hpgl', 'gcode', None)
    """
    h = Head.of(head, truncated)
    for k in sorted(kinds(), key=lambda k: k.sniff_rank):
        if k.sniff is not None and k.sniff(h):
            return k.name
    return None


def decide_kind(name: str, suffix_kind: Optional[str], head: Optional[bytes]
                ) -> tuple[Optional[str], Optional[str]]:
    """The kind of a file from its suffix's kind and its first bytes: ``(kind, warning)``.

    A generic suffix (:data:`cam.sniff.GENERIC_SUFFIXES`: none, ``.txt``, ``.nc``, ``.cnc``) or an unknown one:
    the content decides, a generic suffix falling back to its usual kind when the content says nothing; a
    specific suffix whose content is plainly another kind: the content decides, with a warning naming both
    (never a silent misread).

    Args:
        name: the file's name (for the suffix and the warning).
        suffix_kind: the kind its suffix names, or None.
        head: its first bytes, or None when it cannot be read (the suffix decides).
    """
    suffix = Path(name).suffix.lower()
    content = sniff_kind(head) if head else None
    if suffix_kind is None or suffix in GENERIC_SUFFIXES:
        return (content or suffix_kind), None
    if content is None or content == suffix_kind:
        return suffix_kind, None
    said, found = kind_noun(suffix_kind), kind_noun(content)
    return content, f"{name}: the suffix {Path(name).suffix} says {said} but the content is {found}; read as {found}"


def job_kind(path: str | os.PathLike, warnings: Optional[list[str]] = None, *, head: Optional[bytes] = None) -> str:
    """The kind of a file, from its suffix and, when the suffix is generic, unknown or contradicted, its content.

    A readable file's first few kB decide when its suffix is generic or unknown, and when they plainly show
    another kind than its suffix says (then a warning naming both is appended to ``warnings``).  ``head``: the
    file's first bytes when they are at hand (an upload); default: read from ``path`` if it is a file.

    >>> job_kind("board.DRL"), job_kind("part.ngc"), job_kind("gear.png")
    ('excellon', 'gcode', 'drawing')

    Raises:
        CamError: neither the suffix nor the content says (the message names the file and the accepted types).
    """
    suffix = Path(path).suffix.lower()
    by_suffix = next((k.name for k in kinds() if suffix in k.suffixes), None)
    if head is None and (by_suffix is None or Path(path).is_file()):
        head = read_head(path)
    found, warning = decide_kind(Path(path).name, by_suffix, head)
    if warning and warnings is not None:
        warnings.append(warning)
    if found is not None:
        return found
    listed = "; ".join(f"{k} {' '.join(v)}" for k, v in suffixes().items())
    raise CamError(f"{Path(path).name}: unknown file type '{suffix or '(none)'}' (accepted: {listed})")


def job_options() -> tuple[Option, ...]:
    """Every job option (:data:`cam.options.JOB_OPTIONS`) with the kinds it applies to filled in
    (:attr:`~cam.options.Option.kinds`: the kinds having one of its traits), and ``kind``'s choices, the
    ``--kind`` names of :func:`forced_names`."""
    return _resolved(_options.JOB_OPTIONS, kinds())


@lru_cache(maxsize=8)
def _resolved(declared: tuple[Option, ...], every: tuple[Kind, ...]) -> tuple[Option, ...]:
    out = []
    for o in declared:
        o = replace(o, kinds=frozenset(k.name for k in every if o.traits & k.all_traits))
        if o.name == "kind":
            o = replace(o, choices=forced_names())
        out.append(o)
    return tuple(out)


def _options_by_name() -> dict[str, Option]:
    return _by_name(job_options())


@lru_cache(maxsize=8)
def _by_name(options: tuple[Option, ...]) -> dict[str, Option]:
    return {o.name: o for o in options}


def option_kinds() -> dict[str, frozenset[str]]:
    """The kinds each job option applies to, by option name."""
    return {o.name: o.kinds for o in job_options()}


def kind_defaults() -> dict[str, dict[str, Any]]:
    """The values options take on each kind when they are not given, where that depends on the kind
    (:attr:`cam.options.Option.trait_defaults`: the cut depth and travel height of drill, HPGL, SVG and DXF
    files).  ``GET /api/options`` shows them on the page.

    >>> kind_defaults()["excellon"]["cut_depth_mm"]
    2.0
    """
    out: dict[str, dict[str, Any]] = {}
    for k in kinds():
        values = {o.name: o.default_for(k.all_traits) for o in job_options() if o.trait_defaults}
        out[k.name] = {n: v for n, v in values.items() if v is not None and k.name in _options_by_name()[n].kinds}
    return {k: v for k, v in out.items() if v}


def schema_json() -> list[dict[str, Any]]:
    """The option schema as JSON-able records (``GET /api/options``; :func:`cam.options.schema_json` of
    :func:`job_options` with :func:`kind_defaults`)."""
    return _records(job_options(), kind_defaults())


def kinds_json() -> list[dict[str, Any]]:
    """Every kind as JSON-able records for the page (``GET /api/kinds``): name, title, noun, suffixes, its
    ``--kind`` name and traits."""
    return [{"name": k.name, "title": k.title, "noun": k.noun, "suffixes": list(k.suffixes), "forced_as": k.forced_as,
             "traits": sorted(k.all_traits)} for k in kinds()]

