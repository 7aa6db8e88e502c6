"""gui_bridge: the web panel in headless Chromium (Playwright with Debian's chromium),
observed by real rclpy; and the command-line driver (once, play, record)."""
import math
import os
import signal
import socket
import statistics
import subprocess
import time

import pytest
from geometry_msgs.msg import PointStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64

from conftest import LATCHED, OUTPUT, REPO, bin_path

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]

# A gamepad the page reads through navigator.getGamepads(); the test moves its sticks
# and buttons through window.__pad.
FAKE_GAMEPAD = """
window.__pad = { axes: [0, 0, 0, 0], pressed: new Array(16).fill(false) };
navigator.getGamepads = () => [{
  id: "test pad", index: 0, connected: true, mapping: "standard", timestamp: performance.now(),
  axes: window.__pad.axes.slice(),
  buttons: window.__pad.pressed.map((p) => ({ pressed: p, touched: p, value: p ? 1 : 0 })),
}];
"""


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


class Panel:
    def __init__(self, launch, observer, browser, with_arm=False):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}/"
        if with_arm:
            launch("compute_ik")
            launch("state_publisher")
            launch("serial_node", "--ros-args", "-p", "port:=mock")
        self.proc = launch("gui_bridge", "--ros-args", "-p", f"bind:=127.0.0.1:{self.port}")
        self.o = observer
        self.xyz = observer.sub("/xyz_target", PointStamped)
        self.gripper = observer.sub("/gripper_target", Float64)
        self.joints = observer.sub("/joint_target", JointState)
        self.estop = observer.sub("/estop", Bool, LATCHED)
        observer.wait_publisher("/xyz_target")
        deadline = time.monotonic() + 15
        while True:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.5).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "the web server did not come up"
                time.sleep(0.05)
        self.requests, self.bytes = [], 0
        self.page = browser.new_page(viewport={"width": 1280, "height": 820})
        self.page.add_init_script(FAKE_GAMEPAD)
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.on("response", lambda r: self._count(r))
        self.page.goto(self.url)
        self.page.wait_for_function("() => window.__sent !== undefined || document.getElementById('ws-dot').className.includes('up')")

    def _count(self, response):
        try:
            self.bytes += len(response.body())
        except Exception:  # websocket upgrade has no body
            pass

    def set_slider(self, sid, value):
        self.page.eval_on_selector(f"#{sid}", "(el, v) => { el.value = v; el.dispatchEvent(new Event('input')); }", value)

    def spin_until(self, pred, timeout=5):
        return self.o.spin_until(pred, timeout)

    def close(self):
        self.page.close()


@pytest.fixture
def panel(launch, observer, browser):
    p = Panel(launch, observer, browser)
    yield p
    p.close()


def test_slider_moves_reach_rclpy_with_their_values(panel):
    panel.set_slider("x", 0.2)
    panel.set_slider("y", 0.0)
    panel.set_slider("z", 0.15)
    assert panel.spin_until(lambda: panel.xyz and [round(v, 4) for v in (panel.xyz[-1][1].point.x, panel.xyz[-1][1].point.y, panel.xyz[-1][1].point.z)] == [0.2, 0.0, 0.15])
    m = panel.xyz[-1][1]
    assert m.header.frame_id == "base_link" and (m.header.stamp.sec, m.header.stamp.nanosec) != (0, 0)
    # slider change -> xyz_target received by rclpy, measured (reported, not asserted): the
    # page stamps the input event with the wall clock, the rclpy callback its arrival
    arrivals = []
    panel.o.node.create_subscription(PointStamped, "/xyz_target", lambda m: arrivals.append((time.time(), m.point.y)), 10)
    panel.o.spin_for(0.5)
    delays = []
    for i in range(40):
        panel.o.spin_for(0.03)  # past the 50 Hz limit, so each move goes out at once
        y = round(0.001 * (i + 1), 3)
        t_input = panel.page.eval_on_selector(
            "#y", "(el, v) => { el.value = v; const t = performance.timeOrigin + performance.now(); el.dispatchEvent(new Event('input')); return t; }", y)
        assert panel.spin_until(lambda: any(abs(v - y) < 1e-9 for _, v in arrivals), 2)
        t_arrival = [t for t, v in arrivals if abs(v - y) < 1e-9][0]
        delays.append(t_arrival * 1e3 - t_input)
    OUTPUT.mkdir(parents=True, exist_ok=True)
    (OUTPUT / "gui_slider_latency.txt").write_text(
        f"slider input event -> xyz_target at rclpy: p50 {statistics.median(delays):.2f} ms, "
        f"p90 {sorted(delays)[int(0.9 * len(delays))]:.2f} ms, max {max(delays):.2f} ms over {len(delays)}\n")
    print((OUTPUT / "gui_slider_latency.txt").read_text())


