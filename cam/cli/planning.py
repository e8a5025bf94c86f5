"""From the options of drill, export, preview and info to a planned job, and its pictures."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Optional

import numpy as np

from ..digitize.digitized import Digitized
from ..digitize.drawing import load_image
from ..digitize.profile import Profile, load_profile, profile_from_expr
from ..motion.chunks import ChunkedPlan, plan_chunks
from ..pins import axis_bits
from ..drive.state import MachineState, read_state
from ..errors import CamError, TravelError
from ..kinds.jobs import JobOptions, PreparedJob, own_zero_home, prepare_job
from ..kinds import has, kind, job_options as kind_job_options, option_kinds
from ..options import Option
from ..job.model import JobLike
from ..render.picture import save_picture, surface_picture, toolpath_picture, toolpath_svg
from ..settings import MachineSettings
from ..verify.pinlog import Motion, carve, decode_writes, pixel_under
from .checks import job_kind_of
from .common import machine_settings, reading_bar
from .machine_state import state_path_of

__all__ = [
    "placed_by_own_zero", "prepare", "summary_of", "job_options", "excellon_digits", "profile_of",
    "write_preview", "write_job_preview", "write_file_job_preview", "carved_surface",
]


def placed_by_own_zero(args: argparse.Namespace) -> bool:
    """Whether the command's drill, HPGL or SVG file is placed by its own zero (--origin file, or --offset without
    --origin): ``cam drill`` then holds the machine before planning and plans the file from the active work zero
    (``args.machine_state``), its travel checked in the machine frame, as it plans a G-code program
    (:func:`cam.kinds.jobs.own_zero_home`)."""
    return own_zero_home(job_kind_of(args) or "", job_options(args)) is not None


def prepare(args: argparse.Namespace, settings: Optional[MachineSettings] = None) -> PreparedJob:
    """The command's file (a drawing, --load-digitized matrix, G-code, drill or HPGL file) planned with its
    options by :func:`cam.kinds.jobs.prepare_job`, the call the web page makes too (progress bar by bytes read)."""
    path = getattr(args, "load_digitized", None) or args.image
    if not path:
        raise CamError(f"{args.command} needs an IMAGE or --load-digitized FILE")
    state = getattr(args, "machine_state", None)  # where it runs (cam drill): G-code, and a drill, HPGL or SVG
    # file placed by its own zero (placed_by_own_zero), or any job levelled to a height map (--level)
    in_place = kind(job_kind_of(args)).runs_in_place if job_kind_of(args) else False  # a G-code program
    if state is None and ((args.command in ("info", "preview") and (in_place or placed_by_own_zero(args)))
                          or (args.command in ("info", "preview", "export") and getattr(args, "level", None))):
        state = _state_to_view(args, settings or machine_settings(args))
    try:
        with reading_bar(args) as progress:
            job = prepare_job(path, job_options(args), settings or machine_settings(args), name=path,
                              progress=progress, machine_state=state)
    except TravelError as exc:
        if state is None or in_place or not placed_by_own_zero(args):
            raise
        raise TravelError(f"{exc}; the file's own zero goes to the {state.active_offset} work zero (machine "
                          f"{list(state.work_zero_steps())} steps): set the work zero elsewhere (cam zero) or "
                          "choose another --origin") from None
    if getattr(args, "load_digitized", None) and args.image:
        drawing = load_image(args.image)
        d = job.digitized
        if (drawing.width_px, drawing.height_px) != (d.width_px, d.height_px):
            raise CamError(f"{args.load_digitized}: matrix is for a {d.width_px}x{d.height_px} image, "
                           f"{args.image} is {drawing.width_px}x{drawing.height_px}")
        job.drawing_rgb = drawing.to_rgb()
    return job


def _state_to_view(args: argparse.Namespace, settings: MachineSettings) -> Optional[MachineState]:
    """The machine state ``cam info`` and ``cam preview`` plan a G-code program in (its work zero and offsets, as
    ``cam drill`` would run it): the state file read, not locked or changed; None when it cannot be read."""
    try:
        return read_state(state_path_of(args), settings)
    except CamError:
        return None


def summary_of(job: PreparedJob) -> str:
    """The job's one-line summary without its file name."""
    return job.summary[len(job.name) + 2:] if job.summary.startswith(f"{job.name}: ") else job.summary


