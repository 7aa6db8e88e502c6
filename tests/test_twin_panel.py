"""The physics twin in the web panel (issue 35): gui_bridge reads the twin's cube from `tf`
(the frame `cube`, a child of base_link) and the camera view's images (`camera_view`,
by default twin/camera/image_raw/compressed), and the page draws a 25 mm red cube at the
cube's pose in its 3D view and shows the images in a small view. No cube frame for 2 s:
the cube is hidden; no image for 2 s: the small view is. An image over the camera view's
2 MiB is refused (counted in diagnostics) and the panel stays connected; a TFMessage of
thousands of transforms with megabyte frame names changes nothing. Judged by what the page
shows after what was published, never by the host's speed.

`tf` is written with Cyclone DDS (there is no tf2_msgs wheel for rclpy; tests/interop/idl.py),
the images with rclpy. The last test runs the real twin (nodes/twin, built with MuJoCo) and
takes the screenshot of docs/gui_panel_twin.png."""
import array
import io
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from PIL import Image
from sensor_msgs.msg import CompressedImage

from conftest import OUTPUT, TOPICS, latest_status, status_values
from test_gui_bridge import start_panel

# in a process of its own beside the other tests (judged by order and content, not the wall clock)
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=20)]

IMAGE_TOPIC = "/twin/camera/image_raw/compressed"
COLOUR = (20, 160, 220)
SIZE = (64, 48)
MAX_IMAGE = 2 * 1024 * 1024  # scene.rs MAX_CAMERA_IMAGE_BYTES


class TfWriter:
    """Writes `tf` with Cyclone DDS, with the contract's QoS (reliable, volatile)."""

    def __init__(self, domain_id):
        from cyclonedds.core import Policy, Qos
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic
        from cyclonedds.util import duration

        from interop.idl import TFMessage
        self.participant = DomainParticipant(domain_id)
        qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(TOPICS["tf"]["depth"]))
        self.writer = DataWriter(self.participant, Topic(self.participant, "rt/tf", TFMessage), qos=qos)

    @staticmethod
    def transform(parent, child, xyz, q=(0.0, 0.0, 0.0, 1.0)):
        from interop.idl import Header, Quaternion, Transform, TransformStamped, Vector3
        return TransformStamped(header=Header(frame_id=parent), child_frame_id=child,
                                transform=Transform(translation=Vector3(*xyz), rotation=Quaternion(*q)))

    def write(self, transforms):
        from interop.idl import TFMessage
        self.writer.write(TFMessage(transforms=list(transforms)))

    def cube(self, xyz, q=(0.0, 0.0, 0.0, 1.0), parent="base_link"):
        self.write([self.transform(parent, "cube", xyz, q)])

    def close(self):
        self.writer = None
        self.participant = None


def jpeg(colour=COLOUR, size=SIZE):
    out = io.BytesIO()
    Image.new("RGB", size, colour).save(out, format="JPEG", quality=95)
    return out.getvalue()


def compressed(data, fmt="jpeg"):
    m = CompressedImage()
    m.format = fmt
    m.data = array.array("B", data)
    return m


def pump(observer, publish, done, timeout, what):
    """Publish (as a twin would, every 50 ms) until `done()` holds; fails after `timeout`."""
    end = time.monotonic() + timeout
    while not done():
        if time.monotonic() > end:
            raise AssertionError(f"{what}: not within {timeout} s")
        publish()
        observer.spin_for(0.05)


def cube_on_page(page):
    return page.evaluate("() => window.__view3d ? window.__view3d.cube() : 'no 3D view'")


def camera_on_page(page):
    """The small view: hidden or not, the image's natural size and its centre pixel."""
    return page.evaluate("""() => {
        const box = document.getElementById('camera-view'), img = document.getElementById('camera-img');
        if (box.hidden || !img.complete || !img.naturalWidth) return { shown: false };
        const c = document.createElement('canvas');
        c.width = img.naturalWidth; c.height = img.naturalHeight;
        const g = c.getContext('2d');
        g.drawImage(img, 0, 0);
        const px = Array.from(g.getImageData(c.width >> 1, c.height >> 1, 1, 1).data);
        return { shown: true, w: img.naturalWidth, h: img.naturalHeight, px,
                 caption: document.getElementById('camera-caption').textContent, count: window.__camera.shown };
    }""")


