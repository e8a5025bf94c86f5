"""From the options of drill, export, preview and info to a planned job, and its pictures."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Optional

from ..choices import FILE_JOB_SUFFIXES
from ..digitize import digitize
from ..digitize.digitized import Digitized, load_digitized
from ..digitize.drawing import load_image
from ..digitize.profile import Profile, load_profile, profile_from_expr
from ..drive.runner import simulate_surface
from ..drive.steps import plan_steps
from ..errors import CamError
from ..job.jobs import JobOptions, prepare_job
from ..job.drawing import plan
from ..render.picture import save_picture, surface_picture, toolpath_picture, toolpath_svg
from ..settings import MachineSettings
from .common import machine_settings, reading_bar

__all__ = [
    "is_file_job", "prepare_file_job", "job_options", "excellon_digits", "profile_of", "plan_job",
    "write_preview", "write_file_job_preview",
]


def is_file_job(args: argparse.Namespace) -> bool:
    """Whether the IMAGE argument is a G-code, drill or HPGL file (a job already), not a drawing."""
    return bool(getattr(args, "image", None)) and Path(args.image).suffix.lower() in FILE_JOB_SUFFIXES


def prepare_file_job(args: argparse.Namespace, settings: Optional[MachineSettings] = None):
    """A G-code, drill or HPGL file planned with the command's options (progress bar by bytes read)."""
    with reading_bar(args) as progress:
        return prepare_job(args.image, job_options(args), settings or machine_settings(args), name=args.image,
                           progress=progress)


def excellon_digits(args: argparse.Namespace) -> Optional[tuple[int, int]]:
    """--excellon-format I:F as (I, F), or None."""
    if not args.excellon_format:
        return None
    try:
        a, b = (int(v) for v in args.excellon_format.split(":"))
    except ValueError:
        raise CamError(f"--excellon-format takes I:F such as 2:4, got '{args.excellon_format}'") from None
    return (a, b)


def job_options(args: argparse.Namespace) -> JobOptions:
    """The drill command's options for files that are not drawings, as :class:`cam.job.jobs.JobOptions`."""
    return JobOptions(
        drill_depth_mm=args.drill_depth, travel_height_mm=args.travel_height,
        offset_mm=tuple(args.offset) if args.offset else None, mirror_x=args.mirror_x,
        drill_order=args.drill_order, excellon_units=args.excellon_units,
        excellon_digits=excellon_digits(args), excellon_zeros=args.excellon_zeros,
        flip_y=getattr(args, "flip_y", False), depth_mm=getattr(args, "cut_depth", 0.5),
    )


def profile_of(args: argparse.Namespace, digitized: Digitized) -> Optional[Profile]:
    """The 3D depth profile of --profile or --profile-expr, or None."""
    if args.profile:
        return load_profile(args.profile)
    if args.profile_expr:
        return profile_from_expr(args.profile_expr, max(1, digitized.n_layers))
    return None


def _load_job_input(args: argparse.Namespace) -> Digitized:
    if args.load_digitized:
        d = load_digitized(args.load_digitized)
        if args.image:
            drawing = load_image(args.image)
            if (drawing.width_px, drawing.height_px) != (d.width_px, d.height_px):
                raise CamError(
                    f"{args.load_digitized}: matrix is for a {d.width_px}x{d.height_px} image, "
                    f"{args.image} is {drawing.width_px}x{drawing.height_px}"
                )
        return d
    if not args.image:
        raise CamError("drill needs an IMAGE or --load-digitized FILE")
    return digitize(load_image(args.image), start=args.start)


def plan_job(args: argparse.Namespace) -> tuple[Digitized, Any]:
    """The drawing (or saved matrix) digitized and planned with the command's options: (digitized, toolpath)."""
    settings = machine_settings(args)
    if args.passes < 1:
        raise CamError(f"--passes must be >= 1, got {args.passes}")
    digitized = _load_job_input(args)
    depth = args.depth[0] if len(args.depth) == 1 else args.depth
    job = plan(
        digitized, depth=depth, settings=settings, passes=args.passes,
        start_at=tuple(args.start_at), pause_at=[tuple(p) for p in args.pause_at],
        profile=profile_of(args, digitized),
    )
    return digitized, job


def write_preview(args: argparse.Namespace, job: Any, path: str, surface: bool = False) -> None:
    """The toolpath picture (.png over the drawing, or .svg) of a drawing's job, or its cut surface (.png)."""
    if args.scale is not None and not (1 <= args.scale <= 64):
        raise CamError(f"--scale must be 1..64, got {args.scale}")
    suffix = Path(path).suffix.lower()
    if suffix not in (".png", ".svg"):
        raise CamError(f"{path}: pictures are written as .png or .svg")
    time_s = plan_steps(job).estimated_time_s
    if surface:
        if suffix != ".png":
            raise CamError(f"{path}: the surface picture is written as .png")
        s = simulate_surface(job)
        st = job.settings
        legend = (f"cut surface, decoded from the mock pin log: depth 0..{st.px_to_mm_z(int(s.max()) / st.steps_per_px_z):.2f} mm"
                  f" ({int(s.max())} Z steps)")
        save_picture(surface_picture(s, scale=args.scale, legend=legend), path)
    elif suffix == ".svg":
        save_picture(toolpath_svg(job, scale=args.scale, estimated_time_s=time_s), path)
    else:
        rgb = load_image(args.image).to_rgb() if args.image else None
        save_picture(toolpath_picture(job, drawing_rgb=rgb, scale=args.scale, estimated_time_s=time_s), path)


def write_file_job_preview(job: Any, path: str, scale: Optional[int] = None) -> None:
    """The job's preview (.png, the picture the web page shows: bounded in size at any resolution), or
    the toolpath of a drill or HPGL job as .svg."""
    suffix = Path(path).suffix.lower()
    if suffix not in (".png", ".svg") or (suffix == ".svg" and job.toolpath is None):
        raise CamError(f"{path}: pictures are written as .png" + (" or .svg" if job.toolpath is not None else ""))
    if suffix == ".png":
        save_picture(job.preview_picture(), path)
    else:
        save_picture(toolpath_svg(job.toolpath, scale=scale, estimated_time_s=job.estimated_time_s), path)
