"""A job on a grbl board keeps a journal and resumes from it (issue #45 point 3).

grbl's ``ok`` says a line entered its planner, not that it ran: the journal's last move comes from where grbl reports
the tool (cam.drive.grbl_journal), so it is never ahead of the machine.  Each test runs a job on the grbl emulator
(cam.sim.grbl) on a pty, stops it in the middle of a cut (the machine session's stop, or SIGINT to a ``cam drill``
process at real speed) and resumes it from its journal.  The oracle is what the emulator executed: the job's points
up to the journal's last move lie on the path it ran before the stop, in order (sampled while the job runs, too);
the resumed run starts with a lift and the job's points from the move it resumes at lie on the path it ran after;
the moves between cut nothing; a drawing carves from both runs together exactly what it carves uninterrupted.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

import cam
from cam.drive.grbl_journal import GrblLines, on_path_tolerance_steps
from cam.drive.grbl_machine import PATH_TOLERANCE_STEPS, close_grbl_machines, job_lines
from cam.drive.journal import read_journal
from cam.drive.session import MachineSession
from cam.kinds.jobs import JobOptions, prepare_job, resume_job
from cam.job.resume import cutting_moves
from cam.sim.grbl import start_emulator
from cam.verify.pinlog import Motion, carve
from conftest import ROOT, SAMPLES, run_cli
from support.grbl import quick_thread_switches  # noqa: F401 (autouse)
from test_grbl_session import FAST, known_at_home, url

# over 2 s: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES = {"test_a_job_stopped_in_a_cut_resumes_on_grbl_and_nothing_is_skipped[hpgl]"}

SETTINGS = cam.MachineSettings()
MM_PER_STEP = np.array([SETTINGS.mm_per_step_xy, -SETTINGS.mm_per_step_xy, -SETTINGS.mm_per_step_z])
ON_PATH = PATH_TOLERANCE_STEPS + 0.5 + 1e-6
"""How far a job's point may lie from the lines grbl ran: the lines join runs of points within
PATH_TOLERANCE_STEPS of them, and a resumed run starts from the stop rounded to whole steps (half a step)."""
DRAWING_OPTIONS = JobOptions(depth=(3,))
GUARD_S = 60.0
"""A failure guard: every wait ends as its condition comes."""


def frame_png(tmp_path: Path) -> Path:
    """A frame and a filled block, 30 x 14 px: 59 lines to grbl, 7 s at real speed on FAST settings."""
    img = np.full((14, 30), 255, np.uint8)
    img[2:12, 2:14] = 0
    img[4:10, 4:12] = 255
    img[3:11, 18:28] = 0
    path = tmp_path / "frame.png"
    cv2.imwrite(str(path), img)
    return path


def points_of(job) -> np.ndarray:
    """The job's points in order, steps from its home: (N, 3)."""
    return np.concatenate([np.asarray(p.points_steps, np.int64).reshape(-1, 3) for p in job.toolpath.pieces()])


def steps_of(mm) -> np.ndarray:
    """grbl's machine mm as cam's machine steps, not rounded (+Y toward the operator, +Z deeper)."""
    return np.asarray(mm, np.float64)[..., :3] / MM_PER_STEP


def ran(blocks, origin_mm, origin_steps) -> np.ndarray:
    """The path grbl ran (G0/G1 blocks, in order), steps in the job's frame: the first block's start, then each
    block's end (a halted block's end is where it stopped); ``origin_mm`` of grbl's frame is ``origin_steps``."""
    moves = [b for b in blocks if b.kind in ("G0", "G1")]
    if not moves:
        return np.zeros((0, 3))
    mm = np.array([moves[0].start_mm] + [b.end_mm for b in moves])
    return steps_of(mm) - steps_of(origin_mm) + np.asarray(origin_steps, np.float64)


