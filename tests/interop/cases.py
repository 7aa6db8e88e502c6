"""The msgs test vectors, written independently of msgs/examples/cdr_vectors.rs.

Each case is (name, message) built with the real ROS 2 Python types (rclpy wheels),
or, for tf2_msgs/TFMessage which has no wheel, with the Cyclone DDS IDL types.
"""
import math

from builtin_interfaces.msg import Duration, Time
from control_msgs.action import FollowJointTrajectory, GripperCommand
from control_msgs.msg import GripperCommand as GripperCommandMsg
from control_msgs.msg import JointComponentTolerance, JointTolerance, JointTrajectoryControllerState
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PointStamped, Pose, PoseStamped, Quaternion, Transform, TransformStamped, Vector3
from sensor_msgs.msg import CameraInfo, CompressedImage, JointState, RegionOfInterest
from geometry_msgs.msg import Twist
from std_msgs.msg import Bool, Float64, Header, String
from trajectory_msgs.msg import (JointTrajectory, JointTrajectoryPoint, MultiDOFJointTrajectory,
                                 MultiDOFJointTrajectoryPoint)

from interop import idl

UNICODE = "bäse_link→ü🤖"
NAN = math.nan
INF = math.inf
I32_MAX = 2**31 - 1
I32_MIN = -(2**31)
F64_MAX = 1.7976931348623157e308
U32_MAX = 2**32 - 1


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


def tpoint(p, v=(), a=(), e=(), sec=0, nanosec=0):
    return JointTrajectoryPoint(positions=list(p), velocities=list(v), accelerations=list(a), effort=list(e),
                                time_from_start=Duration(sec=sec, nanosec=nanosec))


def joint_trajectory():
    return JointTrajectory(header=header(1_700_000_000, 5, "base_link"), joint_names=["base_joint", UNICODE, ""],
                           points=[tpoint([0.0, 1.5, -1.5]),
                                   tpoint([0.1, NAN, -0.0], [0.2, 0.0, INF], [1.0, 2.0, 3.0], [F64_MAX], 1, 500_000_000)])


def controller_state():
    return JointTrajectoryControllerState(
        header=header(2, 3, ""), joint_names=["base_joint", "elbow_joint"],
        reference=tpoint([0.5, -1.0], [0.1, 0.2], sec=1), feedback=tpoint([0.49, -1.01]), error=tpoint([0.01, 0.01]),
        output=tpoint([0.5, -1.0]), multi_dof_joint_names=["planar"],
        multi_dof_reference=MultiDOFJointTrajectoryPoint(
            transforms=[Transform()], velocities=[Twist(linear=vec(1, 2, 3), angular=vec(-1, -0.0, NAN))],
            accelerations=[], time_from_start=Duration(sec=4, nanosec=1)),
        speed_scaling_factor=0.5)


def fjt_goal():
    return FollowJointTrajectory.Goal(
        trajectory=joint_trajectory(),
        multi_dof_trajectory=MultiDOFJointTrajectory(header=header(1, 2, "odom"), joint_names=["planar"],
                                                     points=[MultiDOFJointTrajectoryPoint(transforms=[Transform(), Transform()])]),
        path_tolerance=[JointTolerance(name="elbow_joint", position=0.05, velocity=-1.0, acceleration=0.0)],
        component_path_tolerance=[JointComponentTolerance(joint_name="planar", component=5, position=0.1, velocity=0.2,
                                                          acceleration=0.3)],
        goal_tolerance=[JointTolerance()], component_goal_tolerance=[],
        goal_time_tolerance=Duration(sec=0, nanosec=500_000_000))


def cases():
    return [
        ("duration", Duration(sec=-3, nanosec=999_999_999)),
        ("joint_trajectory_empty", JointTrajectory()),
        ("joint_trajectory", joint_trajectory()),
        ("controller_state", controller_state()),
        ("follow_joint_trajectory_goal", fjt_goal()),
        ("follow_joint_trajectory_result", FollowJointTrajectory.Result(
            error_code=FollowJointTrajectory.Result.PATH_TOLERANCE_VIOLATED, error_string=UNICODE)),
        ("follow_joint_trajectory_feedback", FollowJointTrajectory.Feedback(
            header=header(7, 8, ""), joint_names=["base_joint"], desired=tpoint([0.5], [-0.25], [1.0], sec=1, nanosec=2),
            actual=tpoint([0.25]), error=tpoint([0.25]), index=2, multi_dof_index=-1)),
        ("gripper_command_goal", GripperCommand.Goal(command=GripperCommandMsg(position=0.5, max_effort=-0.0))),
        ("gripper_command_result", GripperCommand.Result(position=NAN, effort=0.0, stalled=True, reached_goal=False)),
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
        ("compressed_image_empty", CompressedImage()),
        ("compressed_image", CompressedImage(header=header(1_700_000_000, 33_333_333, "camera"), format="jpeg",
                                             data=bytes([0xFF, 0xD8, 0xFF, 0x00, 0x7F, 0xFF, 0xD9]))),
        ("camera_info_empty", CameraInfo()),
        (
            "camera_info",
            CameraInfo(header=header(7, 999_999_999, "wrist"), height=480, width=640, distortion_model="plumb_bob",
                       d=[-0.25, 0.125, NAN, -0.0, 1e-300], k=[500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0],
                       r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                       p=[500.0, 0.0, 320.0, 0.0, 0.0, 500.0, 240.0, 0.0, 0.0, 0.0, 1.0, INF], binning_x=1,
                       binning_y=U32_MAX, roi=RegionOfInterest(x_offset=1, y_offset=2, height=3, width=4, do_rectify=True)),
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