def cube_at(page, xyz):
    """The page draws the cube at `xyz` (m), within float rounding."""
    c = cube_on_page(page)
    return c is not None and near(c["position"], xyz, 1e-9)


def near(a, b, tol):
    return all(abs(x - y) <= tol for x, y in zip(a, b))


def open_page(browser, port):
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    said = []
    page.on("console", lambda m: said.append((m.type, m.text)) if m.type in ("error", "warning") else None)
    page.on("pageerror", lambda e: said.append(("pageerror", str(e))))
    page.goto(f"http://127.0.0.1:{port}/")
    page.wait_for_function("() => document.getElementById('ws-dot').className === 'dot up'", timeout=10000)
    return page, said


def page_errors(said):
    # (Chromium's software GL reports a stall when a screenshot reads the pixels: the test's doing)
    return [(k, m) for k, m in said if "GL Driver Message (OpenGL, Performance" not in m]


def test_the_cube_and_the_camera_from_tf_and_an_image_topic(launch, observer, browser, domain):
    diags = observer.sub("/diagnostics", DiagnosticArray)
    _, port = start_panel(launch, observer, "-p", "foxglove_bind:=")
    images = observer.pub(IMAGE_TOPIC, CompressedImage)
    tf = TfWriter(domain)
    page, said = open_page(browser, port)
    try:
        hello_cube = cube_on_page(page)
        assert hello_cube is None, f"a cube before any was published: {hello_cube}"
        # 1. the cube where tf puts it, turned as tf turns it (45° about z)
        where, turn = (0.15, -0.05, 0.03), (0.0, 0.0, 0.38268343236, 0.92387953251)
        pump(observer, lambda: tf.cube(where, turn),
             lambda: cube_at(page, where), 15, "the cube drawn")
        c = cube_on_page(page)
        assert c["side"] == pytest.approx(0.025), c
        assert near(c["quaternion"], turn, 1e-6), c
        # it follows: a new pose replaces the old
        moved = (0.2, 0.0, 0.0675)
        pump(observer, lambda: tf.cube(moved),
             lambda: cube_at(page, moved), 10, "the cube moved")

        # 2. the camera view shows the image: its size, its colour, its topic
        picture = jpeg()
        pump(observer, lambda: images.publish(compressed(picture)),
             lambda: camera_on_page(page)["shown"], 15, "the camera view")
        shown = camera_on_page(page)
        assert (shown["w"], shown["h"]) == SIZE, shown
        assert near(shown["px"][:3], COLOUR, 12), shown
        assert shown["caption"] == "twin/camera/image_raw/compressed", shown

        # 3. bad input: an image over the limit is refused, counted, and the page stays
        # connected (the same WebSocket) and shows the next good image; a TFMessage of
        # thousands of transforms with megabyte frame names changes nothing
        page.evaluate("() => { window.__ws_before = ws; }")
        huge = compressed(b"\xff\xd8\xff\xe0" + bytes(MAX_IMAGE + 1000))

        def refused():
            v = status_values(latest_status(diags, "gui_bridge"))
            return int(v.get("camera_images_refused", "0")) > 0 and "over" in v.get("last_camera_refusal", "")
        pump(observer, lambda: images.publish(huge), refused, 20, "the big image refused")
        big_name = "x" * (1 << 20)
        junk = [tf.transform("base_link", f"frame{i}", (1.0, 2.0, 3.0)) for i in range(3000)]
        junk.append(tf.transform(big_name, big_name, (1.0, 2.0, 3.0)))
        junk.append(tf.transform(big_name, "cube", (1.0, 2.0, 3.0)))  # a cube in another frame: not shown
        tf.write(junk)
        # (the view may have hidden itself meanwhile: no image for 2 s)
        before = page.evaluate("() => window.__camera.shown")
        green = jpeg((30, 200, 40), (80, 60))
        pump(observer, lambda: images.publish(compressed(green)),
             lambda: (s := camera_on_page(page))["shown"] and s["count"] > before and s["w"] == 80, 15,
             "a good image after the big one")
        assert near(camera_on_page(page)["px"][:3], (30, 200, 40), 12)
        again = (0.1, 0.1, 0.02)
        pump(observer, lambda: tf.cube(again),
             lambda: cube_at(page, again), 10, "the cube after the junk")
        assert page.evaluate("() => ws === window.__ws_before && ws.readyState === 1"), "the panel's connection changed"
        # the cube in another frame, counted (gui_bridge reports once a second)
        def ignored():
            v = status_values(latest_status(diags, "gui_bridge"))
            return int(v.get("cube_ignored", "0")) >= 1 and "bytes" in v.get("last_cube_ignored", "")
        assert observer.spin_until(ignored, 5), status_values(latest_status(diags, "gui_bridge"))

        # 4. the twin stops: no cube frame and no image for 2 s, and both are hidden
        def both():
            tf.cube(again)
            images.publish(compressed(picture))
        pump(observer, both, lambda: cube_on_page(page) is not None and camera_on_page(page)["shown"], 10,
             "the cube and the camera both shown")
        page.wait_for_function("() => window.__view3d.cube() === null", timeout=10000)
        page.wait_for_function("() => document.getElementById('camera-view').hidden", timeout=10000)
        assert not page_errors(said), said
    finally:
        page.close()
        tf.close()


