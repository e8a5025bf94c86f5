"""The machine file listed and edited (cam.machine_file) and the machine's tool table (cam.tool_table, cam tools):
issue #47 points 4 and 5, the library and the command line."""
from __future__ import annotations

import dataclasses
import os
import shutil

import pytest

from cam.errors import CamError, SettingsError
from cam.machine_file import backup_path, check_setting, list_settings, machine_file_of, save_settings, setting_keys
from cam.settings import DEFAULT_SETTINGS, MachineSettings, load_settings, settings_from_mapping
from cam.tool_table import (TableTool, ToolTable, ToolTableError, annotate_tool_change, read_tool_table,
                            tool_table_path, tool_table_warnings, write_tool_table)

from conftest import ROOT, SAMPLES, run_cli

GRBL = ROOT / "profiles" / "grbl-3018.toml"


@pytest.fixture
def machine(tmp_path):
    path = tmp_path / "m.toml"
    shutil.copy(GRBL, path)
    return path


def _every_key(settings: MachineSettings) -> set[str]:
    keys = set()
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        if dataclasses.is_dataclass(value):
            keys |= {f"{f.name}.{g.name}" for g in dataclasses.fields(value)}
        elif f.name != "mm_per_step_y":  # derived, no machine-file key
            keys.add(f.name)
    return keys


def test_every_key_of_the_machine_file_is_listed_with_its_value_unit_and_help():
    settings = load_settings(GRBL)
    infos = list_settings(settings)
    assert {i.key for i in infos} == _every_key(settings) == set(setting_keys())
    by_key = {i.key: i for i in infos}
    assert all(i.help for i in infos)
    assert by_key["mm_per_step_xy"].value == 0.00125 and by_key["mm_per_step_xy"].unit == "mm/step"
    assert by_key["accel_z_mm_s2"].unit == "mm/s^2" and by_key["travel.z_min_steps"].unit == "steps"
    assert (by_key["maximus.delay_x"].lo, by_key["maximus.delay_x"].hi) == (1, 255)
    assert by_key["homing.direction_x"].choices == ("-", "+")
    assert by_key["mock.home_x_steps"].optional and by_key["mock.home_x_steps"].value is None


def test_every_range_listed_is_refused_beyond_by_the_settings_too():
    """The ranges the page shows are those the settings check: just beyond one, a machine file is refused."""
    for info in list_settings(DEFAULT_SETTINGS):
        if info.lo is None or info.kind not in ("int", "float") or info.key.startswith("homing.offset"):
            continue
        for beyond in (info.lo - (1 if info.kind == "int" else abs(info.lo) * 0.5 + 1e-3),
                       info.hi + (1 if info.kind == "int" else abs(info.hi) * 0.5 + 1)):
            beyond = int(beyond) if info.kind == "int" else beyond
            with pytest.raises(SettingsError, match=info.key.replace(".", r"\.")):
                check_setting(info.key, beyond)
            table, _, name = info.key.rpartition(".")
            if table == "tool":  # the built-in point tool has no sizes to check: only the page refuses them
                continue
            with pytest.raises(SettingsError):  # and a machine file saying it is refused when read
                settings_from_mapping({table: {name: beyond}} if table else {name: beyond})


def test_save_round_trip_keeps_comments_and_the_old_file_as_backup(machine):
    old = machine.read_text()
    new = save_settings(machine, {"max_speed_x_mm_s": 20.0, "travel.x_max_steps": 1000, "maximus.delay_x": 20,
                                  "homing.order": "xyz", "half_step": True})
    assert load_settings(machine) == new
    assert (new.max_speed_x_mm_s, new.travel.x_max_steps, new.maximus.delay_x, new.homing.order, new.half_step) == \
        (20.0, 1000, 20, "xyz", True)
    assert backup_path(machine).read_text() == old
    text = machine.read_text()
    assert "max_speed_x_mm_s = 20.0    # $110 = 1000 mm/min" in text  # the value in place, its comment kept
    assert text.count("# A grbl 1.1 desktop router") == 1
    info = {i.key: i.value for i in list_settings(load_settings(machine))}
    assert info["maximus.delay_x"] == 20 and info["homing.order"] == "xyz"
    # text from a form, and an optional key cleared
    again = save_settings(machine, {"max_speed_x_mm_s": "12.5", "mock.home_x_steps": "250"})
    assert again.max_speed_x_mm_s == 12.5 and again.mock.home_x_steps == 250
    assert backup_path(machine).read_text() == text  # the backup is the file as it was just before
    assert save_settings(machine, {"mock.home_x_steps": ""}).mock.home_x_steps is None
    assert "home_x_steps" not in machine.read_text()


