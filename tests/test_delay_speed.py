"""A speed setting means what it says (issue #32 point 7): --delay sets the top speed with every ramp kind or is
refused naming the setting that limits it, and cam info shows the effective top speeds."""
import pytest

from conftest import SAMPLES, run_cli


def test_a_delay_faster_than_the_top_speed_is_refused_naming_the_limit():
    r = run_cli("drill", SAMPLES / "board.drl", "--delay", "1,1", "--yes")
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip() == ("cam: error: --delay 1 ms asks X for 28.9 mm/s, over its top speed max_speed_x_mm_s = "
                                "5.78 mm/s: raise max_speed_x_mm_s in the machine file, use a delay of 5 ms or more, "
                                "or --ramp constant")


@pytest.mark.parametrize("ramp,speeds", [("lookahead", "X 2.89, Y 2.89, Z 1.57"),
                                          ("linear40", "X 2.89, Y 2.89, Z 1.57"),
                                          ("constant", "X 2.89, Y 2.89, Z 1.57")])
def test_a_slower_delay_is_the_top_speed_with_every_ramp(ramp, speeds):
    r = run_cli("info", SAMPLES / "ellipse.png", "--delay", "10,10", "--ramp", ramp)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[-1] == f"top speeds: {speeds} mm/s ({ramp} ramps, delays 10/10 ms)"


def test_info_shows_the_machine_limit_when_no_delay_is_given():
    r = run_cli("info", SAMPLES / "board.drl")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[-1] == "top speeds: X 5.78, Y 5.78, Z 3.14 mm/s (lookahead ramps, delays 5/5 ms)"


def test_a_constant_ramp_takes_any_delay():
    r = run_cli("info", SAMPLES / "board.drl", "--delay", "1,1", "--ramp", "constant")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[-1].startswith("top speeds: X 28.9, Y 28.9, Z 15.7 mm/s (constant ramps")
