"""cam.kinds.jobs: a file and its options to a ready job, for every kind."""
from __future__ import annotations

import numpy as np
import pytest

import cam
from cam.errors import CamError
from cam.kinds.jobs import JobOptions, job_kind, prepare_job

from conftest import ROOT, SAMPLES, assert_surface_equal

FAST = cam.MachineSettings().replace(delay_xy_ms=0.05, delay_z_ms=0.05, ramp="constant")

GCODE = "G21 G90\nG0 Z1\nG0 X1 Y-1\nG1 Z-0.2 F100\nG1 X3 F300\nM6 T2\nG1 Y-3\nG0 Z1\nG0 X0 Y0\nG0 Z0\nM2\n"


def _png_is_picture(data: bytes) -> tuple[int, int]:
    import cv2

    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None and img.ndim == 3
    return img.shape[1], img.shape[0]


def test_kind_by_suffix_and_unknown_types_name_file_and_accepted():
    assert job_kind("a.PNG") == "drawing" and job_kind("m.txt") == "digitized"
    assert job_kind("p.tap") == "gcode" and job_kind("b.xln") == "excellon" and job_kind("d.plt") == "hpgl"
    with pytest.raises(CamError, match=r"thing\.docx: unknown file type '\.docx' \(accepted: drawing .png"):
        job_kind("/some/where/thing.docx")


def test_options_from_mapping_parse_and_refuse_bad_values():
    o = JobOptions.from_mapping({"depth": "3, 4", "passes": "2", "start_at": [1, 2, 0], "pause_at": "5,6; 7,8",
                                 "mirror_x": True, "offset_mm": "1.5,2", "excellon_zeros": "lz"})
    assert o.depth == (3, 4) and o.passes == 2 and o.start_at == (1, 2, 0)
    assert o.pause_at == ((5, 6), (7, 8)) and o.mirror_x and o.offset_mm == (1.5, 2.0) and o.excellon_zeros == "LZ"
    for bad, word in [({"depth": "x"}, "depth"), ({"depth": -1}, "depth"), ({"passes": 0}, "passes"),
                      ({"start_at": "1,2"}, "start_at"), ({"cut_depth_mm": "nan"}, "cut_depth_mm"),
                      ({"mirror_x": "maybe"}, "mirror_x"), ({"start": "left"}, "start"), ({"bogus": 1}, "bogus"),
                      ({"passes": True}, "passes")]:
        with pytest.raises(CamError, match=word):
            JobOptions.from_mapping(bad)
    with pytest.raises(CamError):
        JobOptions.from_mapping(["depth", 3])  # type: ignore[arg-type]


def test_drawing_job_equals_the_library_plan_and_carves_exactly():
    job = prepare_job(SAMPLES / "gear.png", JobOptions(depth=(4, 2), passes=2), FAST)
    d = cam.digitize(cam.load_image(SAMPLES / "gear.png"))
    tp = cam.plan(d, depth=[4, 2], passes=2, settings=FAST)
    plan = cam.plan_steps(tp)
    assert job.kind == "drawing" and np.array_equal(job.steps.data, plan.data)
    assert np.array_equal(job.steps.t_ns, plan.t_ns)
    assert job.estimated_time_s == plan.estimated_time_s
    rep = cam.image_report(d, FAST)
    assert job.size_mm == (rep["width_mm"], rep["height_mm"])
    assert job.summary.startswith("gear.png: 2 object(s)")
    result = cam.run(job.steps)
    motion = cam.decode_pin_log(result.pin_log(), FAST)
    got = cam.carve(motion, (tp.height_px, tp.width_px), FAST)
    assert_surface_equal(got, cam.simulate_surface(tp))
    # extent: what the job reaches from where it starts
    pos = job.positions_steps()
    assert job.extent_steps.tolist() == [[min(0, int(pos[:, a].min())), int(pos[:, a].max())] for a in range(3)]
    w, h = _png_is_picture(job.preview_png())
    assert w >= tp.width_px and h >= tp.height_px


