"""The 3D pipeline from the command line."""
import json

import numpy as np

import cam
from cam.digitize.peel3d import peel_layers

from conftest import ROOT, SAMPLES, assert_surface_equal
from test_cli import assert_one_line_error, cli


def test_drill_heart_with_dome_profile_carves_the_relief(tmp_path):
    proc = cli("drill", SAMPLES / "heart.png", "--profile", ROOT / "profiles" / "dome.png", "--pin-log",
               tmp_path / "p.csv", "--report", tmp_path / "r.json", "--save-digitized", tmp_path / "m.txt",
               "--no-progress")
    assert proc.returncode == 0, proc.stderr
    drawing = cam.load_image(SAMPLES / "heart.png")
    profile = cam.load_profile(ROOT / "profiles" / "dome.png")
    layer = peel_layers(drawing.classes)
    want = np.where(layer > 0, profile.depth_px[np.maximum(layer, 1) - 1], 0)
    motion = cam.decode_pin_log(tmp_path / "p.csv")
    assert_surface_equal(cam.carve(motion, layer.shape), want)
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["layers"] == int(layer.max()) and rep["retracts"] <= rep["rings"] + rep["objects"]
    # the saved 3D matrix reloads into the same job
    proc = cli("drill", "--load-digitized", tmp_path / "m.txt", "--profile", ROOT / "profiles" / "dome.png",
               "--report", tmp_path / "r2.json", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / "r2.json").read_text())["steps"] == rep["steps"]


def test_3d_options_passes_start_at_and_expression(tmp_path):
    proc = cli("drill", SAMPLES / "disc.png", "--profile-expr", "k // 2 + 1", "--passes", "2",
               "--start-at", "3,4,0", "--steps-per-pixel", "4,2", "--pin-log", tmp_path / "p.csv", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    drawing = cam.load_image(SAMPLES / "disc.png")
    layer = peel_layers(drawing.classes)
    want = np.where(layer > 0, layer // 2 + 1, 0) * 2
    s = cam.MachineSettings().replace(steps_per_px_xy=4, steps_per_px_z=2)
    motion = cam.decode_pin_log(tmp_path / "p.csv", s)
    assert_surface_equal(cam.carve(motion, layer.shape, s, origin_px=(3, 4, 0)), want)


def test_info_on_3d_reports_layers_rings_and_relief_size():
    proc = cli("info", SAMPLES / "ring.png", "--profile", ROOT / "profiles" / "cone.png", "--json")
    rep = json.loads(proc.stdout)
    assert rep["mode"] == "3d" and rep["objects"] == 1 and rep["rings"] >= rep["layers"] > 1
    assert rep["depth_mm"] > 0 and rep["width_mm"] > 0
    text = cli("info", SAMPLES / "ring.png").stdout
    assert "layers" in text and "rings" in text


def test_profile_command():
    proc = cli("profile", ROOT / "profiles" / "cone.png")
    assert proc.returncode == 0 and "layers, depth" in proc.stdout


def test_3d_errors(tmp_path):
    assert_one_line_error(cli("drill", SAMPLES / "heart.png"), "give --depth N for a flat-bottomed pocket")
    short = tmp_path / "short.csv"
    short.write_text("1\n2\n3\n")
    assert_one_line_error(cli("drill", SAMPLES / "disc.png", "--profile", short), "profile has 3 layers, the object has")
    assert_one_line_error(cli("drill", SAMPLES / "disc.png", "--profile-expr", "k +"), "profile expression")
    assert_one_line_error(cli("drill", SAMPLES / "gear.png", "--profile", ROOT / "profiles" / "dome.png"),
                          "3D drawings only")
    assert_one_line_error(cli("drill", ROOT / "profiles" / "dome.png"), "profile drawing")
