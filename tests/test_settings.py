import pytest

import cam
from cam.settings import DEFAULT_SETTINGS


def test_thesis_defaults():
    s = DEFAULT_SETTINGS
    assert (s.steps_per_px_xy, s.steps_per_px_z) == (8, 1)
    assert (s.delay_xy_ms, s.delay_z_ms) == (5.0, 5.0)
    assert (s.mm_per_step_xy, s.mm_per_step_z) == (0.0289, 0.0157)
    p = s.pins
    assert (p.clock_z, p.dir_z, p.clock_y, p.dir_y, p.clock_x, p.dir_x) == (2, 3, 4, 5, 6, 7)
    assert s.half_step is False
    # Eq 4.1 / 4.2
    assert s.px_to_mm_xy(286) == pytest.approx(286 * 8 * 0.0289)
    assert s.px_to_mm_z(10) == pytest.approx(10 * 1 * 0.0157)


def test_load_partial_file(tmp_path):
    f = tmp_path / "m.toml"
    f.write_text("steps_per_px_xy = 4\ndelay_xy_ms = 2.5\n[travel]\nx_max_steps = 500\n[pins]\nclock_x = 8\ndir_x = 9\n")
    s = cam.load_settings(f)
    assert s.steps_per_px_xy == 4 and s.delay_xy_ms == 2.5 and s.steps_per_px_z == 1
    assert s.travel.x_max_steps == 500 and s.travel.y_max_steps == DEFAULT_SETTINGS.travel.y_max_steps
    assert s.pins.clock_x == 8 and s.pins.bit("clock_x") == 6


@pytest.mark.parametrize(
    "text, key",
    [
        ("steps_per_pixel = 8\n", "steps_per_pixel"),
        ("[travel]\nx_max = 3\n", "travel.x_max"),
        ("steps_per_px_xy = 'eight'\n", "steps_per_px_xy"),
        ("steps_per_px_xy = 0\n", "steps_per_px_xy"),
        ("delay_z_ms = -1\n", "delay_z_ms"),
        ("[pins]\nclock_x = 12\n", "pins.clock_x"),
        ("[pins]\nclock_x = 2\n", "pins.clock_x"),  # clashes with clock_z
        ("travel = 5\n", "travel"),
        ("[travel]\nx_min_steps = 10\n", "travel.x_min_steps"),
    ],
)
def test_bad_settings_name_the_key(tmp_path, text, key):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(cam.SettingsError) as info:
        cam.load_settings(f)
    assert f"'{key}'" in str(info.value) and "bad.toml" in str(info.value)


def test_bad_toml_and_missing_file(tmp_path):
    f = tmp_path / "x.toml"
    f.write_text("steps_per_px_xy = = 3")
    with pytest.raises(cam.SettingsError, match="not valid TOML"):
        cam.load_settings(f)
    with pytest.raises(cam.SettingsError, match="not found"):
        cam.load_settings(tmp_path / "none.toml")


def test_shipped_thesis_machine_file_equals_builtin_defaults():
    from conftest import ROOT
    assert cam.load_settings(ROOT / "profiles" / "thesis-machine.toml") == DEFAULT_SETTINGS


@pytest.mark.parametrize("changes, key", [
    ({"start_speed_x_mm_s": 4e-10}, "start_speed_x_mm_s"), ({"max_speed_z_mm_s": 1e-12}, "max_speed_z_mm_s"),
    ({"accel_y_mm_s2": float("nan")}, "accel_y_mm_s2"), ({"max_speed_x_mm_s": float("inf")}, "max_speed_x_mm_s"),
])
def test_speeds_are_bounded_and_finite(changes, key):
    with pytest.raises(cam.SettingsError, match=key):
        cam.MachineSettings().replace(**changes)


def test_travel_is_bounded():
    with pytest.raises(cam.SettingsError, match="travel.x_min_steps"):
        cam.MachineSettings().replace(travel=cam.settings.Travel(x_max_steps=10**12))


def test_a_drill_depth_that_rounds_to_no_step_is_an_error():
    holes = cam.parse_excellon("M48\nMETRIC,LZ\nT1C1.0\n%\nT1\nX1.0Y1.0\nM30\n", source="one.drl")
    with pytest.raises(cam.PlanError, match="mm_per_step_z"):
        cam.plan_drill(holes, settings=cam.MachineSettings().replace(mm_per_step_z=100), cut_depth_mm=2.0)


def test_the_maximus_table_loads_and_is_checked(tmp_path):
    from cam.drive.maximus.board import MAXIMUS_SETTINGS
    from conftest import ROOT

    assert cam.load_settings(ROOT / "profiles" / "maximus-machine.toml", base=MAXIMUS_SETTINGS) == MAXIMUS_SETTINGS
    f = tmp_path / "m.toml"
    f.write_text("[maximus]\ndelay_x = 3\ninvert_y = true\ndrill_z_up_steps = 40\ndrill_z_down_steps = 90\n")
    m = cam.load_settings(f, base=MAXIMUS_SETTINGS).maximus
    assert (m.delay_x, m.delay_y, m.invert_y, m.drill_z_up_steps, m.drill_z_down_steps) == (3, 10, True, 40, 90)
    assert m.drill_stroke_set and cam.load_settings(f, base=MAXIMUS_SETTINGS).mm_per_step_xy == 0.004375
    for text, key in (("delay_z_up = 0", "maximus.delay_z_up"), ("delay_y = 256", "maximus.delay_y"),
                      ("drill_z_up_steps = 50\ndrill_z_down_steps = 50", "maximus.drill_z_down_steps"),
                      ("baud = 'fast'", "maximus.baud"), ("spindel = true", "maximus.spindel")):
        f.write_text(f"[maximus]\n{text}\n")
        with pytest.raises(cam.SettingsError, match=key):
            cam.load_settings(f)
