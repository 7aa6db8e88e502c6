"""A pick through the graph against the physics twin, judged by the cube's tf frame: the
twin (its cube at `cube_xy`), compute_ik and serial_node; the claw opened, moved over
the cube, lowered along a line, closed, and lifted 5 cm along a line. Used by
tests/test_twin.py (one trial) and tests/soak/twin_pick.py (seeded trials, BENCHMARKS).

Each move is judged done by the twin, not by time: compute_ik at rest with the target
taken, and the twin's joints still (every joint under 0.02 rad/s in its latest state)."""
import math

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from conftest import TfListener, latest_status, status_values

STAND_M = 0.055           # the stand's height (twin_model's Scene)
CUBE_HALF_M = 0.0125      # half the 25 mm cube
FINGER_DROP_M = 0.006     # the claw's fingers hang this far below tool0


class PickGraph:
    """The graph of one trial in `domain`, started by `launch` (the tests' fixture or a
    soak's launcher); `observer` an rclpy Observer of the domain."""

    def __init__(self, launch, observer, domain, link, cube_xy):
        self.o = observer
        self.cube_xy = cube_xy
        self.diags = observer.sub("/diagnostics", DiagnosticArray)
        self.joints = observer.sub("/twin/joint_states", JointState)
        launch("twin", "--ros-args", "-p", f"link:={link}", "-p", "camera_fps:=0",
               "-p", f"cube_xy:=[{cube_xy[0]}, {cube_xy[1]}]")
        launch("compute_ik")
        launch("serial_node", "--ros-args", "-p", f"port:={link}")
        self.xyz = observer.pub("/xyz_target", PointStamped)
        self.line = observer.pub("/xyz_line_target", PointStamped)
        self.gripper = observer.pub("/gripper_target", Float64)
        for p in (self.xyz, self.line, self.gripper):
            observer.wait_matched(p)
        self.tf = TfListener(domain)
        assert observer.spin_until(lambda: self.status("serial_node").get("connection") == "connected", 30), \
            self.status("serial_node")
        assert observer.spin_until(lambda: "cube" in self.tf.transforms(), 20), "no cube frame"
        self.accepted = int(self.status("compute_ik").get("accepted", "0"))

    def status(self, name):
        return status_values(latest_status(self.diags, name))

    def cube_z(self):
        return self.tf.transforms()["cube"].transform.translation.z

    def still(self):
        m = self.joints[-1][1] if self.joints else None
        return m is not None and all(abs(v) < 0.02 for v in m.velocity)

    def done(self):
        v = self.status("compute_ik")
        return int(v.get("accepted", "0")) >= self.accepted and v.get("motion") == "at rest" and self.still()

    def send(self, pub, msg, what, timeout=20):
        """Publish until compute_ik has taken one more target, then wait for the twin to come to rest."""
        want = self.accepted + 1
        ok = False
        for _ in range(timeout):
            pub.publish(msg)
            if self.o.spin_until(lambda: int(self.status("compute_ik").get("accepted", "0")) >= want, 1):
                ok = True
                break
        assert ok, f"{what}: compute_ik did not take it: {self.status('compute_ik')}"
        self.accepted = want
        assert self.o.spin_until(self.done, timeout), f"{what}: the twin did not come to rest"

    def point(self, x, y, z):
        m = PointStamped()
        m.header.frame_id = "base_link"
        m.point.x, m.point.y, m.point.z = x, y, z
        return m

    def pick(self):
        """The scripted pick; returns the cube's rise (m) by its tf frame."""
        x, y = self.cube_xy
        z0 = self.cube_z()
        grip = z0 + FINGER_DROP_M
        self.send(self.gripper, Float64(data=1.0), "open")
        self.send(self.xyz, self.point(x, y, grip + 0.05), "over the cube")
        self.send(self.line, self.point(x, y, grip), "down")
        self.send(self.gripper, Float64(data=0.0), "close")
        self.send(self.line, self.point(x, y, grip + 0.05), "lift")
        return self.cube_z() - z0

    def close(self):
        self.tf.close()


def expected_start_z():
    return STAND_M + CUBE_HALF_M


def gripped(rise):
    """Lifted 5 cm: a rise of at least 45 mm (the claw's grip may let it settle a little)."""
    return rise >= 0.045 and not math.isnan(rise)