def excellon_digits(args: argparse.Namespace) -> Optional[tuple[int, int]]:
    """--excellon-digits I:F as (I, F) (checked by the parser, :data:`cam.options.OPTIONS`), or None."""
    value = getattr(args, "excellon_digits", None)
    if not value:
        return None
    if isinstance(value, str):
        try:
            a, b = (int(v) for v in value.split(":"))
        except ValueError:
            raise CamError(f"--excellon-digits takes I:F such as 2:4, got '{value}'") from None
        return (a, b)
    return (int(value[0]), int(value[1]))


def _job_value(o: Option, value: Any) -> Any:
    """A flag's parsed value as its JobOptions field holds it (lists as tuples)."""
    if o.type == "points":
        return tuple(tuple(p) for p in value)
    if isinstance(value, list):
        return tuple(value)
    if o.type == "flag":
        return bool(value)
    return value


def job_options(args: argparse.Namespace) -> JobOptions:
    """The command's job options as :class:`cam.kinds.jobs.JobOptions`, one field per flag of
    :data:`cam.options.JOB_OPTIONS`.  The flags were checked against the file's kind by
    :func:`cam.cli.checks.check_args`; a flag given for another kind (``cam export``'s --travel-height and
    --flip-y of every kind, ``cam preview``'s --scale of pictures) is its export or picture meaning, not the
    job's, and leaves the field at its default."""
    kind = job_kind_of(args)
    values: dict[str, Any] = {}
    for o in kind_job_options():
        value = getattr(args, o.dest, None)
        if value is None or value == [] or (kind is not None and kind not in o.kinds):
            continue
        values[o.name] = _job_value(o, value)
    return JobOptions(**values).checked("options")


def profile_of(args: argparse.Namespace, digitized: Digitized) -> Optional[Profile]:
    """The 3D depth profile of --profile or --profile-expr, or None."""
    if args.profile:
        return load_profile(args.profile)
    if args.profile_expr:
        return profile_from_expr(args.profile_expr, max(1, digitized.n_layers))
    return None


def write_job_preview(args: argparse.Namespace, job: PreparedJob, path: str, surface: bool = False) -> None:
    """A prepared job's picture: a drawing's toolpath over it or its cut surface, a file job's preview (a job
    held in memory or made a piece at a time alike, see :func:`write_preview`)."""
    if has(job.kind, "pixels"):
        write_preview(args, job.toolpath, path, surface=surface, drawing_rgb=job.drawing_rgb)
    elif job.kind in option_kinds()["scale"]:  # --scale scaled the drawing (SVG, DXF, HPGL), as in drill
        write_file_job_preview(job, path)
    else:
        write_file_job_preview(job, path, scale=_picture_scale(args))