def on_path(points: np.ndarray, path: np.ndarray, tolerance: float = ON_PATH) -> int:
    """How many of ``points`` (from the first) lie on the polyline ``path`` within ``tolerance`` steps, in order."""
    points = np.asarray(points, np.float64)
    if not len(path):
        return 0
    segments = [(path[0], path[0])] if len(path) == 1 else list(zip(path[:-1], path[1:]))
    j = 0
    for i, p in enumerate(points):
        while j < len(segments):
            a, b = segments[j]
            ab = b - a
            t = min(1.0, max(0.0, float((p - a) @ ab) / float(ab @ ab))) if ab.any() else 0.0
            if np.linalg.norm(p - (a + t * ab)) <= tolerance:
                break
            j += 1
        else:
            return i
    return len(points)


def stepped(path: np.ndarray) -> Motion:
    """A point tool along ``path`` ((N, 3) steps), at every step of each segment's longest axis."""
    out = [np.rint(path[0])]
    for a, b in zip(path[:-1], path[1:]):
        n = int(np.ceil(np.abs(b - a).max()))
        out += [np.rint(a + (b - a) * k / n) for k in range(1, n + 1)]
    pos = np.asarray(out, np.int64)
    return Motion(t_ns=np.arange(len(pos), dtype=np.int64), position_steps=pos, step_counts=np.zeros(3, np.int64))


def cutting_at_depth(emu, remaining_mm: float = 1.0) -> bool:
    """The emulator runs a cut at the job's depth (a level line below where the job started: Z < 0 in grbl's frame
    of a job started at its machine zero) with at least ``remaining_mm`` to go: a stop lands in it (the emulator's
    running block and position, read under its lock)."""
    with emu._lock:
        if not emu._planner:
            return False
        block = emu._planner[0]
        left = np.linalg.norm(np.subtract(block.end, emu._pos))
        return (not block.rapid and block.start[2] == block.end[2] and block.end[2] < -1e-6
                and left >= remaining_mm)


class NeverAhead:
    """Reads the journal while the job runs and holds each record against what the emulator has run since: the job's
    points up to its last move lie on that path, in order (the journal is never ahead of the machine)."""

    def __init__(self, emu, journal: Path, points: np.ndarray, origin_mm, origin_steps=(0, 0, 0)) -> None:
        self.emu, self.journal, self.points = emu, journal, points
        self.origin_mm, self.origin_steps = origin_mm, origin_steps
        self.checked: list[int] = []
        self._seen: object = None

    def check(self) -> bool:
        """Check the journal if it changed (a record checked once stays true: the machine only goes on); True."""
        try:
            stat = self.journal.stat()
        except FileNotFoundError:
            return True
        if (stat.st_mtime_ns, stat.st_size, stat.st_ino) == self._seen:
            return True
        self._seen = (stat.st_mtime_ns, stat.st_size, stat.st_ino)
        record = read_journal(self.journal)
        with self.emu._lock:  # what ran so far, and where the tool is in the block it runs now
            blocks, here = list(self.emu._executed), tuple(self.emu._pos)
        path = ran(blocks, self.origin_mm, self.origin_steps)
        now = steps_of(here) - steps_of(self.origin_mm) + np.asarray(self.origin_steps, np.float64)
        path = np.vstack([path, now]) if len(path) else np.vstack([np.asarray(self.origin_steps, np.float64), now])
        m = record.last_move
        assert on_path(self.points[:m + 1], path) == m + 1, (m, record)
        self.checked.append(m)
        return True


def check_resumed(job, journal_record, before: np.ndarray, after: np.ndarray) -> None:
    """The stop and the resume together run the whole job: its points up to the journal's last move lie on the path
    run ``before`` the stop (the journal is not ahead), the resumed run starts with a lift straight up (within the
    stop's rounding to whole steps), its points from the move resumed at lie on the path run ``after``, and the
    moves between cut nothing."""
    points = points_of(job)
    k = journal_record.last_move
    assert on_path(points[:k + 1], before) == k + 1, "the journal is ahead of the machine"
    # where grbl reported the stop, to the whole step (its report has 3 decimals of a mm)
    assert np.abs(before[-1] - journal_record.position_steps).max() <= 0.52, (before[-1], journal_record)
    lift = after[1] - after[0]
    assert lift[2] < 0 and np.abs(lift[:2]).max() <= 0.5 + 1e-6, ("the resumed run starts with a lift", after[:3])
    resumed = resume_job(job, journal_record)
    j = resumed.report["resumed_at_move"]
    assert j > k
    assert not cutting_moves(job.toolpath)[k + 1:j].any(), "a move that cuts was skipped"
    assert on_path(points[j:], after) == len(points) - j, "the resumed run left out a move of the job"


