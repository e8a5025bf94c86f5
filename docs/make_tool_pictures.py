"""Make docs/tools-rest.png: what a ball and a flat 1 mm cutter leave of the heart cut as a steep dome.

Each job runs on the mock port; its pin log is decoded and carved with the tool's shape
(cam.verify.toolcarve), then compared with the point tool's exact carve of the same drawing: white where the
cut equals the relief, blue where material is left, red where the tool cut below it (never, here).

    python docs/make_tool_pictures.py
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

import cam
from cam.tool import parse_tool
from cam.verify.toolcarve import carve_tool, compare_surface, gouge_rest_picture

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    d = cam.digitize(cam.load_image(ROOT / "samples" / "heart.png"))
    profile = cam.profile_from_expr("round(sqrt(n*n-(n-k)*(n-k))*3)", d.n_layers)
    point = cam.plan(d, profile=profile)
    want = cam.carve(cam.decode_pin_log(cam.run(point).pin_log(), point.settings), (d.height_px, d.width_px),
                     point.settings)
    panels = []
    for spec in ("ball:1", "flat:1"):
        job = cam.plan(d, profile=profile, tool=spec)
        motion = cam.decode_pin_log(cam.run(job).pin_log(), job.settings)
        cut = carve_tool(motion, want.shape, parse_tool(spec), job.settings)
        c = compare_surface(cut.depth_steps, want, job.settings)
        print(f"{spec}: max gouge {c.max_gouge_mm:.3f} mm, rest mean {c.rest_mean_mm:.4f} mm, "
              f"p95 {c.rest_p95_mm:.4f} mm")
        rgb = gouge_rest_picture(c, scale_mm=0.3)
        panels.append(cv2.resize(rgb, None, fx=3, fy=3, interpolation=cv2.INTER_NEAREST))
    gap = np.full((panels[0].shape[0], 12, 3), 255, np.uint8)
    picture = np.concatenate([panels[0], gap, panels[1]], axis=1)
    out = ROOT / "docs" / "tools-rest.png"
    cv2.imwrite(str(out), picture[:, :, ::-1])
    print(out)


if __name__ == "__main__":
    main()