def write_preview(args: argparse.Namespace, job: JobLike, path: str, surface: bool = False,
                  drawing_rgb: Any = None) -> None:
    """The toolpath picture (.png over the drawing, or .svg) of a drawing's job, or its cut surface (.png).

    ``job`` is any :class:`~cam.job.model.JobLike` and gives the same picture whatever its pieces.  The time in
    the legend is planned from its pieces and the cut surface is carved from its writes a chunk at a time
    (:func:`carved_surface`, bounded memory); the toolpath pictures are drawn from the whole job,
    ``job.joined()`` (memory grows with its moves: the .svg and the picture's lines hold every move).
    """
    scale = _picture_scale(args)
    suffix = Path(path).suffix.lower()
    if suffix not in (".png", ".svg"):
        raise CamError(f"{path}: pictures are written as .png or .svg")
    if surface and suffix != ".png":
        raise CamError(f"{path}: the surface picture is written as .png")
    steps = plan_chunks(job, start_steps=None)  # a picture of the job in its own frame (issue #45 point 4)
    if surface:
        s = carved_surface(job, steps)
        st = job.settings
        legend = (f"cut surface, decoded from the mock pin log: depth 0..{st.px_to_mm_z(int(s.max()) / st.steps_per_px_z):.2f} mm"
                  f" ({int(s.max())} Z steps)")
        save_picture(surface_picture(s, scale=scale, legend=legend), path)
    elif suffix == ".svg":
        save_picture(toolpath_svg(job.joined(), scale=scale, estimated_time_s=steps.estimated_time_s), path)
    else:
        save_picture(toolpath_picture(job.joined(), drawing_rgb=drawing_rgb, scale=scale,
                                      estimated_time_s=steps.estimated_time_s), path)


def carved_surface(job: JobLike, steps: Optional[ChunkedPlan] = None) -> np.ndarray:
    """``(height_px, width_px)`` int64 cut surface of a drawing job, depth in Z steps (drawing frame): its port
    writes (``steps``, None: :func:`cam.motion.chunks.plan_chunks` of it) decoded and carved by a point tool a
    chunk at a time, in bounded memory; the same surface as :func:`cam.drive.runner.simulate_surface` of the
    whole job (tested).

    Each chunk's positions are carved after a row that carries the pixel under the tool before them: a pixel
    centre (never on a border) at the surface, so a border position at the chunk's start keeps that pixel.
    """
    st = job.settings
    spp = st.steps_per_px_xy
    h, w = job.pixels.height_px, job.pixels.width_px
    surface_steps = job.pixels.origin_px[2] * st.steps_per_px_z
    clock, dirbit = axis_bits(st)
    out = np.zeros((h, w), np.int64)
    pos, prev_byte, before = np.zeros(3, np.int64), 0, None
    for chunk in (steps or plan_chunks(job, start_steps=None)).chunks():  # its own frame: nothing moves
        if not len(chunk.data):
            continue
        p, counts = decode_writes(chunk.data, prev_byte, pos, clock, dirbit)
        if before is not None:
            p = np.vstack([before, p])
        np.maximum(out, carve(Motion(chunk.t_ns, p, counts), (h, w), st, origin_px=job.pixels.origin_px), out=out)
        under = [int(pixel_under(p[:, a], spp)[-1]) for a in (0, 1)]
        before = np.array([[under[0] * spp, under[1] * spp, surface_steps]], np.int64)
        pos, prev_byte = p[-1].copy(), int(chunk.data[-1])
    return out


def _picture_scale(args: argparse.Namespace) -> Optional[int]:
    """preview's --scale as picture pixels per drawing pixel: a whole number 1..64, or None."""
    scale = getattr(args, "scale", None)
    if scale is None:
        return None
    if not (1 <= scale <= 64 and float(scale).is_integer()):
        raise CamError(f"--scale must be a whole number 1..64 (picture pixels per drawing pixel), got {scale:g}")
    return int(scale)


def write_file_job_preview(job: Any, path: str, scale: Optional[int] = None) -> None:
    """The job's preview (.png, the picture the web page shows: bounded in size at any resolution), or
    the toolpath of a drill or HPGL job as .svg (from its pieces joined: memory grows with its moves)."""
    suffix = Path(path).suffix.lower()
    if suffix not in (".png", ".svg") or (suffix == ".svg" and job.toolpath is None):
        raise CamError(f"{path}: pictures are written as .png" + (" or .svg" if job.toolpath is not None else ""))
    if suffix == ".png":
        save_picture(job.preview_picture(), path)
    else:  # every move of the job, held in memory or made a piece at a time, joined (the .svg holds each)
        save_picture(toolpath_svg(job.toolpath.joined(), scale=scale, estimated_time_s=job.estimated_time_s), path)
