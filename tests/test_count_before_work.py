"""Count before work (issue #32 point 3): a canned cycle knows its pecks and repeats before it makes one, and
refuses past a documented limit in one line naming the count."""
from cam.formats._gcode_cycles import MAX_PECKS

from conftest import run_cli


def test_a_peck_of_a_tenth_of_a_nanometre_is_refused_naming_the_count(tmp_path):
    prog = tmp_path / "peck.ngc"
    prog.write_text("G21 G90\nG0 Z5\nG83 X1 Y1 Z-100 R1 Q0.0000001 F100\nM2\n")  # a billion pecks: 60 s+ before
    for command in ("info", "drill", "preview"):
        args = [command, prog] + (["--yes"] if command == "drill" else [])
        if command == "preview":
            args += ["-o", tmp_path / "p.png"]
        r = run_cli(*args)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, (command, r.stderr)
        assert "peck.ngc:3: canned cycle G83 would peck 1,010,000,000 times" in r.stderr
        assert f"at most {MAX_PECKS:,} pecks a hole" in r.stderr


def test_a_reasonable_peck_still_drills(tmp_path):
    prog = tmp_path / "peck.ngc"
    prog.write_text("G21 G90\nG0 Z5\nG83 X1 Y-1 Z-3 R1 Q0.5 F100\nG80\nM2\n")
    r = run_cli("info", prog)
    assert r.returncode == 0, r.stderr