def test_a_value_out_of_range_is_refused_in_one_line_naming_key_unit_and_range(machine):
    old = machine.read_text()
    cases = [({"max_speed_x_mm_s": 20000}, "'max_speed_x_mm_s' must be 0.01..10000 mm/s, got 20000"),
             ({"maximus.delay_x": 300}, "'maximus.delay_x' must be 1..255 Delay byte, got 300"),
             ({"steps_per_px_xy": 2.5}, "'steps_per_px_xy' must be a whole number of steps/pixel, got 2.5"),
             ({"ramp": "fast"}, "'ramp' must be one of lookahead, linear40, constant, got 'fast'"),
             ({"half_step": "maybe"}, "'half_step' must be true or false, got 'maybe'"),
             ({"nokey": 1}, "unknown machine setting 'nokey'")]
    for change, message in cases:
        with pytest.raises(SettingsError) as err:
            save_settings(machine, change)
        assert str(err.value).startswith(message) and "\n" not in str(err.value)
    with pytest.raises(SettingsError, match="start_speed_x_mm_s.*max_speed_x_mm_s"):  # a rule between keys
        save_settings(machine, {"start_speed_x_mm_s": 100.0})
    assert machine.read_text() == old and not backup_path(machine).exists()


def test_a_failed_write_leaves_the_old_file(machine, monkeypatch):
    old = machine.read_text()
    real_replace = os.replace

    def refused(src, dst, *args, **kwargs):
        if os.path.basename(dst) == machine.name:
            raise OSError(28, "No space left on device")
        return real_replace(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", refused)
    with pytest.raises(CamError, match="No space left on device"):
        save_settings(machine, {"max_speed_x_mm_s": 7.0})
    assert machine.read_text() == old
    assert not [p for p in machine.parent.iterdir() if p.name.endswith(".tmp")]


def test_a_file_the_lines_cannot_say_is_written_anew_and_reads_the_same(tmp_path):
    path = tmp_path / "inline.toml"
    path.write_text("travel = { x_max_steps = 5000 }\npins.clock_x = 6\n")
    s = save_settings(path, {"travel.y_max_steps": 4000})
    assert load_settings(path) == s and (s.travel.x_max_steps, s.travel.y_max_steps) == (5000, 4000)


def test_machine_file_of_the_built_in_settings_is_in_the_state_folder():
    assert machine_file_of(None, {"XDG_STATE_HOME": "/s"}).as_posix() == "/s/cam/default.toml"
    assert tool_table_path(machine_file_of(None, {"XDG_STATE_HOME": "/s"})) == tool_table_path(None, {"XDG_STATE_HOME": "/s"})


# -- the tool table ------------------------------------------------------------------------------------------

def test_tool_table_round_trip(tmp_path):
    table = ToolTable().with_tool(TableTool(3, "v", 0.2, 30, 12.3)).with_tool(TableTool(1, "ball", 1.5))
    path = write_tool_table(tmp_path / "m.tools.toml", table, "m.toml")
    back = read_tool_table(path)
    assert back == table and [t.number for t in back.sorted()] == [1, 3]
    assert back.get(3).cutter().tip_mm == 0.2 and back.get(1).cutter().diameter_mm == 1.5
    assert read_tool_table(tmp_path / "none.toml") == ToolTable()
    (tmp_path / "bad.toml").write_text("[tool.2]\nshape = \"v\"\ndiameter_mm = 0.1\n")
    with pytest.raises(ToolTableError, match="bad.toml.*T2.*angle"):
        read_tool_table(tmp_path / "bad.toml")


def test_a_drill_files_size_wins_and_a_table_tool_of_another_size_is_a_warning():
    table = ToolTable().with_tool(TableTool(3, "flat", 1.0)).with_tool(TableTool(7, "flat", 3.2))
    note = "tool change: T3 3.200 mm (4 holes)"
    said = annotate_tool_change(note, table)
    assert said.startswith(note) and "T3: flat end mill 1 mm: NOT the file's 3.2 mm" in said and "T7" in said
    warnings = tool_table_warnings([note], table, [(3, 3.2, 4)])
    assert warnings == ["T3: the drill file's 3.2 mm wins (its holes are drilled at that size), not the tool table's "
                        "T3: flat end mill 1 mm: put in a 3.2 mm tool at the prompt; the table's T7: flat end mill "
                        "3.2 mm has that size"]
    assert tool_table_warnings([], table, [(7, 3.2, 4)]) == []
    assert annotate_tool_change("tool change: pen 2", table) == "tool change: pen 2"
    assert annotate_tool_change(note, ToolTable()) == note


def test_a_gcode_tool_change_names_the_tables_tool(tmp_path):
    table = ToolTable().with_tool(TableTool(3, "v", 0.2, 30))
    assert annotate_tool_change("tool change: T3 (line 4)", table) == \
        "tool change: T3 (line 4) [tool table T3: V bit 30 degrees, tip 0.2 mm]"
    assert tool_table_warnings(["tool change: T3 (line 4)", "tool change: T5 (line 9)"], table) == \
        ["T5 M6 (line 9): tool T5 is not in the tool table (cam tools set 5 ...)"]


# -- cam tools -----------------------------------------------------------------------------------------------

def test_cam_tools_sets_lists_and_removes(tmp_path, machine):
    r = run_cli("tools", "--machine", machine, "set", "3", "--shape", "v", "--diameter", "0.2", "--angle", "30",
                "--length", "12.3")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == f"set T3: V bit 30 degrees, tip 0.2 mm, length 12.3 mm in {tmp_path / 'm.tools.toml'}"
    assert run_cli("tools", "--machine", machine, "set", "1", "--shape", "flat", "--diameter", "0.8").returncode == 0
    r = run_cli("tools", "--machine", machine)
    assert r.returncode == 0 and r.stdout.splitlines() == [
        f"tool table {tmp_path / 'm.tools.toml'}: 2 tools", "  T1: flat end mill 0.8 mm",
        "  T3: V bit 30 degrees, tip 0.2 mm, length 12.3 mm"]
    assert read_tool_table(tmp_path / "m.tools.toml").get(3) == TableTool(3, "v", 0.2, 30, 12.3)
    r = run_cli("tools", "--machine", machine, "remove", "1")
    assert r.returncode == 0 and "removed T1" in r.stdout
    r = run_cli("tools", "--machine", machine, "--json", "list")
    assert r.returncode == 0 and '"number": 3' in r.stdout and '"number": 1' not in r.stdout


@pytest.mark.parametrize("args, fragment", [
    (["set", "3", "--shape", "v", "--diameter", "0.2"], "angle must be 1..179"),
    (["set", "3", "--shape", "flat", "--diameter", "1", "--angle", "30"], "an angle is for a V bit only"),
    (["set", "3", "--shape", "drill", "--diameter", "1"], "--shape"),
    (["set", "x", "--shape", "flat", "--diameter", "1"], "N takes a whole number"),
    (["set", "3", "--shape", "flat", "--diameter", "500"], "--diameter must be"),
    (["set", "3", "--shape", "flat"], "--diameter"),
    (["remove", "9"], "no tool T9"),
])
def test_cam_tools_bad_input_is_one_line_and_exit_2(machine, args, fragment):
    r = run_cli("tools", "--machine", machine, *args)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0] and "Traceback" not in r.stderr


