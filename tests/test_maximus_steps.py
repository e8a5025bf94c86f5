"""Issue #45 point 5: on the MAXIMUS board distances follow each axis's half/full step mode, ``cam info`` shows the
board's own speeds, ``cam home`` says what the board can do, and the page / API place a drill file exactly as the
command line does for the same options (``offset_mm [0, 0]`` = ``--offset 0,0``).  Checked on the emulator's hole
log (motor half steps per axis, whatever the MODE pins say) and on the mock's state file."""
from __future__ import annotations

import json
import time

import pytest

from cam.cli import main
from cam.drive.maximus.board import MAXIMUS_SETTINGS, board_settings
from cam.drive.state import read_state
from cam.errors import SettingsError
from cam.settings import load_settings
from cam.sim.maximus import start_emulator

HALF_STEP_MM = 0.004375  # what one count of the emulator's hole log is: a motor half step (8.75 um per full step)
HOLES_MM = [(7.62, -5.08), (15.24, -10.16), (22.86, -2.54)]


def _board(tmp_path, holes=HOLES_MM):
    path = tmp_path / "b.drl"
    lines = [f"X{x:.2f}Y{y:.2f}" for x, y in holes]
    path.write_text("\n".join(["M48", "METRIC", "T1C0.800", "%", "T1", *lines, "M30"]) + "\n")
    return path