def drawing_carves_as_uninterrupted(job, before: np.ndarray, after: np.ndarray) -> None:
    """A point tool along the path run before the stop and then after the resume carves, pixel by pixel, what it
    carves along the job's own points, never deeper."""
    tp = job.toolpath
    shape = (tp.height_px, tp.width_px)
    whole = carve(stepped(np.vstack([np.zeros((1, 3)), points_of(job)]).astype(np.float64)), shape, SETTINGS,
                  origin_px=tp.origin_px)
    both = stepped(np.vstack([before, after]))
    got = carve(both, shape, SETTINGS, origin_px=tp.origin_px)
    assert np.array_equal(got, whole), np.argwhere(got != whole)[:5]
    assert both.position_steps[:, 2].max() == points_of(job)[:, 2].max(), "never deeper than the job asks"


# ---------------------------------------------------------------------------------------------------------------
def test_the_search_takes_the_first_line_a_position_lies_on():
    """A plunge and its retract at one X, Y: a position half way down lies on both; the plunge (the earlier line) is
    taken, so only the line before it counts as done, never the retract.  A position on no line changes nothing; a
    position further on frees the lines before its line, and every line is done once grbl stands idle after them."""
    lines = GrblLines(3.0)
    for end, last in (((100, 0, 0), 4), ((100, 0, 50), 5), ((100, 0, 0), 6), ((200, 0, 0), 9)):
        lines.add(np.array(end), last)
    assert lines.seen_at((0, 0, 0)) == -1  # at the start: on the first line
    assert lines.seen_at((100, 0, 25)) == 4  # on the plunge (and on the retract): the travel before it is done
    assert lines.seen_at((500, 500, 0)) == 4  # on no line
    assert lines.seen_at((150, 1.5, 0)) == 6  # on the last line
    assert lines.seen_at((100, 0, 25)) == 6  # never back
    lines.all_done(12)
    assert lines.done_point == 12
    assert on_path_tolerance_steps({100: 1 / SETTINGS.mm_per_step_xy, 101: 1 / SETTINGS.mm_per_step_xy,
                                    102: 1 / SETTINGS.mm_per_step_z}, SETTINGS) == 3.0
    assert on_path_tolerance_steps({100: 0.5 / SETTINGS.mm_per_step_xy}, SETTINGS) == 6.0  # grbl's step is 2 of cam's


