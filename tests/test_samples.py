"""The shipped samples and profiles are exactly what their scripts make, and keep the drawing rules."""
import importlib.util
import sys

import pytest

import cam

from conftest import ROOT


def _load(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the script runs
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("folder, script", [("samples", "make_samples.py"), ("profiles", "make_profiles.py")])
def test_scripts_regenerate_the_shipped_files(tmp_path, folder, script):
    made = _load(ROOT / folder / script).make_all(tmp_path)
    assert made
    for name, path in made.items():
        shipped = ROOT / folder / path.name
        assert shipped.read_bytes() == path.read_bytes(), f"{folder}/{path.name} differs from what {script} makes"


def test_samples_keep_the_rules_and_kinds():
    kinds = {"ellipse": "2d", "two_curves": "2d", "gear": "2d", "word": "2d", "stamp": "2d",
             "disc": "3d", "pyramid": "3d", "heart": "3d", "dumbbell": "3d", "ring": "3d"}
    for name, kind in kinds.items():
        d = cam.load_image(ROOT / "samples" / f"{name}.png")
        assert d.kind == kind and d.warnings == [], name
    for name in ("dome", "cone", "pyramid", "flat"):
        assert cam.load_profile(ROOT / "profiles" / f"{name}.png").n_layers == 120