@pytest.mark.parametrize("command", [["tools"], ["tools", "set"], ["tools", "remove"], ["tools", "list"]])
def test_cam_tools_help(command):
    r = run_cli(*command, "--help")
    assert r.returncode == 0 and "usage: cam tools" in r.stdout


def test_cam_drill_names_the_tables_tool_at_each_tool_change(tmp_path):
    machine = tmp_path / "th.toml"
    shutil.copy(ROOT / "profiles" / "thesis-machine.toml", machine)
    assert run_cli("tools", "--machine", machine, "set", "1", "--shape", "flat", "--diameter", "0.8").returncode == 0
    assert run_cli("tools", "--machine", machine, "set", "3", "--shape", "flat", "--diameter", "1").returncode == 0
    r = run_cli("drill", SAMPLES / "board.drl", "--machine", machine, "--yes", "--no-progress",
                "--state", tmp_path / "state.json")
    assert r.returncode == 0, r.stderr
    assert "warning: T3: the drill file's 3.2 mm wins" in r.stderr
    assert "tool change: T1 0.800 mm (16 holes) [tool table T1: flat end mill 0.8 mm]" in r.stderr
    assert "tool change: T2 1.000 mm (24 holes) [tool table: no T2; the table's T3: flat end mill 1 mm has that " \
           "size]" in r.stderr


def test_cam_drill_of_gcode_names_the_tables_tool_at_t3_m6(tmp_path):
    machine = tmp_path / "th.toml"
    shutil.copy(ROOT / "profiles" / "thesis-machine.toml", machine)
    program = tmp_path / "job.ngc"
    program.write_text("G21 G90\nG0 Z1\nT3 M6\nG0 X1 Y-1\nG1 Z-0.2 F60\nG0 Z1\nT5 M6\nG0 X2\nM2\n")
    assert run_cli("tools", "--machine", machine, "set", "3", "--shape", "v", "--diameter", "0.2",
                   "--angle", "30").returncode == 0
    r = run_cli("drill", program, "--machine", machine, "--yes", "--no-progress", "--state", tmp_path / "state.json")
    assert r.returncode == 0, r.stderr
    assert "tool change: T3 (line 3) [tool table T3: V bit 30 degrees, tip 0.2 mm]" in r.stderr
    assert "tool change: T5 (line 7) [tool table: no T5]" in r.stderr
    assert "warning: T5 M6 (line 7): tool T5 is not in the tool table (cam tools set 5 ...)" in r.stderr