@pytest.mark.parametrize("kind", ["drawing", "hpgl"])
def test_a_job_stopped_in_a_cut_resumes_on_grbl_and_nothing_is_skipped(kind, tmp_path):
    """Through the machine session (as the page runs it): a drawing and an HPGL file (its pen prompt answered) are
    stopped in the middle of a cut and resumed from the journal; the journal was never ahead while the job ran, it
    ends with where grbl reports the stop, the resumed run lifts first and goes on with nothing skipped, and the
    resumed run's journal ends finished."""
    if kind == "drawing":  # 59 lines of 0.2-2.5 mm at 6 mm/s: stopped after a third of them
        job, speed, after_blocks, remaining_mm = prepare_job(frame_png(tmp_path), DRAWING_OPTIONS, SETTINGS), 10.0, \
            19, 1.0
    else:  # 35 s: a star of 10 lines of 14-18 mm at 7 mm/s, then a circle: stopped in the star's 4th line or later
        job, speed, after_blocks, remaining_mm = prepare_job(SAMPLES / "inkscape_star.plt", None, SETTINGS), 40.0, \
            5, 5.0
    journal = tmp_path / "job.journal.json"
    emu = start_emulator(speed=speed, settings=FAST)
    try:
        session = MachineSession(url(emu), SETTINGS, on_prompt=lambda prompt: "continue")
        origin_mm = emu.machine_position_mm
        watch = NeverAhead(emu, journal, points_of(job), origin_mm)
        session.start(job, journal=str(journal))
        # in a cut with room left for the stop to land in (a second of simulated time each 25 ms of a busy computer's
        # wall clock)
        assert emu.wait_for(lambda e: watch.check() and len(e.executed()) >= after_blocks
                            and cutting_at_depth(e, remaining_mm), GUARD_S), emu.executed()[-3:]
        session.stop()
        while not session.wait_idle(0.02):
            watch.check()
        assert session.last_run["status"] == "stopped", session.last_run
        assert session.last_run["journal"] == str(journal)
        watch.check()
        record = read_journal(journal)
        assert record.state == "stopped" and 0 <= record.last_move < record.moves - 1, record
        before = ran(emu.executed(), origin_mm, (0, 0, 0))
        # the journal holds where grbl reports the stop: the session's position, to the step
        assert tuple(record.position_steps) == session.position_steps()
        assert np.abs(before[-1] - record.position_steps).max() <= 0.52  # (MPos is reported to 0.001 mm)
        assert record.position_steps[2] > 0, "stopped below the surface (the resumed run lifts)"
        n0 = len(emu.executed())
        session.start(resume_job(job, record), journal=str(journal))
        assert session.wait_idle(GUARD_S)
        assert session.last_run["status"] == "finished", session.last_run
        after = ran(emu.executed()[n0:], origin_mm, (0, 0, 0))
        check_resumed(job, record, before, after)
        if kind == "drawing":
            drawing_carves_as_uninterrupted(job, before, after)
        final, j = read_journal(journal), resume_job(job, record).report["resumed_at_move"]
        assert (final.state, final.last_move, final.resumed_at_move) == ("finished", final.moves - 1, j)
    finally:
        close_grbl_machines()
        emu.stop()
    assert emu.error is None


def test_a_stop_at_a_tool_change_resumes_with_the_tool_change(tmp_path):
    """Answered with stop, a drill file's tool-change prompt leaves the journal at the pause, pending (grbl stood
    still there: every line sent is done): the resumed run asks for the tool again before its next hole."""
    path = tmp_path / "two.drl"
    path.write_text("M48\nMETRIC\nT1C0.8\nT2C1.0\n%\nT1\nX1.0Y-1.0\nX2.0Y-1.0\nT2\nX3.0Y-2.0\nM30\n")
    job = prepare_job(path, None, SETTINGS)
    journal = tmp_path / "two.journal.json"
    notes: list[str] = []
    answers = iter(["continue", "stop"])

    def on_prompt(prompt):
        notes.append(prompt.note)
        return next(answers, "continue")

    emu = start_emulator(speed=20.0, settings=FAST)
    try:
        session = MachineSession(url(emu), SETTINGS, on_prompt=on_prompt)
        session.start(job, journal=str(journal))
        assert session.wait_idle(GUARD_S)
        assert session.last_run["status"] == "stopped", session.last_run
        record = read_journal(journal)
        pauses = np.flatnonzero(np.concatenate([np.asarray(p.pause, bool) for p in job.toolpath.pieces()]))
        assert record.pause_pending and record.last_move == pauses[1], (record, pauses)
        asked = len(notes)
        session.start(resume_job(job, record), journal=str(journal))
        assert session.wait_idle(GUARD_S)
        assert session.last_run["status"] == "finished", session.last_run
        assert notes[asked:][:1] == [notes[1]], notes  # the tool asked for again first
        assert read_journal(journal).state == "finished"
    finally:
        close_grbl_machines()
        emu.stop()
    assert emu.error is None


