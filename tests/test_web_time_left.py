"""Issue #47 point 7 in Chromium (Playwright): keyboard jogging refused while a job runs, and the time remaining
that follows the feed override and says "(paused)" while the job is paused or waits at a prompt.

The API-level twin of the feed-override check is ``test_web_track.test_time_left_follows_the_feed_override_on_grbl``;
these tests read what the page shows (``#remaining``, the error banner) and what requests it sends.
"""
from __future__ import annotations

import re
import time

import pytest

from conftest import SAMPLES
from test_web import MEDIUM, Server, browser  # noqa: F401  (the browser fixture: Debian chromium)
from test_web_track import DESKTOP, PHONE, _open_and_plan, _page

# counts the snapshots the page receives (window.__snapshots), so a test can wait for the page to have rendered a
# few newer ones instead of sleeping
_COUNT_SNAPSHOTS = """
(() => {
  window.__snapshots = 0;
  const Native = window.EventSource;
  window.EventSource = class extends Native {
    constructor(url, init) {
      super(url, init);
      this.addEventListener("message", () => { window.__snapshots += 1; });
    }
  };
})();
"""

_STATE_IS = "(want) => want.includes(document.getElementById('state').dataset.state)"


def _browser_page(browser, viewport):
    ctx, p = _page(browser, viewport)
    p.add_init_script(_COUNT_SNAPSHOTS)
    return ctx, p


def _wait_snapshots(p, n: int = 3) -> None:
    """Wait until the page has rendered ``n`` more snapshots (the server sends one every period while busy)."""
    p.wait_for_function("(k) => window.__snapshots >= k", arg=p.evaluate("window.__snapshots") + n, timeout=20_000)


def _remaining(p) -> tuple[int, bool]:
    """The page's time left in seconds (its ``h:mm:ss``) and whether it says "(paused)"."""
    text = p.inner_text("#remaining")
    m = re.fullmatch(r"(\d+):(\d\d):(\d\d)( \(paused\))?", text.strip())
    assert m, text
    return int(m[1]) * 3600 + int(m[2]) * 60 + int(m[3]), m[4] is not None


def _jog_requests(s: Server) -> list:
    return [seen for seen in s.seen if seen[1] == "/api/jog"]


def _press_refused(p, s: Server, key: str, *states: str) -> None:
    """A jog key while the machine is in one of ``states``: the page says why in one line and sends no jog."""
    if p.is_visible("#error-close"):
        p.click("#error-close")
    sent = len(_jog_requests(s))
    p.locator("body").press(key)
    p.wait_for_function("!document.getElementById('error').hidden")
    text = p.inner_text("#error-text")
    words = {"prompt": "waiting at a prompt"}
    assert text in [f"keyboard jog refused: the machine is {words.get(state, state)}" for state in states], text
    assert len(_jog_requests(s)) == sent


@pytest.mark.browser
def test_keyboard_jog_refused_while_a_job_runs_and_at_its_prompt(browser, tmp_path):
    """A drill job on the mock (real time, tool changes): while it runs and while it waits at a tool-change prompt the
    arrow and Page keys jog nothing (the page refuses in one line and sends no jog; the server refuses a jog too);
    at the prompt the time left stands still and says "(paused)"; after the job is stopped the keys jog again."""
    s = Server(tmp_path, settings=MEDIUM, realtime=True)
    ctx, p = _browser_page(browser, DESKTOP)
    try:
        _open_and_plan(p, s, SAMPLES / "board.drl")
        p.select_option("#jog-steps", "100")
        p.click("#start")
        p.wait_for_function(_STATE_IS, arg=["running"])
        before = s.session.position_steps()
        _press_refused(p, s, "ArrowRight", "running", "prompt")  # (a tool change may come meanwhile)
        status, err = s.call("POST", "/api/jog", {"axis": "x", "steps": 100, "unit": "steps"})
        assert status == 409 and "\n" not in err["error"], (status, err)

        p.wait_for_function(_STATE_IS, arg=["prompt"])  # the first tool change
        assert p.is_visible("#prompt-continue")
        _wait_snapshots(p)
        left, paused = _remaining(p)
        assert paused and left > 0, p.inner_text("#remaining")
        at_prompt = s.session.position_steps()
        _press_refused(p, s, "PageDown", "prompt")
        _press_refused(p, s, "ArrowLeft", "prompt")
        _wait_snapshots(p)
        assert _remaining(p) == (left, True)  # the time left stands still while the job waits
        assert s.session.position_steps() == at_prompt and s.session.state()["state"] == "prompt"

        p.click("#prompt-continue")
        p.wait_for_function(_STATE_IS, arg=["running"])
        p.wait_for_function("!document.getElementById('remaining').textContent.includes('paused')")
        _press_refused(p, s, "ArrowUp", "running", "prompt")
        assert s.session.position_steps() != before  # the job moved the tool; the keys did not get in its way

        p.click("#stop")
        p.wait_for_function(_STATE_IS, arg=["idle"])
        deadline = time.monotonic() + 30
        while s.session.busy:
            assert time.monotonic() < deadline
            p.wait_for_timeout(20)
        assert p.is_hidden("#error")  # Stop's request cleared the refusal
        start = s.session.position_steps()
        p.locator("body").press("ArrowRight")  # idle again: the key jogs
        deadline = time.monotonic() + 20
        while s.session.position_steps()[0] != start[0] + 100 or s.session.busy:
            assert time.monotonic() < deadline, s.session.position_steps()
            p.wait_for_timeout(20)
        assert ("POST", "/api/jog", 200) in s.seen
        assert p.is_hidden("#error")
    finally:
        ctx.close()
        s.close()


