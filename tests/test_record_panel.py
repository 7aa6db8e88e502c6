"""The panel's Record card against the real recorder (issue 34): gui_bridge finds the
recorder by its node name, shows what its `diagnostics` say, and its buttons call the
recorder: Record sets the `task` parameter to the field's text and starts an episode,
Save saves it (the dataset's episode count goes to 1); a call the recorder does not
answer (the recorder stopped with SIGSTOP) is reported on the card as such, and the
teleop goes on meanwhile. The page shows the red REC banner while recording, with the
elapsed time ticking. Driven through the panel's WebSocket as the page drives it."""
import signal
import time

import pytest

from conftest import OUTPUT
from test_gui_bridge import RawWs, start_panel

# in a process of its own beside the other tests (judged by order and content, not the wall clock)
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=15)]

TASK = "pick the cube"


def card(ws, pred, timeout=10.0, what="the card"):
    """The next `recorder` message for which `pred` holds."""
    seen = []

    def check(m):
        if m.get("t") == "recorder":
            seen.append(m)
            return pred(m)
        return False
    try:
        return ws.recv_json(check, timeout=timeout)
    except TimeoutError:
        raise AssertionError(f"{what}: not seen within {timeout} s; the last cards: {seen[-3:]}") from None


def test_record_save_and_a_call_without_answer_from_the_panel(launch, observer, browser, tmp_path):
    launch("compute_ik")
    launch("serial_node", "--ros-args", "-p", "port:=mock")
    recorder = launch("recorder", "--ros-args", "-p", f"root:={tmp_path / 'ds'}", "-p", "task:=the parameter's task")
    _, port = start_panel(launch, observer, "-p", "foxglove_bind:=")
    ws = RawWs(port, headers={"Origin": f"http://127.0.0.1:{port}"})
    try:
        hello = ws.recv_json(lambda m: m["t"] == "hello")
        assert hello["recorder"]["node"] == "recorder", hello["recorder"]
        # 1. the recorder heard: idle, nothing saved yet, Record enabled
        idle = card(ws, lambda m: m["up"] and m["state"] == "idle" and m["can_start"], 20, "the recorder idle")
        assert idle["episodes"] == 0 and not idle["can_save"] and not idle["can_discard"], idle
        assert idle["task"] == "the parameter's task", idle

        # 2. Record: the field's text becomes the task, the episode runs, its time goes on
        ws.send({"t": "record", "op": "start", "task": f"  {TASK} "})
        started = card(ws, lambda m: m["call"] is not None and m["call"]["op"] == "start", 10, "the start's outcome")
        assert started["call"]["ok"], started["call"]
        running = card(ws, lambda m: m["state"] == "recording" and (m["elapsed_s"] or 0) >= 1.0 and (m["frames"] or 0) > 0,
                       10, "recording for a second")
        assert running["task"] == TASK and running["episode"] == 0, running
        assert running["can_save"] and running["can_discard"] and not running["can_start"], running
        # a second start while recording is refused by the panel (the button is off)
        ws.send({"t": "record", "op": "start", "task": TASK})
        refused = ws.recv_json(lambda m: m["t"] == "refused")
        assert "being recorded" in refused["reason"], refused

        # the page: the red REC banner with the episode, its elapsed time ticking
        page = browser.new_page(viewport={"width": 1280, "height": 820})
        console = []
        page.on("console", lambda m: console.append((m.type, m.text)) if m.type in ("error", "warning") else None)
        page.on("pageerror", lambda e: console.append(("pageerror", str(e))))
        try:
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_function("() => !document.getElementById('rec-banner').hidden", timeout=10000)
            banner = page.inner_text("#rec-banner")
            assert "REC episode 0" in banner and TASK in banner, banner
            first = page.inner_text("#rec-elapsed")
            page.wait_for_function(f"() => document.getElementById('rec-elapsed').textContent !== {first!r}", timeout=5000)
            assert page.is_disabled("#rec-start") and page.is_enabled("#rec-save"), "the buttons while recording"
            OUTPUT.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(OUTPUT / "gui_panel_record.png"))
            # (Chromium's software GL reports a stall when the screenshot reads the pixels: the test's doing)
            page_said = [(k, m) for k, m in console if "GL Driver Message (OpenGL, Performance" not in m]
            assert not page_said, page_said
        finally:
            page.close()

        # 3. Save: the dataset has one episode
        ws.send({"t": "record", "op": "save"})
        saved = card(ws, lambda m: m["call"] is not None and m["call"]["op"] == "save", 35, "the save's outcome")
        assert saved["call"]["ok"], saved["call"]
        card(ws, lambda m: m["state"] == "idle" and m["episodes"] == 1 and m["can_start"], 10, "one episode saved")

        # 4. a call without an answer: the recorder stopped (SIGSTOP) right after a start
        ws.send({"t": "record", "op": "start", "task": TASK})
        card(ws, lambda m: m["state"] == "recording" and m["can_discard"], 10, "the second episode")
        recorder.proc.send_signal(signal.SIGSTOP)
        try:
            ws.send({"t": "record", "op": "discard"})
            # the teleop goes on while the call waits
            ws.send({"t": "target", "xyz": [0.2, 0.0, 0.15]})
            assert ws.recv_json(lambda m: m["t"] in ("ack", "refused"))["t"] == "ack"
            lost = card(ws, lambda m: m["call"] is not None and m["call"]["op"] == "discard", 10, "the discard's outcome")
            assert not lost["call"]["ok"] and "did not answer" in lost["call"]["text"], lost["call"]
        finally:
            recorder.proc.send_signal(signal.SIGCONT)
        # the recorder back: it reports again, still one episode saved
        back = card(ws, lambda m: m["up"] and m["state"] in ("idle", "recording"), 10, "the recorder back")
        assert back["episodes"] == 1, back
    finally:
        ws.close()