def test_keyboard_jog_moves_the_target_by_the_step(panel):
    panel.set_slider("x", 0.2)
    panel.set_slider("y", 0.0)
    panel.set_slider("z", 0.15)
    assert panel.spin_until(lambda: panel.xyz and abs(panel.xyz[-1][1].point.z - 0.15) < 1e-9)
    panel.o.spin_for(0.1)
    panel.page.evaluate("() => document.activeElement && document.activeElement.blur()")
    n = len(panel.xyz)
    panel.page.keyboard.press("w")  # +x by the default 5 mm step
    assert panel.spin_until(lambda: len(panel.xyz) > n)
    p = panel.xyz[-1][1].point
    assert (p.x, p.y, p.z) == pytest.approx((0.205, 0.0, 0.15), abs=1e-9)
    panel.page.select_option("#step", "0.01")
    panel.page.evaluate("() => document.activeElement && document.activeElement.blur()")
    panel.o.spin_for(0.05)
    n = len(panel.xyz)
    panel.page.keyboard.press("q")  # +z by 10 mm
    assert panel.spin_until(lambda: len(panel.xyz) > n)
    p = panel.xyz[-1][1].point
    assert (p.x, p.y, p.z) == pytest.approx((0.205, 0.0, 0.16), abs=1e-9)
    n = len(panel.xyz)
    panel.page.keyboard.press("ArrowRight")  # -y
    assert panel.spin_until(lambda: len(panel.xyz) > n)
    assert panel.xyz[-1][1].point.y == pytest.approx(-0.01, abs=1e-9)


def test_gamepad_moves_only_while_the_deadman_is_held(panel):
    panel.set_slider("x", 0.2)
    panel.set_slider("y", 0.0)
    panel.set_slider("z", 0.15)
    assert panel.spin_until(lambda: panel.xyz and abs(panel.xyz[-1][1].point.z - 0.15) < 1e-9)
    panel.o.spin_for(0.2)
    n = len(panel.xyz)
    panel.page.evaluate("() => { window.__pad.axes[1] = -1; }")  # stick forward, deadman released
    panel.o.spin_for(0.6)
    assert len(panel.xyz) == n, "moved without the deadman"
    panel.page.evaluate("() => { window.__pad.pressed[4] = true; }")  # hold LB
    assert panel.spin_until(lambda: len(panel.xyz) > n + 3)
    panel.o.spin_for(0.4)
    panel.page.evaluate("() => { window.__pad.pressed[4] = false; }")
    panel.o.spin_for(0.3)
    moved = panel.xyz[-1][1].point.x
    assert moved > 0.2 + 0.005, "the stick should have moved the tool forward"
    n = len(panel.xyz)
    panel.o.spin_for(0.6)
    assert len(panel.xyz) == n, "kept moving after the deadman was released"


def test_unreachable_position_shows_the_reason_and_sends_nothing(panel):
    panel.set_slider("x", 0.2)
    panel.set_slider("z", 0.15)
    assert panel.spin_until(lambda: panel.xyz and abs(panel.xyz[-1][1].point.z - 0.15) < 1e-9)
    panel.o.spin_for(0.2)
    n = len(panel.xyz)
    panel.set_slider("x", 0.3)
    panel.page.wait_for_function("() => document.getElementById('reach').textContent === 'unreachable'")
    reason = panel.page.inner_text("#reason")
    assert "out of reach" in reason or "outside its limits" in reason, reason
    panel.o.spin_for(0.5)
    assert len(panel.xyz) == n and all(m.point.x != 0.3 for _, m in panel.xyz)
    # typing a number shows reachability before anything is sent
    panel.page.fill("#z_num", "0.05")
    panel.page.dispatch_event("#z_num", "input")
    panel.page.wait_for_function("() => document.getElementById('reach').textContent === 'unreachable'")
    panel.o.spin_for(0.3)
    assert len(panel.xyz) == n


def test_estop_button_publishes_estop(panel):
    panel.page.click("#estop")
    assert panel.spin_until(lambda: panel.estop and panel.estop[-1][1].data is True)
    assert "ENGAGED" in panel.page.inner_text("#estop-state")
    panel.page.click("#release")
    assert panel.spin_until(lambda: panel.estop[-1][1].data is False)