def _machine(tmp_path, **maximus) -> str:
    path = tmp_path / "m.toml"
    path.write_text("[maximus]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in maximus.items()))
    return str(path)


@pytest.mark.parametrize("modes", [{"half_step_x": False}, {"half_step_y": False}, {}],
                         ids=["x-full", "y-full", "both-half"])
def test_maximus_half_and_full_step_axes_drill_where_the_file_says(emu, tmp_path, capsys, modes):
    path = _board(tmp_path)
    port, st = f"maximus:{emu.device_path}", str(tmp_path / "s.json")
    machine = _machine(tmp_path, **modes)
    assert main(["where", "--set", "0,0,0", "--port", port, "--state", st, "--machine", machine]) == 0
    code = main(["drill", str(path), "--yes", "--offset", "0,0", "--port", port, "--state", st, "--machine", machine,
                 "--travel-height", "0.2", "--cut-depth", "0.3", "--drill-order", "file"])
    assert code == 0, capsys.readouterr().err
    rows = emu.hole_log()
    assert len(rows) == len(HOLES_MM)
    for (x, y), row in zip(HOLES_MM, rows):
        # the board frame: X right, Y up from the origin, as the file's Y; within one pulse of the axis's mode
        for a, (want, got) in enumerate(((x, row[1] * HALF_STEP_MM), (y, row[2] * HALF_STEP_MM))):
            pulse = HALF_STEP_MM * (1 if modes.get(f"half_step_{'xy'[a]}", True) else 2)
            assert abs(got - want) <= pulse, (modes, a, want, got)
    # the position the state file keeps is in each axis's own pulses: back at the origin, and 1 mm jogs move 1 mm
    assert read_state(st, board_settings(load_settings(machine, base=MAXIMUS_SETTINGS))).position_steps == (0, 0, 0)
    start = emu.position_pulses
    assert main(["jog", "X+", "1", "--unit", "mm", "--port", port, "--state", st, "--machine", machine]) == 0
    assert main(["jog", "Y-", "1", "--unit", "mm", "--port", port, "--state", st, "--machine", machine]) == 0
    capsys.readouterr()
    for a in (0, 1):  # Y- is away from the operator: the board's Y up
        pulse = HALF_STEP_MM * (1 if modes.get(f"half_step_{'xy'[a]}", True) else 2)
        assert abs((emu.position_pulses[a] - start[a]) * pulse - 1.0) <= pulse, (modes, a, emu.position_pulses)
    assert main(["where", "--port", port, "--state", st, "--machine", machine]) == 0
    machine_line = capsys.readouterr().out.splitlines()[0]  # "machine: X=0.9975 Y=-1.0019 Z=0.0 mm (...)"
    shown = [float(v.split("=")[1]) for v in machine_line.split(" mm")[0].split()[1:3]]
    assert abs(shown[0] - 1.0) <= 2 * HALF_STEP_MM and abs(shown[1] + 1.0) <= 2 * HALF_STEP_MM, machine_line


def test_a_machine_files_own_step_that_disagrees_with_the_boards_modes_is_one_line(tmp_path):
    m = tmp_path / "m.toml"
    m.write_text("mm_per_step_xy = 0.005\n")
    with pytest.raises(SettingsError, match="mm_per_full_step"):
        board_settings(load_settings(m, base=MAXIMUS_SETTINGS))
    m.write_text("mm_per_step_y = 0.005\n")  # not a machine-file key: the board's settings derive it
    with pytest.raises(SettingsError, match="unknown key 'mm_per_step_y'"):
        load_settings(m, base=MAXIMUS_SETTINGS)


def test_cam_info_on_maximus_shows_the_boards_speeds(tmp_path, capsys):
    path = _board(tmp_path)
    machine = _machine(tmp_path, delay_x=5, delay_y=20, delay_z_up=10, delay_z_down=40, half_step_y=False)
    assert main(["info", str(path), "--port", "maximus:/dev/null", "--machine", machine,
                 "--state", str(tmp_path / "s.json")]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert "thesis" not in line and "lookahead" not in line and "top speeds" not in line
    # a pulse every 2 x Delay x 0.1 ms: X 1 ms of 4.375 um, Y 4 ms of 8.75 um (full steps), Z 2 ms / 8 ms
    for part in ("X 4.38 mm/s (Delay 5: a pulse every 1 ms, half steps of 0.004375 mm)",
                 "Y 2.19 mm/s (Delay 20: a pulse every 4 ms, full steps of 0.00875 mm)",
                 "Z up 2.19 mm/s (Delay 10", "Z down 0.547 mm/s (Delay 40: a pulse every 8 ms"):
        assert part in line, line
    assert main(["info", str(path)]) == 0  # the thesis machine's line on the other ports
    assert capsys.readouterr().out.strip().splitlines()[-1].startswith("top speeds:")


def test_cam_home_on_maximus_says_what_the_board_can_do(tmp_path, capsys):
    code = main(["home", "--port", "maximus:/dev/null", "--state", str(tmp_path / "s.json")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    for words in ("cannot home", "limit switches only stop a move", "cam jog", "cam where --set 0,0,0",
                  "Set position", "step/dir"):
        assert words in err, err
    assert "parallel-port" not in err and "pin" not in err


def _api_drill(tmp_path, port: str, settings, board, options) -> dict:
    from test_web import Server

    s = Server(tmp_path, settings=settings, machine_port=port, realtime=port != "mock",
               state_file=str(tmp_path / "api.json"))
    try:
        assert s.call("POST", "/api/set-position", {"xyz": [0, 0, 0], "unit": "mm"})[0] == 200
        status, r = s.upload("b.drl", board.read_bytes())
        assert status == 200, r
        status, plan = s.call("POST", "/api/plan", {"job": r["job"], "options": options})
        assert status == 200, plan
        assert s.call("POST", "/api/start", {"job": plan["job"]})[0] == 200
        deadline = time.monotonic() + 60
        while s.session.busy:  # a tool-change prompt is answered as the page's Continue would
            assert time.monotonic() < deadline, "the drill job did not end"
            st = s.session.state()
            if st["prompt"]:
                s.call("POST", "/api/answer", {"prompt": st["prompt"]["id"], "action": "continue"})
            s.session.wait_idle(0.02)
        st = s.session.state()
        assert st["last"]["status"] == "finished", st["last"]
        return st
    finally:
        s.close()


def test_api_and_cli_place_a_drill_file_the_same_for_offset_0_0(tmp_path, emu, capsys):
    board = _board(tmp_path)  # no hole at the file's zero: placed by its upper-left hole it would differ
    cli_flags = ["--offset", "0,0", "--travel-height", "0.2", "--cut-depth", "0.3"]
    options = {"offset_mm": "0,0", "travel_height_mm": 0.2, "cut_depth_mm": 0.3}
    # the MAXIMUS board: where the holes were drilled, in the emulator's hole log
    port = f"maximus:{emu.device_path}"
    cli_state = str(tmp_path / "cli.json")
    assert main(["where", "--set", "0,0,0", "--port", port, "--state", cli_state]) == 0
    assert main(["drill", str(board), "--yes", "--port", port, "--state", cli_state, *cli_flags]) == 0
    cli_holes = [row[1:3] for row in emu.hole_log()]
    emu2 = start_emulator(speed=None)
    (tmp_path / "maximus").mkdir()
    try:
        _api_drill(tmp_path / "maximus", f"maximus:{emu2.device_path}", MAXIMUS_SETTINGS, board, options)
        api_holes = [row[1:3] for row in emu2.hole_log()]
    finally:
        emu2.stop()
    assert sorted(api_holes) == sorted(cli_holes)
    assert min(r[0] for r in cli_holes) == round(7.62 / HALF_STEP_MM)  # the file's zero at the work zero
    # the mock: where each front end's job started (its home, the file's zero: the job journal's start), from the
    # same known position; placed by its upper-left hole it would start 7.62 mm left of the work zero
    mock_state, journal = str(tmp_path / "mock.json"), tmp_path / "cli.journal.json"
    assert main(["where", "--set", "0,0,0", "--state", mock_state]) == 0
    assert main(["drill", str(board), "--yes", "--state", mock_state, "--journal", str(journal), *cli_flags]) == 0
    (tmp_path / "mock").mkdir()
    st = _api_drill(tmp_path / "mock", "mock", load_settings(None), board, options)
    api_journal = json.loads(open(st["last"]["journal"]).read())
    cli_journal = json.loads(journal.read_text())
    assert api_journal["start_position_steps"] == cli_journal["start_position_steps"] == [0, 0, 0]
    assert api_journal["plan_sha256"] == cli_journal["plan_sha256"]  # the same job, planned the same