@pytest.mark.browser
def test_time_left_follows_the_feed_override_and_pauses_on_grbl(browser, tmp_path):
    """A job on the grbl emulator at phone size: with the feed override set to 50 % on the page, the page's time
    left is about twice the machine's; paused, it stands still and says "(paused)" (and the keys jog nothing);
    resumed and set back to 100 %, it is the machine's again."""
    from cam.drive.grbl_machine import close_grbl_machines
    from cam.sim.grbl import start_emulator
    from test_grbl_session import FAST as GRBL_FAST, SETTINGS as GRBL_SETTINGS

    emu = start_emulator(speed=1.0, settings=GRBL_FAST)
    s = Server(tmp_path, settings=GRBL_SETTINGS, machine_port=f"grbl:{emu.device_path}")
    ctx, p = _browser_page(browser, PHONE)

    def bracketed() -> tuple[float, int, float]:
        """(machine time left before, the page's time left, machine time left after) read in that order."""
        m0 = s.session.state()["remaining_s"]
        left, paused = _remaining(p)
        m1 = s.session.state()["remaining_s"]
        assert not paused
        return m0, left, m1

    def near(factor: float, m0: float, left: int, m1: float) -> bool:
        # the page shows whole seconds of a snapshot at most a period or two older than the first reading
        return factor * m1 - 1.0 <= left <= factor * m0 + 1.5

    try:
        _open_and_plan(p, s, SAMPLES / "two_curves.png")
        p.wait_for_function("!document.getElementById('grbl-row').hidden")
        p.fill("#feed-override", "50")
        p.click("#feed-set")
        deadline = time.monotonic() + 20
        while s.session.state().get("grbl", {}).get("feed_override_pct") != 50:
            assert time.monotonic() < deadline, s.session.state().get("grbl")
            p.wait_for_timeout(20)
        p.click("#start")
        p.wait_for_function(_STATE_IS, arg=["running"])

        checked, deadline = 0, time.monotonic() + 60
        while checked < 3:  # at 50 %: twice the machine's time left (far from once: more than 4 s left)
            assert time.monotonic() < deadline and s.session.busy, checked
            _wait_snapshots(p, 1)
            m0, left, m1 = bracketed()
            assert m1 > 4, (m0, left, m1)
            assert near(2.0, m0, left, m1), (m0, left, m1)
            checked += 1

        p.click("#pause")
        p.wait_for_function(_STATE_IS, arg=["paused"])
        p.wait_for_function("document.getElementById('remaining').textContent.endsWith(' (paused)')")
        _wait_snapshots(p)
        left, paused = _remaining(p)
        machine = s.session.state()["remaining_s"]
        assert paused and abs(left - 2 * machine) <= 1.0, (left, machine)
        _press_refused(p, s, "ArrowDown", "paused")
        _wait_snapshots(p)
        assert _remaining(p) == (left, True)  # it stands still while paused
        assert s.session.state()["remaining_s"] == machine

        p.click("#resume")
        p.wait_for_function(_STATE_IS, arg=["running"])
        p.wait_for_function("!document.getElementById('remaining').textContent.includes('paused')")
        p.fill("#feed-override", "100")
        p.click("#feed-set")
        deadline = time.monotonic() + 30
        while True:  # back at 100 %: the machine's own time left
            assert time.monotonic() < deadline and s.session.busy
            _wait_snapshots(p, 1)
            m0, left, m1 = bracketed()
            assert m1 > 2, (m0, left, m1)
            if s.session.state().get("grbl", {}).get("feed_override_pct") == 100 and near(1.0, m0, left, m1):
                break
        p.click("#stop")
        p.wait_for_function(_STATE_IS, arg=["idle"])
        s.wait_idle(60)
    finally:
        ctx.close()
        s.close()
        close_grbl_machines()
        emu.stop()
