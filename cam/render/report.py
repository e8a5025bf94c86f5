"""Reports: the image property report (thesis 4.2.2) and the job report (JSON)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Optional

import cv2
import numpy as np

from ..settings import DEFAULT_SETTINGS, MachineSettings

if TYPE_CHECKING:  # names in annotations only: render sits below digitize and job (tests/test_layers.py)
    from ..digitize.digitized import Digitized
    from ..job.model import Job

__all__ = ["image_report", "job_report", "format_report"]


def image_report(digitized: Digitized, settings: MachineSettings = DEFAULT_SETTINGS) -> dict[str, Any]:
    """Image property report: size of what will be cut in pixels and mm (Eq. 4.1), object count, warnings.

    ``width_px``/``height_px`` are the extent of the traced pixels (the
    material block needed), not the image size, which is ``image_width_px``/``image_height_px``.
    """
    x0, y0, x1, y1 = digitized.bounding_box_px()
    width_px, height_px = x1 - x0 + 1, y1 - y0 + 1
    rep: dict[str, Any] = {
        "mode": digitized.mode,
        "objects": len(digitized.objects),
        "image_width_px": digitized.width_px,
        "image_height_px": digitized.height_px,
        "width_px": width_px,
        "height_px": height_px,
        "width_mm": round(settings.px_to_mm_xy(width_px), 4),
        "height_mm": round(settings.px_to_mm_xy(height_px), 4),
        "points": digitized.n_points,
        "warnings": list(digitized.warnings),
    }
    if digitized.mode == "3d":
        drawn = np.zeros((digitized.height_px, digitized.width_px), np.uint8)
        for obj in digitized.objects:
            drawn[obj[:, 1], obj[:, 0]] = 1
        rep["objects"] = _components(drawn) - 1
        rep["rings"] = len(digitized.objects)
        rep["layers"] = digitized.n_layers
    return rep


def _components(mask_hw: np.ndarray) -> int:
    """The number of 8-connected components of a ``(H, W)`` uint8 mask, its background included: labelled in 16
    bits (half the memory of 32: 33 MB at 4096^2), in 32 when there are more labels than 16 bits hold (OpenCV
    refuses the 16-bit labelling then)."""
    try:
        return int(cv2.connectedComponents(mask_hw, connectivity=8, ltype=cv2.CV_16U)[0])
    except cv2.error:
        return int(cv2.connectedComponents(mask_hw, connectivity=8, ltype=cv2.CV_32S)[0])


def job_report(
    digitized: Optional[Digitized], toolpath: Job, plan: Any
) -> dict[str, Any]:
    """The JSON job report: image report plus depth, points, retracts, steps, time and the speed ramp mode.

    ``plan`` is the :class:`~cam.motion.steps.StepPlan` of ``toolpath``.
    """
    s = toolpath.settings
    rep: dict[str, Any] = image_report(digitized, s) if digitized is not None else {"warnings": []}
    depth_px = 0
    if toolpath.height_px and toolpath.n_targets:
        depth_px = int(toolpath.deepest_px)
    rep.update(
        {
            "depth_px": depth_px,
            "depth_mm": round(s.px_to_mm_z(depth_px), 4),
            "points": toolpath.n_targets,
            "retracts": toolpath.n_retracts,
            "steps": {axis: int(v) for axis, v in zip("xyz", plan.steps_total)},
            "estimated_time_s": round(plan.estimated_time_s, 6),
            "ramp": plan.settings.ramp,
        }
    )
    tool = getattr(toolpath, "tool", None)
    if tool is not None:
        rep["tool"] = tool.describe()
        if digitized is not None and digitized.mode != "3d":  # an engraved line's width follows its depth
            rep["line_width_mm"] = round(tool.width_at_depth_mm(s.px_to_mm_z(depth_px)), 4)
    rep["warnings"] = list(rep.get("warnings", [])) + [w for w in toolpath.warnings if w not in rep["warnings"]]
    return rep


def format_report(rep: dict[str, Any]) -> str:
    """Human-readable lines of a report."""
    lines = [
        f"objects:    {rep['objects']}" + (f"  (rings: {rep['rings']}, layers: {rep['layers']})" if "layers" in rep else ""),
        f"size:       {rep['width_px']} x {rep['height_px']} px = {rep['width_mm']:.2f} x {rep['height_mm']:.2f} mm"
        f"  (image {rep['image_width_px']} x {rep['image_height_px']} px)",
        f"points:     {rep['points']}",
    ]
    if "depth_mm" in rep:
        lines.append(f"depth:      {rep['depth_px']} Z px = {rep['depth_mm']:.3f} mm")
    if "tool" in rep:
        width = f", lines {rep['line_width_mm']:.3f} mm wide" if "line_width_mm" in rep else ""
        lines.append(f"tool:       {rep['tool']}{width}")
    if "steps" in rep:
        lines.append(f"retracts:   {rep['retracts']}")
        st = rep["steps"]
        lines.append(f"steps:      X {st['x']}  Y {st['y']}  Z {st['z']}")
        ramp = f"  ({rep['ramp']} ramps)" if "ramp" in rep else ""
        lines.append(f"time:       {rep['estimated_time_s']:.1f} s{ramp}")
    for w in rep["warnings"]:
        lines.append(f"warning:    {w}")
    return "\n".join(lines)