def test_joint_mode_and_gripper(panel):
    panel.page.click("#mode-joint")
    panel.set_slider("j_base_joint", 0.3)
    assert panel.spin_until(lambda: panel.joints and panel.joints[-1][1].name == ["base_joint"])
    assert panel.joints[-1][1].position[0] == pytest.approx(0.3, abs=1e-3)  # the slider's 1 mrad step
    panel.set_slider("gripper", 0.75)
    assert panel.spin_until(lambda: panel.gripper and panel.gripper[-1][1].data == pytest.approx(0.75))


def test_page_is_small_local_and_shows_the_live_arm(launch, observer, browser):
    p = Panel(launch, observer, browser, with_arm=True)
    try:
        p.page.wait_for_function("() => document.getElementById('pose').textContent.includes('tool0')", timeout=20000)
        p.set_slider("x", 0.22)
        p.set_slider("y", 0.05)
        p.set_slider("z", 0.12)
        p.page.wait_for_function("() => document.getElementById('latency').textContent.includes('ms')", timeout=20000)
        p.page.wait_for_function(
            "() => ['compute_ik','state_publisher','serial_node'].every(n => document.querySelector('#status-' + n + ' .dot').className.includes('up'))",
            timeout=20000)
        time.sleep(1.0)
        OUTPUT.mkdir(parents=True, exist_ok=True)
        p.page.screenshot(path=str(OUTPUT / "gui_panel.png"))
        assert p.bytes < 300_000, f"page and assets are {p.bytes} bytes"
        foreign = [u for u in p.requests if not u.startswith(p.url.rstrip("/")) and not u.startswith(f"ws://127.0.0.1:{p.port}")]
        assert not foreign, foreign
    finally:
        p.close()


def run_cli(domain, *args, timeout=30):
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    return subprocess.run([bin_path("gui_bridge"), *args], capture_output=True, text=True, env=env, timeout=timeout)


def test_once_delivers_one_target_or_says_why_not(launch, observer, domain):
    launch("compute_ik")
    states = observer.sub("/joint_states", JointState)
    observer.wait_publisher("/joint_states")
    r = run_cli(domain, "--once", "0.2", "0.01", "0.15", "--timeout", "20")
    assert r.returncode == 0, r.stderr
    assert "delivered" in r.stdout
    # compute_ik moved the arm there (its joint_states put tool0 at the target)
    H, L2, L3, DX = 0.094, 0.135, 0.147, 0.0393

    def tool(js):
        q = dict(zip(js.name, js.position))
        a, phi = q["shoulder_joint"], q["shoulder_joint"] + q["elbow_joint"]
        r = L2 * math.cos(a) + L3 * math.cos(phi) + DX
        return (r * math.cos(q["base_joint"]), r * math.sin(q["base_joint"]), H + L2 * math.sin(a) + L3 * math.sin(phi))
    assert observer.spin_until(lambda: any(tool(m) == pytest.approx((0.2, 0.01, 0.15), abs=1e-9) for _, m in states), 5)
    r = run_cli(domain, "--once", "0.5", "0", "0.15", "--timeout", "10")
    assert r.returncode != 0 and "out of reach" in r.stderr


def test_play_and_record_teach_and_replay(launch, observer, domain, tmp_path):
    launch("compute_ik")
    observer.wait_publisher("/joint_states")
    recording = tmp_path / "taught.csv"
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    rec = subprocess.Popen([bin_path("gui_bridge"), "--record", str(recording)], stdout=subprocess.PIPE, text=True, env=env)
    script = tmp_path / "waypoints.csv"
    script.write_text("x,y,z,gripper,dwell\n0.2,0,0.15,0.5,0.2\n# a comment\n0.18,0.05,0.12,,0.1\n0.22,-0.04,0.18,1,0\n")
    time.sleep(3.0)  # let the recorder's subscriptions be discovered
    r = run_cli(domain, "--play", str(script), "--timeout", "20", timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("waypoint ") == 3
    time.sleep(1.0)
    rec.send_signal(signal.SIGINT)
    assert rec.wait(10) == 0
    rows = [line.split(",") for line in recording.read_text().splitlines()[1:]]
    xyz = [tuple(round(float(v), 4) for v in row[:3]) for row in rows]
    assert xyz == [(0.2, 0.0, 0.15), (0.18, 0.05, 0.12), (0.22, -0.04, 0.18)]
    assert [row[3] for row in rows] == ["0.500", "0.500", "1.000"]
    assert float(rows[0][4]) >= 0.2
    # a bad script names the line
    bad = tmp_path / "bad.csv"
    bad.write_text("0.2,0,0.15,,0\n0.2,zero,0.15,,0\n")
    r = run_cli(domain, "--play", str(bad))
    assert r.returncode != 0 and "line 2" in r.stderr