def test_no_camera_view_with_an_empty_camera_view(launch, observer, browser):
    _, port = start_panel(launch, observer, "-p", "foxglove_bind:=", "-p", "camera_view:=")
    # gui_bridge's endpoints known (it subscribes tf), and none on the image topic
    assert observer.spin_until(lambda: observer.node.count_subscribers("/tf") > 0, 10)
    assert observer.node.count_subscribers(IMAGE_TOPIC) == 0
    images = observer.pub(IMAGE_TOPIC, CompressedImage)
    page, said = open_page(browser, port)
    try:
        assert page.evaluate("() => document.getElementById('camera-caption').textContent") == ""
        # published for a while (a twin's few frames): nothing reaches the page
        for _ in range(20):
            images.publish(compressed(jpeg()))
            observer.spin_for(0.05)
        assert page.evaluate("() => window.__camera.shown") == 0
        assert page.evaluate("() => document.getElementById('camera-view').hidden")
    finally:
        page.close()


def test_the_real_twin_in_the_panel(launch, observer, browser, tmp_path):
    link = tmp_path / "twin-link"
    launch("twin", "--ros-args", "-p", "camera_fps:=5", "-p", f"link:={link}")
    # the graph too, for the picture: the URDF, compute_ik's pose, and serial_node holding
    # the twin's arm there (the cube and the camera need none of them)
    launch("state_publisher")
    launch("compute_ik")
    launch("serial_node", "--ros-args", "-p", f"port:={link}")
    _, port = start_panel(launch, observer, "-p", "foxglove_bind:=")
    page, said = open_page(browser, port)
    try:
        # the twin's cube: on its stand, 55 mm plus half of its 25 mm
        page.wait_for_function("() => window.__view3d.cube() !== null", timeout=30000)
        c = cube_on_page(page)
        assert near(c["position"], (0.2, 0.0, 0.0675), 0.005), c
        # its camera, 640x480
        observer.spin_until(lambda: camera_on_page(page)["shown"], 30)
        shown = camera_on_page(page)
        assert shown["shown"] and (shown["w"], shown["h"]) == (640, 480), shown
        # the arm drawn (its URDF loaded) and state_publisher heard before the picture
        page.wait_for_function("() => window.__view3d.robot !== null", timeout=20000)
        page.wait_for_function("() => !!document.querySelector('#status-state_publisher .dot.up')"
                               " && !!document.querySelector('#status-serial_node .dot.up')", timeout=30000)
        OUTPUT.mkdir(parents=True, exist_ok=True)
        # the header and the live view (docs/gui_panel_twin.png, made smaller from it)
        page.screenshot(path=str(OUTPUT / "gui_panel_twin.png"), clip={"x": 0, "y": 0, "width": 1280, "height": 660})
        assert not page_errors(said), said
    finally:
        page.close()
