"""camera_node through real rclpy: its test source's JPEG images, their stamps read back
from the pixels (the block code of nodes/camera_node/src/code.rs, decoded here
independently with Pillow), the camera infos beside them, and a missing camera as a
diagnostics entry while the node stays up.

No real webcam here: the V4L2 path (MJPEG pass-through, YUYV encoding, unplugging) is
not exercised by these tests."""
import io

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from PIL import Image
from sensor_msgs.msg import CameraInfo, CompressedImage

from conftest import latest_status, qos, status_values
from stamp_code import read_code

IMAGE, INFO = "camera/image_raw/compressed", "camera/camera_info"


def ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def test_the_test_source_publishes_jpeg_frames_whose_pixels_carry_their_stamps(launch, observer):
    launch("camera_node", "--ros-args", "-p", "device:=test", "-p", "fps:=30", "-p", "diagnostics_period:=0.2")
    images = observer.sub(IMAGE, CompressedImage)
    infos = observer.sub(INFO, CameraInfo)
    diags = observer.sub("/diagnostics", DiagnosticArray)
    assert qos(IMAGE).reliability.name == "BEST_EFFORT"
    observer.wait_publisher(f"/{IMAGE}")
    assert observer.spin_until(lambda: len(images) >= 30 and len(infos) >= 30, timeout=15), \
        f"{len(images)} images, {len(infos)} infos"
    stamps = []
    for _, m in images[:30]:
        assert m.format == "jpeg"
        assert m.header.frame_id == "camera"
        img = Image.open(io.BytesIO(bytes(m.data)))
        assert img.format == "JPEG"
        assert img.size == (640, 480)
        assert read_code(img) == ns(m.header.stamp)
        stamps.append(ns(m.header.stamp))
    # increasing, on the grid of 1/30 s (frame k at start + floor(k * 10^9 / 30) ns)
    assert all(b > a for a, b in zip(stamps, stamps[1:])), stamps
    for s in stamps:
        periods = (s - stamps[0]) * 30 / 1e9
        assert abs(periods - round(periods)) < 1e-6, (s - stamps[0], periods)
    by_stamp = {ns(m.header.stamp): m for _, m in images}
    matched = 0
    for _, info in infos:
        assert (info.width, info.height, info.header.frame_id) == (640, 480, "camera")
        if ns(info.header.stamp) in by_stamp:
            matched += 1
    # best effort: an info may come without its image, but on one host nearly all pair
    assert matched >= 20, f"{matched} of {len(infos)} camera infos have their image's stamp"
    # the node's count reaches the images received (a report may predate the last ones)
    received = len(images)

    def counted():
        s = latest_status(diags, "camera_node: camera")
        return s is not None and int(status_values(s).get("frames_published", "0")) >= received
    assert observer.spin_until(counted, timeout=5), status_values(latest_status(diags, "camera_node: camera"))
    s = latest_status(diags, "camera_node: camera")
    values = status_values(s)
    assert s.level == DiagnosticStatus.OK, s.message
    assert values["device"] == "test" and values["size"] == "640x480" and values["format"].startswith("test pattern")


def test_a_missing_camera_is_a_diagnostics_error_and_the_node_stays_up(launch, observer):
    proc = launch("camera_node", "--ros-args", "-r", "__node:=wrist", "-r", "__ns:=/arm2",
                  "-p", "device:=/dev/video99", "-p", "frame_id:=wrist_cam", "-p", "diagnostics_period:=0.2")
    diags = observer.sub("/arm2/diagnostics", DiagnosticArray)
    observer.wait_publisher("/arm2/diagnostics")

    def retried():
        s = latest_status(diags, "wrist: camera")
        return s is not None and int(status_values(s).get("failures", "0")) >= 2

    assert observer.spin_until(retried, timeout=10), proc.output()
    s = latest_status(diags, "wrist: camera")
    values = status_values(s)
    assert s.level == DiagnosticStatus.ERROR
    assert "/dev/video99" in s.message and "/dev/video99" in values["last_error"], s.message
    assert values["device"] == "/dev/video99" and values["frame_id"] == "wrist_cam"
    assert values["frames_published"] == "0"
    assert proc.proc.poll() is None, "the node is still running"
    assert observer.node.count_publishers(f"/arm2/{IMAGE}") == 1
