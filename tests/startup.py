"""Start-up discovery between our nodes and a real ROS 2 (rclpy, Fast DDS) process that
starts at the same moment, the way one launch file starts a user's nodes together with
ours. One trial: start the four nodes and an rclpy participant (in a given order, on
one host or split across the `pc`/`pi` namespaces), then check within a deadline that
  * rclpy's node list has every node of ours (node names travel on ros_discovery_info);
  * every endpoint of ours is discovered and matched: rclpy's xyz_target publisher is
    matched by compute_ik, rclpy's servo_state subscription by serial_node, and the
    graph shows each node's publishers and subscriptions.
Used by test_two_hosts.py (one trial of each kind) and tests/soak/starts.py (hundreds),
each trial in a process of its own (`run_in_subprocess`): a fresh rclpy process, as a
user's, and no state left by other trials (Fast DDS in a process that has had
participants in other network namespaces no longer discovers anything in its own).

    python tests/startup.py --domain N [--order together|rclpy_first|nodes_first] [--split]
prints one trial's result as JSON."""
import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from geometry_msgs.msg import PointStamped
from sensor_msgs.msg import JointState

from conftest import NodeProcess, Observer

NODES = ["compute_ik", "state_publisher", "serial_node", "gui_bridge"]
# (node, topic, kind): what rclpy must see of each node
ENDPOINTS = [
    ("compute_ik", "/xyz_target", "sub"), ("compute_ik", "/servo_angles", "pub"), ("compute_ik", "/joint_states", "pub"),
    ("state_publisher", "/joint_states", "sub"), ("state_publisher", "/tf", "pub"),
    ("state_publisher", "/robot_description", "pub"),
    ("serial_node", "/servo_angles", "sub"), ("serial_node", "/servo_state", "pub"),
    ("gui_bridge", "/xyz_target", "pub"), ("gui_bridge", "/servo_state", "sub"),
]


def start_nodes(domain, hosts=None):
    """The graph: on one host, or compute_ik/state_publisher/gui_bridge in hosts.pc and
    serial_node (virtual Arduino in-process) in hosts.pi."""
    procs = []
    for name in NODES:
        args = ["--ros-args", "-p", "port:=mock"] if name == "serial_node" else []
        if name == "gui_bridge":
            args = ["--ros-args", "-p", "bind:=127.0.0.1:0"]
        ns = None if hosts is None else (hosts.pi if name == "serial_node" else hosts.pc)
        if os.environ.get("EEZYBOT_TRIAL_LOG_LEVEL"):
            args = (args or ["--ros-args"]) + ["--log-level", os.environ["EEZYBOT_TRIAL_LOG_LEVEL"]]
        procs.append(NodeProcess(name, args, domain, netns=ns))
    return procs


def trial(domain, order="together", hosts=None, deadline=20.0):
    """Returns a dict: missing_nodes, missing_endpoints (what was still missing at the
    deadline), node_list_s / endpoints_s (when everything was there, or None)."""
    procs, o = [], None
    t0 = time.monotonic()
    try:
        if order in ("nodes_first", "together"):
            procs = start_nodes(domain, hosts)
        if order == "nodes_first":
            time.sleep(1.0)
        o = Observer(domain, name="user_node", netns=None if hosts is None else hosts.pc)
        if order == "rclpy_first":
            time.sleep(1.0)
            procs = start_nodes(domain, hosts)
            t0 = time.monotonic()
        xyz = o.pub("/xyz_target", PointStamped)
        o.sub("/servo_state", JointState)
        result = {"order": order, "hosts": "split" if hosts else "one", "node_list_s": None, "endpoints_s": None}

        def missing_nodes():
            names = {n for n, _ in o.node.get_node_names_and_namespaces()}
            return [n for n in NODES if n not in names]

        def missing_endpoints():
            out = []
            for node, topic, kind in ENDPOINTS:
                infos = (o.node.get_subscriptions_info_by_topic(topic) if kind == "sub"
                         else o.node.get_publishers_info_by_topic(topic))
                # an endpoint of ours: the node name comes from ros_discovery_info, so
                # count by topic and type here, nodes are checked separately
                if not infos:
                    out.append(f"{node} {kind} {topic}")
            if xyz.get_subscription_count() == 0:
                out.append("compute_ik sub /xyz_target (not matched by rclpy's publisher)")
            if o.node.count_publishers("/servo_state") == 0:
                out.append("serial_node pub /servo_state (not matched)")
            return out

        end = t0 + deadline
        while time.monotonic() < end:
            o.spin_for(0.05)
            now = time.monotonic() - t0
            if result["endpoints_s"] is None and not missing_endpoints():
                result["endpoints_s"] = now
            if result["node_list_s"] is None and not missing_nodes():
                result["node_list_s"] = now
            if result["endpoints_s"] is not None and result["node_list_s"] is not None:
                break
        result["missing_nodes"] = missing_nodes()
        result["missing_endpoints"] = missing_endpoints()
        result["logs"] = [p.log_path for p in procs]
        return result
    finally:
        codes = [p.stop() for p in procs]
        if o is not None:
            o.close()
        if any(c != 0 for c in codes):
            raise AssertionError(f"nodes did not exit cleanly: {codes}; logs (a node killed after "
                                 f"ignoring SIGINT has its stacks there): "
                                 f"{[str(p.log_path) for p, c in zip(procs, codes) if c != 0]}")


def run_in_subprocess(domain, order="together", split=False, deadline=20.0):
    """One trial in a new Python process (in namespaces of its own when split)."""
    argv = [sys.executable, str(Path(__file__).resolve()), "--domain", str(domain), "--order", order,
            "--deadline", str(deadline)] + (["--split"] if split else [])
    out = subprocess.run(argv, capture_output=True, text=True, timeout=deadline + 60)
    lines = [line for line in out.stdout.splitlines() if line.startswith("{")]
    if out.returncode != 0 or not lines:
        raise RuntimeError(f"start-up trial failed to run (exit {out.returncode}):\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}")
    return json.loads(lines[-1])


def main():
    import twohost

    ap = argparse.ArgumentParser(description="one start-up discovery trial; prints JSON")
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--order", default="together", choices=["together", "rclpy_first", "nodes_first"])
    ap.add_argument("--split", action="store_true", help="nodes in namespaces pc/pi, rclpy in pc")
    ap.add_argument("--deadline", type=float, default=20.0)
    args = ap.parse_args()
    hosts = twohost.TwoHosts(tag="s") if args.split else None
    try:
        r = trial(args.domain, order=args.order, hosts=hosts, deadline=args.deadline)
    finally:
        if hosts is not None:
            hosts.close()
    r["logs"] = [str(p) for p in r["logs"]]
    print(json.dumps(r), flush=True)


if __name__ == "__main__":
    main()
