"""The MAXIMUS board in the machine and work frames (issue #29 point 6): its Set Offset is the work zero, a drill
file is drilled from the work zero, `cam goto 0,0,0` goes back to it, the position is live after every hole, and a
limit-switch reply makes the position unknown.  Sped-up emulator here; one run at real speed at the end."""
from __future__ import annotations

import json

import pytest

from cam.cli import main
from cam.drive.maximus.board import MAXIMUS_SETTINGS
from cam.drive.session import MachineSession
from cam.drive.state import MachineState, PositionUnknownError, StateHold, read_state, write_state
from cam.kinds.jobs import JobOptions, prepare_job
from cam.sim.maximus import LIMIT_SWITCH_X
from support.maximus_log import decode_port_log

MM = MAXIMUS_SETTINGS.mm_per_step_xy


def _board(tmp_path, holes: list[str]):
    path = tmp_path / "board.drl"
    path.write_text("M48\nMETRIC,TZ\nT1C0.8\nT2C1.0\n%\n" + "\n".join(holes) + "\nM30\n")
    return path


def head(emu) -> list[int]:
    """The head in the board's pulses from power-up: x, y up, z height."""
    return decode_port_log(emu.port_log())[-1].tolist()


def test_zero_then_drill_then_goto_zero_on_the_board(emu, tmp_path, capsys):
    port, st = f"maximus:{emu.device_path}", str(tmp_path / "m.json")
    # a new machine: its position unknown until said (issue #43 point 5); the head stands at the board origin
    assert main(["where", "--set", "0,0,0", "--port", port, "--state", st]) == 0
    assert main(["goto", "400,300,0", "--unit", "steps", "--port", port, "--state", st]) == 0, capsys.readouterr().err
    assert head(emu) == [400, -300, 0]  # cam's +Y is toward the operator: the board's -Y
    assert main(["zero", "--port", port, "--state", st]) == 0  # the PC program's Set Offset: the work zero here
    path = _board(tmp_path, ["T1", "X2.0Y-1.0", "X2.5Y-1.5", "T2", "X3.0Y-1.0"])
    code = main(["drill", str(path), "--yes", "--offset", "0,0", "--port", port, "--state", st,
                 "--travel-height", "0.2", "--cut-depth", "0.3"])
    assert code == 0, capsys.readouterr().err
    got = sorted((round((r[1] - 400) * MM, 2), round((r[2] + 300) * MM, 2)) for r in emu.hole_log())
    assert got == [(2.0, -1.0), (2.5, -1.5), (3.0, -1.0)]  # measured from the work zero, not from power-up
    capsys.readouterr()
    assert main(["where", "--json", "--port", port, "--state", st]) == 0
    where = json.loads(capsys.readouterr().out)
    assert where["work_steps"] == [0, 0, 0] and where["position_known"]
    assert main(["jog", "X+", "50", "--port", port, "--state", st]) == 0
    assert head(emu) == [450, -300, 0]
    assert main(["goto", "0,0,0", "--port", port, "--state", st]) == 0  # back to the work zero, not power-up
    assert head(emu) == [400, -300, 0]


def test_the_position_is_live_after_every_hole_and_a_limit_switch_makes_it_unknown(emu, tmp_path):
    path = _board(tmp_path, ["T1", "X1.0Y-1.0", "X2.0Y-1.0", "X3.0Y-1.0"])
    job = prepare_job(path, JobOptions(offset_mm=(0.0, 0.0), travel_height_mm=0.2, cut_depth_mm=0.3),
                      MAXIMUS_SETTINGS)
    write_state(tmp_path / "m.json", MachineState())  # known at the home (a missing file would be unknown)
    hold = StateHold(tmp_path / "m.json", MAXIMUS_SETTINGS, "the test")
    try:
        ses = MachineSession(f"maximus:{emu.device_path}", MAXIMUS_SETTINGS, state=hold,
                             on_prompt=lambda prompt: "continue")
        seen = []
        ses.on_detail = lambda text: seen.append((text, ses.position_steps()))
        ses.run(job)
        assert ses.last_run["status"] == "finished", ses.last_run
        xs = [round(pos[0] * MM, 1) for text, pos in seen if text.startswith("drilling hole")]
        # offset_mm (0, 0) places the file's own zero at the work zero (the home), as --offset 0,0 does (issue #45
        # point 5): the job starts there, and before hole n + 1 the head stands at hole n: live, not only at the end
        assert xs == [0.0, 1.0, 2.0], seen
        assert read_state(hold.path, MAXIMUS_SETTINGS).position_known
        emu.trip_limit_switch(LIMIT_SWITCH_X)
        ses.jog("x", 200)
        ses.wait_idle(30)
        assert ses.last_run["status"] != "finished"
        s = read_state(hold.path, MAXIMUS_SETTINGS)
        assert not s.position_known and s.unknown_reason, s
        # a go-to is refused; a jog would be allowed to find the work (issue #45 point 3: test_recovery.py)
        with pytest.raises(PositionUnknownError, match="unknown"):
            ses.go_to((0, 0, 0))
    finally:
        hold.close()


@pytest.mark.realtime
def test_at_real_speed_a_go_to_and_a_drill_job_from_the_work_zero(tmp_path, capsys):
    from cam.sim.maximus import start_emulator

    emu = start_emulator(speed=1.0)
    try:
        port, st = f"maximus:{emu.device_path}", str(tmp_path / "m.json")
        assert main(["where", "--set", "0,0,0", "--port", port, "--state", st]) == 0  # a new machine (#43 point 5)
        assert main(["goto", "200,100,0", "--unit", "steps", "--port", port, "--state", st]) == 0
        assert main(["zero", "XY", "--port", port, "--state", st]) == 0
        path = _board(tmp_path, ["T1", "X0.5Y-0.5", "X1.0Y-0.5"])
        assert main(["drill", str(path), "--yes", "--offset", "0,0", "--port", port, "--state", st,
                     "--travel-height", "0.1", "--cut-depth", "0.1"]) == 0, capsys.readouterr().err
        got = sorted((round((r[1] - 200) * MM, 2), round((r[2] + 100) * MM, 2)) for r in emu.hole_log())
        assert got == [(0.5, -0.5), (1.0, -0.5)]
        assert read_state(st, MAXIMUS_SETTINGS).position_steps == (200, 100, 0)
    finally:
        emu.stop()