def test_resume_with_a_journal_of_another_file_is_one_line(tmp_path):
    """``cam drill B --port grbl:... --resume`` with the journal of file A: one line, exit 2, nothing sent to grbl."""
    emu = start_emulator(speed=200.0, settings=FAST)
    try:
        state = str(known_at_home(tmp_path / "s.json"))
        a, journal = tmp_path / "a.drl", tmp_path / "a.journal.json"
        a.write_text("M48\nMETRIC\nT1C0.8\n%\nT1\nX1.0Y-1.0\nM30\n")
        r = run_cli("drill", a, "--yes", "--port", url(emu), "--state", state, "--journal", journal)
        assert r.returncode == 0, r.stderr
        assert read_journal(journal).state == "finished"
        close_grbl_machines()  # as a new process
        n_lines, n_blocks = len(emu.lines()), len(emu.executed())
        r = run_cli("drill", frame_png(tmp_path), "--depth", "3", "--port", url(emu), "--state", state,
                    "--resume", journal)
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        error = [line for line in r.stderr.splitlines() if line.strip() and not line.startswith("warning:")]
        assert len(error) == 1 and "another input" in error[0] and str(journal) in error[0], r.stderr
        assert len(emu.executed()) == n_blocks
        assert not [t for _, t, _ in emu.lines()[n_lines:] if t[:1] in "GXYZ" or t.startswith("$J")]
    finally:
        close_grbl_machines()
        emu.stop()
    assert emu.error is None


@pytest.mark.realtime
def test_at_real_speed_ctrl_c_in_a_cut_then_cam_drill_resume_runs_the_rest(tmp_path):
    """``cam drill frame.png --port grbl:...`` at real speed, Ctrl-C (SIGINT) in the middle of a cut: exit 130, the
    journal closed ``stopped`` at the position grbl reports, never ahead while the job ran; ``cam drill --resume``
    (a new process: the Arduino restarts when the port opens, cam keeps the state file's frame) lifts first, runs
    the rest, and the two runs carve what the drawing asks."""
    emu = start_emulator(speed=1.0, settings=FAST)
    try:
        png, journal, state = frame_png(tmp_path), tmp_path / "frame.journal.json", known_at_home(tmp_path / "s.json")
        common = ["--depth", "3", "--port", url(emu), "--state", str(state)]
        job = prepare_job(png, DRAWING_OPTIONS, SETTINGS)
        env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        proc = subprocess.Popen([sys.executable, "-m", "cam", "drill", str(png), *common, "--journal", str(journal)],
                                cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            # grbl restarts when the process opens the port: its machine zero is where the tool stands, the home
            assert emu.wait_for(lambda e: any(b.kind == "G1" for b in e.executed()), GUARD_S), proc.poll()
            watch = NeverAhead(emu, journal, points_of(job), (0.0, 0.0, 0.0))
            n_lines = sum(isinstance(item, str) for item in job_lines(job.plan.job, (0, 0, 0), (0, 0, 0), SETTINGS))
            assert emu.wait_for(lambda e: watch.check() and len(e.executed()) >= n_lines // 3 and cutting_at_depth(e),
                                GUARD_S), (emu.executed()[-3:], proc.poll())
            proc.send_signal(signal.SIGINT)
            out, err = proc.communicate(timeout=GUARD_S)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
        assert proc.returncode == 130, err
        watch.check()
        assert len(watch.checked) >= 3, watch.checked
        record = read_journal(journal)
        assert record.state == "stopped" and record.identity == job.identity, record
        before = ran(emu.executed(), (0.0, 0.0, 0.0), (0, 0, 0))
        stop_mm = emu.machine_position_mm
        reported = tuple(int(round(v)) for v in steps_of(np.round(stop_mm, 3)))
        assert tuple(record.position_steps) == reported, (record.position_steps, stop_mm)
        assert record.position_steps[2] > 0, "stopped below the surface (the resumed run lifts)"
        n0 = len(emu.executed())
        r = run_cli("drill", png, *common, "--resume", journal)
        assert r.returncode == 0, r.stderr
        assert f"resuming at move {resume_job(job, record).report['resumed_at_move']}" in r.stderr, r.stderr
        # the new process's grbl restarted where the tool stood: its zero is the stop
        after = ran(emu.executed()[n0:], (0.0, 0.0, 0.0), before[-1])
        check_resumed(job, record, before, after)
        drawing_carves_as_uninterrupted(job, before, after)
        assert read_journal(journal).state == "finished"
        assert emu.overflow_bytes == 0
    finally:
        close_grbl_machines()
        emu.stop()
    assert emu.error is None