def test_digitized_matrix_and_3d_profile_jobs(tmp_path):
    d = cam.digitize(cam.load_image(SAMPLES / "two_curves.png"))
    cam.save_digitized(d, tmp_path / "m.txt")
    job = prepare_job(tmp_path / "m.txt", JobOptions(depth=(3,)), FAST)
    assert job.kind == "digitized"
    assert np.array_equal(job.steps.data, cam.plan_steps(cam.plan(d, depth=3, settings=FAST)).data)
    job3 = prepare_job(SAMPLES / "disc.png", JobOptions(profile=str(ROOT / "profiles" / "dome.png")), FAST)
    tp = cam.plan(cam.digitize(cam.load_image(SAMPLES / "disc.png")), profile=cam.load_profile(ROOT / "profiles" / "dome.png"),
                  settings=FAST)
    assert np.array_equal(job3.steps.data, cam.plan_steps(tp).data)
    assert job3.depth_mm > 0
    with pytest.raises(CamError, match="profile"):
        prepare_job(SAMPLES / "disc.png", JobOptions(), FAST)  # a 3D drawing needs a profile


def test_gcode_job_with_tool_change(tmp_path):
    from cam.motion.steps import plan_steps
    from cam.formats.gcode import load_gcode
    from cam.job.gcode import plan_gcode

    path = tmp_path / "p.ngc"
    path.write_text(GCODE)
    job = prepare_job(path, JobOptions(), FAST)
    want = plan_steps(plan_gcode(load_gcode(path), FAST))
    assert job.kind == "gcode" and np.array_equal(job.steps.data, want.data)
    assert len(job.tool_changes) == 1 and "tool change" in job.tool_changes[0]
    assert job.size_mm == pytest.approx((2.0, 2.0), abs=FAST.mm_per_step_xy)
    assert job.depth_mm == pytest.approx(0.2, abs=FAST.mm_per_step_z)
    _png_is_picture(job.preview_png())
    path.write_text("G21\nG1 X1 Q5\n")
    with pytest.raises(CamError, match=r"p\.ngc:2"):
        prepare_job(path, JobOptions(), FAST)


def test_excellon_job(tmp_path):
    path = tmp_path / "b.drl"
    path.write_text("M48\nMETRIC,LZ\nT1C0.8\nT2C1.0\n%\nT1\nX5.0Y5.0\nX10.0Y5.0\nT2\nX10.0Y10.0\nM30\n")
    job = prepare_job(path, JobOptions(cut_depth_mm=1.0), FAST)
    assert job.kind == "excellon" and job.summary.startswith("b.drl: 3 holes")
    assert len(job.tool_changes) == 2
    assert job.size_mm == pytest.approx((5.0, 5.0), abs=FAST.mm_per_step_xy)
    z = job.positions_steps()[:, 2]
    assert z.max() == round(1.0 / FAST.mm_per_step_z)
    _png_is_picture(job.preview_png())


def test_hpgl_job(tmp_path):
    path = tmp_path / "d.plt"
    path.write_text("IN;SP1;PU0,0;PD400,0,400,400,0,400,0,0;PU;SP2;PA800,800;PD;PA1200,800;PU;\n")
    job = prepare_job(path, JobOptions(cut_depth_mm=0.3), FAST)
    assert job.kind == "hpgl" and len(job.tool_changes) == 2
    assert job.size_mm == pytest.approx((30.0, 20.0), abs=FAST.mm_per_step_xy)  # 1200 x 800 plotter units
    assert job.depth_mm == pytest.approx(0.3, abs=FAST.mm_per_step_z)


def test_missing_file_and_bad_drawing(tmp_path):
    with pytest.raises(CamError, match="not found"):
        prepare_job(tmp_path / "none.png")
    (tmp_path / "junk.png").write_bytes(b"not a png")
    with pytest.raises(CamError, match="junk.png"):
        prepare_job(tmp_path / "junk.png")
