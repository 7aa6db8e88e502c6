"""The msgs test vectors, written independently of msgs/examples/cdr_vectors.rs.

Each case is (name, message) built with the real ROS 2 Python types (rclpy wheels),
or, for tf2_msgs/TFMessage which has no wheel, with the Cyclone DDS IDL types.
"""
import math

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PointStamped, Pose, PoseStamped, Quaternion, Transform, TransformStamped, Vector3
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, Header, String

from interop import idl

UNICODE = "bäse_link→ü🤖"
NAN = math.nan
INF = math.inf
I32_MAX = 2**31 - 1
I32_MIN = -(2**31)
F64_MAX = 1.7976931348623157e308


def header(sec, nanosec, frame):
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame)


def vec(x, y, z):
    return Vector3(x=float(x), y=float(y), z=float(z))


def quat(x, y, z, w):
    return Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))


def ts(h, child, tr, rot):
    return TransformStamped(header=h, child_frame_id=child, transform=Transform(translation=vec(*tr), rotation=quat(*rot)))


def idl_ts(sec, nanosec, frame, child, tr, rot):
    return idl.TransformStamped(
        header=idl.Header(stamp=idl.Time(sec, nanosec), frame_id=frame),
        child_frame_id=child,
        transform=idl.Transform(idl.Vector3(*map(float, tr)), idl.Quaternion(*map(float, rot))),
    )


def cases():
    return [
        ("header_empty", header(0, 0, "")),
        ("header_max", header(I32_MAX, 999_999_999, UNICODE)),
        ("header_min", header(I32_MIN, 0, "base_link")),
        ("string_empty", String(data="")),
        ("string_unicode", String(data=UNICODE + ' "quoted"\n\ttab')),
        ("float64_neg_zero", Float64(data=-0.0)),
        ("float64_nan", Float64(data=NAN)),
        ("float64_inf", Float64(data=INF)),
        ("float64_neg_inf", Float64(data=-INF)),
        ("float64_min_subnormal", Float64(data=5e-324)),
        ("float64_max", Float64(data=F64_MAX)),
        ("bool_true", Bool(data=True)),
        ("bool_false", Bool(data=False)),
        ("point", Point(x=-0.0, y=INF, z=NAN)),
        ("point_stamped", PointStamped(header=header(1_700_000_000, 123_456_789, "base_link"), point=Point(x=0.2, y=-0.05, z=0.15))),
        ("point_stamped_odd_frame", PointStamped(header=header(-1, 1, "x"), point=Point(x=-F64_MAX, y=1e300, z=-5e-324))),
        ("pose_stamped", PoseStamped(header=header(1_700_000_000, 987_654_321, "base_link"),
                                     pose=Pose(position=Point(x=0.3, y=-0.25, z=0.5), orientation=quat(0, math.sqrt(0.5), 0, math.sqrt(0.5))))),
        ("pose_stamped_odd", PoseStamped(header=header(-1, 1, UNICODE),
                                         pose=Pose(position=Point(x=NAN, y=-0.0, z=F64_MAX), orientation=quat(0, 0, 0, 0)))),
        ("vector3", vec(-F64_MAX, 5e-324, -INF)),
        ("quaternion_identity", quat(0, 0, 0, 1)),
        ("quaternion_odd", quat(NAN, -0.0, INF, -1)),
        ("transform", Transform(translation=vec(1, 2, 3), rotation=quat(0.5, -0.5, 0.5, -0.5))),
        ("transform_stamped", ts(header(5, 6, "base_link"), "tool0", (0.1, -0.0, NAN), (0, 0, 0, 1))),
        ("transform_stamped_empty_frames", ts(header(I32_MIN, 999_999_999, ""), "", (INF, -INF, 0), (1, 0, 0, 0))),
        ("joint_state_empty", JointState()),
        (
            "joint_state_full",
            JointState(header=header(1_700_000_000, 5, ""), name=["base_joint", UNICODE, ""], position=[NAN, -0.0, INF], velocity=[], effort=[F64_MAX]),
        ),
        ("tf_message_empty", idl.TFMessage(transforms=[])),
        (
            "tf_message_two",
            idl.TFMessage(
                transforms=[
                    idl_ts(10, 20, "base_link", "turntable", (0, 0, 0.094), (0, 0, 0.38268343236508984, 0.9238795325112867)),
                    idl_ts(10, 20, UNICODE, "a", (-0.0, NAN, 1e-300), (NAN, 0, 0, 1)),
                ]
            ),
        ),
        ("key_value", KeyValue(key="", value=UNICODE)),
        ("diagnostic_status", DiagnosticStatus(level=bytes([255]), name="compute_ik: inverse kinematics", message="", hardware_id="x", values=[])),
        ("diagnostic_array_empty", DiagnosticArray()),
        (
            "diagnostic_array",
            DiagnosticArray(
                header=header(I32_MAX, 0, "odd"),
                status=[
                    DiagnosticStatus(level=DiagnosticStatus.WARN, name=UNICODE, message="out of reach", hardware_id="",
                                     values=[KeyValue(key="k", value=""), KeyValue(key="ü", value="v")]),
                    DiagnosticStatus(level=bytes([0])),
                ],
            ),
        ),
    ]
