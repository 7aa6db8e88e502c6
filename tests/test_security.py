"""SROS2 (DDS Security, issue 18) across two hosts: compute_ik in namespace `pc` and
serial_node (port:=mock) in `pi`, joined by a veth (twohost.py), each under its enclave
of a keystore made by launch_scripts/keystore.sh.

rclpy from PyPI has no DDS Security, so the secured operator is tests/interop/sros2_peer
(Debian's Fast DDS 2.9 with its builtin PKI-DH, Access-Permissions and AES-GCM-GMAC
plugins, carrying the topics as raw CDR): a second DDS Security implementation, as a
stock ROS 2 install would be. rclpy is the outsider without security.

Timings are printed, not asserted: the resume within 5 s of a link outage (issue 8) is
measured by tests/soak/secure_outages.py, which fails past it; here the order is judged."""
import math
import os
import subprocess
import time

import pytest

import twohost
from conftest import REPO, NodeProcess, Observer, bin_path
from security_rig import (NO_SECURITY, PERMISSIONS_TOPIC, Capture, SecureGraph, SecurePeer, answered_stamp, drive,
                          exchange, handshake_permissions_removed, joint_state, make_keystore, point_target,
                          security_env, servo_deg, stamp, udp_datagrams, wait_at, wait_at_rest)

# in a process of its own (Fast DDS and network namespaces, conftest), beside the other
# modules: mostly handshakes and an outage waited out, judged by order
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=60)]
# the tests across the veth need network namespaces (root); the bad-keystore cases run
# one node on the host's own network and run anywhere
two_hosts = pytest.mark.skipif(twohost.available() is not None, reason=f"two hosts: {twohost.available()}")

TARGET = (0.2, 0.0, 0.15)
STRANGER_TARGET = (0.18, -0.04, 0.2)
HANDSHAKE_TIMEOUT = 30.0  # discovery + PKI-DH handshakes of three participants (a few s here)


@pytest.fixture(scope="module")
def keystore(tmp_path_factory):
    """keystore.sh's keystore, with a `tools` enclave besides (RViz2's, `ros2 topic`'s)."""
    return make_keystore(tmp_path_factory.mktemp("keystore") / "keystore", "/eezybot/tools")


@pytest.fixture(scope="module")
def foreign_keystore(tmp_path_factory):
    """Another keystore: same enclave names, other CAs."""
    return make_keystore(tmp_path_factory.mktemp("foreign") / "keystore")


@pytest.fixture
def hosts():
    h = twohost.TwoHosts(tag="s")
    yield h
    h.close()


def close(graph, *peers):
    codes = {p.name: p.close() for p in peers}
    codes.update(graph.close())
    assert all(c == 0 for c in codes.values()), f"exit codes {codes}"


def wait_matched(peer, graph, pubs=("xyz_target",), subs=("servo_state",)):
    """The operator's endpoints are matched by the graph's (handshakes done): the
    seconds it took."""
    t0 = time.monotonic()
    ok = peer.wait(lambda: all(peer.matched(t, "pub") > 0 for t in pubs) and all(peer.matched(t, "sub") > 0 for t in subs),
                   HANDSHAKE_TIMEOUT)
    assert ok, (f"{peer.name} not matched within {HANDSHAKE_TIMEOUT} s: pubs "
                f"{[(t, peer.matched(t, 'pub')) for t in pubs]}, subs {[(t, peer.matched(t, 'sub')) for t in subs]}; "
                f"authenticated {sorted(peer.authenticated())}, failed {sorted(peer.auth_failed())}\n"
                f"{peer.stderr()[-2000:]}\n{graph.logs_tail()}")
    return time.monotonic() - t0


def degrees(msg):
    return [math.degrees(a) for a in msg.position[:3]]


# ---------------------------------------------------------------------------------------
# interop with another DDS Security implementation

@two_hosts
@pytest.mark.parametrize("secured", [True, False], ids=["secured", "plain"])
def test_a_secured_fast_dds_operator_drives_the_arm(hosts, domain, keystore, secured):
    """The C++ Fast DDS peer under the /eezybot/pc enclave publishes a target; compute_ik
    (pc enclave) answers with servo_angles and serial_node (pi enclave, across the veth)
    with servo_state, both at ROBOT.md's servo angles. `plain` is the same run without
    security: the same answers."""
    graph = SecureGraph(hosts, domain, keystore if secured else None)
    peer = graph.operator()
    try:
        handshake_s = wait_matched(peer, graph, subs=("servo_angles", "servo_state"))
        sent, answered = drive(peer, TARGET)
        assert answered, f"no servo_state for the target\n{peer.stderr()[-2000:]}\n{graph.logs_tail()}"
        angles = [joint_state(p) for _, p in peer.received("servo_angles")]
        assert any(stamp(m) == answered for m in angles), "no servo_angles carries the answered target's stamp"
        # the motion ends where the target's IK puts the arm: compute_ik's last step, then
        # the device's state (a quiet period could end in a stall mid-motion)
        expected = servo_deg(*TARGET)
        last_angles = wait_at(peer, "servo_angles", expected)
        state = wait_at(peer, "servo_state", expected)
        print(f"\n{'secured' if secured else 'plain'}: matched after {handshake_s:.2f} s; at rest "
              f"servo_angles {[round(a, 2) for a in degrees(last_angles)]}, servo_state "
              f"{[round(a, 2) for a in degrees(state)]}, ROBOT.md {[round(a, 2) for a in expected]}")
        assert state.name[:3] == ["base_servo", "shoulder_servo", "elbow_servo"], state.name
        assert max(abs(a - e) for a, e in zip(degrees(last_angles), expected)) < 0.1, (degrees(last_angles), expected)
        assert max(abs(a - e) for a, e in zip(degrees(state), expected)) < 0.1, (degrees(state), expected)
    finally:
        close(graph, peer)


# ---------------------------------------------------------------------------------------
# on the wire

SECRETS = [b"xyz_target", b"servo_state", b"servo_angles", b"rt/xyz_target", b"rt/servo_state",
           b"ros_discovery_info"]


@two_hosts
@pytest.mark.parametrize("secured", [True, False], ids=["secured", "plain"])
def test_the_wire_carries_no_topic_name_nor_payload_in_clear(hosts, domain, keystore, tmp_path, secured):
    """tcpdump on the Pi's end of the veth while a target goes end to end (the operator
    in `pi` this time, so the target itself crosses the link to compute_ik): secured, the
    capture holds neither a topic name nor the target's CDR nor a servo_angles sample's;
    `plain`, the control, holds them all. (Bare "rt/", three bytes, is not searched:
    encrypted bytes match it by chance in about one capture in thirty.)"""
    graph = SecureGraph(hosts, domain, keystore if secured else None)
    capture = Capture(hosts.pi, hosts.pi_if, tmp_path / "veth.pcap")
    peer = graph.operator(netns=hosts.pi)
    try:
        wait_matched(peer, graph, subs=("servo_angles", "servo_state"))
        sent, answered = drive(peer, TARGET)
        assert answered, f"no servo_state for the target\n{graph.logs_tail()}"
        wait_at_rest(peer, "servo_angles")
        time.sleep(0.5)
    finally:
        pcap = capture.stop()
        close(graph, peer)
    targets = [p for t, p in peer.published if t == "xyz_target"]
    angle_samples = [p for _, p in peer.received("servo_angles")]
    assert angle_samples
    datagrams = udp_datagrams(pcap)
    print(f"\n{'secured' if secured else 'plain'}: {capture.packets()} packets, {len(datagrams)} UDP datagrams, "
          f"{len(pcap)} bytes captured")
    assert sum(1 for d in datagrams if d.startswith(b"RTPS")) > 10, "the capture holds (almost) no RTPS message"
    # the permissions documents exchanged in the handshakes name the topics each side may use
    handshakes = [d for d in datagrams if PERMISSIONS_TOPIC.search(d)]
    wire = b"\0".join(handshake_permissions_removed(d) for d in datagrams)
    named = [s.decode() for s in SECRETS if s in wire]
    targets_seen = sum(1 for t in targets if t in wire)
    angles_seen = sum(1 for a in angle_samples if a in wire)
    leaks = {"names": named, "targets": targets_seen, "servo_angles samples": angles_seen}
    if secured:
        print(f"{len(handshakes)} datagrams carry (part of) a permissions document in clear (DDS Security's "
              f"c.perm in the handshakes): the topics each enclave may use, not the traffic")
        assert not named and targets_seen == 0 and angles_seen == 0, f"in clear on the wire: {leaks}"
        for word in (b"compute_ik", b"serial_node", b"/eezybot/"):
            if word in wire:
                print(f"note: {word.decode()!r} is in the capture (unencrypted participant announcement or certificate)")
    else:
        assert not handshakes
        assert set(named) == {s.decode() for s in SECRETS} and targets_seen >= 1 and angles_seen >= 1, \
            f"the unsecured control does not show what the test looks for: {leaks}"


# ---------------------------------------------------------------------------------------
# outsiders

def rclpy_target(publisher, xyz):
    """Publish a PointStamped target stamped now with rclpy: its stamp."""
    from geometry_msgs.msg import PointStamped

    m = PointStamped()
    t = time.time()
    m.header.frame_id = "base_link"
    m.header.stamp.sec, m.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
    m.point.x, m.point.y, m.point.z = xyz
    publisher.publish(m)
    return m.header.stamp.sec, m.header.stamp.nanosec


# what compute_ik and serial_node add to an rclpy participant's topic list (rclpy's own
# /servo_state and /xyz_target are in it anyway: whether anyone else has them is what the
# counts say)
OUR_TOPICS = {"/servo_angles", "/joint_states", "/diagnostics", "/estop", "/gripper_target", "/joint_target",
              "/pose_target", "/xyz_line_target"}


@two_hosts
def test_outsiders_see_nothing_and_cannot_move_the_arm(hosts, domain, other_domain, keystore, foreign_keystore):
    """With the graph secured, each outsider beside its control, in the same window:
    rclpy without security in `pc` discovers none of our nodes or topics and its targets
    do not move the arm, while the same rclpy outsider in `pc` on another domain, where
    the same two nodes run without security, sees them and moves that arm; the Fast DDS
    peer with another CA's keystore fails a handshake with each of our nodes (on a
    certificate check, on its side or the node's), discovers nothing and does not move
    the arm; and the secured operator's own targets go on being answered until after
    every control has held. `gui_bridge once` without security exits 1, and with the pc enclave 0."""
    graph = SecureGraph(hosts, domain, keystore)
    control_graph = SecureGraph(hosts, other_domain, None)
    peer = graph.operator()
    stranger = SecurePeer(domain, enclave=foreign_keystore.enclave("/eezybot/pc"), pubs=["xyz_target"],
                          subs=["servo_state"], netns=hosts.pc, name="stranger")
    outsider = control = None
    try:
        wait_matched(peer, graph)
        sent, answered = drive(peer, TARGET)
        assert answered, f"the secured operator cannot drive the arm\n{graph.logs_tail()}"
        rest = wait_at_rest(peer)
        n_states = len(peer.received("servo_state"))
        # compute_ik's and serial_node's participants, by the endpoints the operator matched
        ours = {graph.ik: peer.endpoint_participants("reader", "xyz_target") & peer.authenticated(),
                graph.serial: peer.endpoint_participants("writer", "servo_state") & peer.authenticated()}
        assert all(len(g) == 1 for g in ours.values()), \
            f"the operator's authenticated participants {sorted(peer.authenticated())}: {peer.said('writer ') + peer.said('reader ')}"
        ours = {node: g.pop() for node, g in ours.items()}

        def refused(node):
            """A handshake of node's with the stranger failed on a certificate check: on the
            stranger's side (it replied to the node's request) or the node's (the other way)."""
            return ours[node] in stranger.auth_failed() or any(
                g in line and "handshake" in line and "ertificate" in line
                for line in node.output().splitlines() for g in peer.participants_named("stranger"))

        from geometry_msgs.msg import PointStamped
        from sensor_msgs.msg import JointState
        outsider = Observer(domain, name="outsider", netns=hosts.pc)
        outsider_states = outsider.sub("/servo_state", JointState)
        outsider_xyz = outsider.pub("/xyz_target", PointStamped)
        control = Observer(other_domain, name="outsider", netns=hosts.pc)
        control_states = control.sub("/servo_state", JointState)
        control_xyz = control.pub("/xyz_target", PointStamped)
        stranger.wait_ready()

        def control_sees_the_graph():
            return ({"compute_ik", "serial_node"} <= set(control.node.get_node_names())
                    and OUR_TOPICS <= {n for n, _ in control.node.get_topic_names_and_types()}
                    and control.node.count_publishers("/servo_state") > 0 and control_xyz.get_subscription_count() > 0)

        def control_moved(after=0.0):
            """The unsecured arm answered one of the control's targets sent after `after`."""
            wanted = {st for t, st in control_sent if t > after}
            return any(stamp(m) in wanted for _, m in control_states)

        # The outsiders send a target each round, the control its own to the unsecured arm,
        # until the controls hold (the control sees the unsecured graph and moved its arm;
        # the stranger failed the handshake with each of our nodes) and the unsecured arm
        # has answered a target the control sent after that: the outsiders had that long
        # to do the same. Then the operator sends until one of its targets is answered: the
        # secured graph was alive after the outsiders' last target. (Not interleaved: a
        # target a moment after another supersedes it in compute_ik, which could hide an
        # outsider's.) The deadlines only bound a failure.
        foreign, control_sent, own = set(), [], []
        held_at = None
        end = time.monotonic() + HANDSHAKE_TIMEOUT
        while time.monotonic() < end:
            foreign.add(rclpy_target(outsider_xyz, STRANGER_TARGET))
            payload, st = point_target(*STRANGER_TARGET)
            stranger.publish("xyz_target", payload)
            foreign.add(st)
            control_sent.append((time.monotonic(), rclpy_target(control_xyz, STRANGER_TARGET)))
            outsider.spin_for(0.05)
            control.spin_for(0.05)
            if held_at is None:
                if control_sees_the_graph() and control_moved() and all(refused(node) for node in ours):
                    held_at = time.monotonic()
                    end = held_at + HANDSHAKE_TIMEOUT
            elif control_moved(held_at):
                break
        outsiders_s = time.monotonic() - control_sent[0][0]
        end = time.monotonic() + HANDSHAKE_TIMEOUT
        while time.monotonic() < end:
            payload, st = point_target(*TARGET)
            peer.publish("xyz_target", payload)
            own.append(st)
            outsider.spin_for(0.05)  # (what rclpy receives comes to its lists as it spins)
            control.spin_for(0.05)
            if answered_stamp(peer, own):
                break
        print(f"\noutsiders' window: {outsiders_s:.2f} s (the controls held after "
              f"{'-' if held_at is None else round(held_at - control_sent[0][0], 2)} s); then the operator's "
              f"target {'answered' if answered_stamp(peer, own) else 'NOT answered'} after {len(own)} sent")
        assert control_sees_the_graph(), (
            f"the control: rclpy without security on the unsecured domain sees nodes "
            f"{sorted(control.node.get_node_names())}, topics {sorted(n for n, _ in control.node.get_topic_names_and_types())}"
            f"\n{control_graph.logs_tail()}")
        assert held_at is not None and control_moved(held_at), \
            "the control: rclpy's targets did not move the unsecured arm (or not after the controls held)"
        assert all(refused(node) for node in ours), (
            f"the foreign CA's peer {sorted(peer.participants_named('stranger'))} has not failed a handshake with each of our nodes: "
            f"{ {node.name: refused(node) for node in ours} } (it failed with {sorted(stranger.auth_failed())}; ours "
            f"{ {node.name: g for node, g in ours.items()} })\n{stranger.stderr()[-2000:]}")
        assert answered_stamp(peer, own), (f"the operator's targets were not answered after the outsiders' "
                                           f"({len(own)} sent)\n{graph.logs_tail()}")

        nodes = set(outsider.node.get_node_names())
        topics = {n for n, _ in outsider.node.get_topic_names_and_types()}
        assert not nodes & {"compute_ik", "serial_node"}, f"rclpy without security sees {sorted(nodes)}"
        assert not topics & OUR_TOPICS, f"rclpy without security sees {sorted(topics & OUR_TOPICS)}"
        assert outsider.node.count_publishers("/servo_state") == 0
        assert outsider_xyz.get_subscription_count() == 0, "rclpy's xyz_target is matched by a secured node"
        assert not outsider_states, "rclpy received servo_state from the secured graph"

        assert not stranger.authenticated(), f"a foreign CA's participant was authenticated: {stranger.authenticated()}"
        assert not stranger.remote_endpoints(), f"the foreign peer discovered {sorted(stranger.remote_endpoints())}"
        assert stranger.matched("xyz_target", "pub") == 0 and not stranger.received("servo_state")

        states = [joint_state(p) for _, p in peer.received("servo_state")]
        moved = [s for s in states if stamp(s) in foreign]
        assert not moved, f"an outsider's target moved the arm: {len(moved)} servo_state replies"
        assert all(list(s.position) == list(rest.position) for s in states[n_states:]), "servo_state changed"
        # the controls are done: their processes stop before gui_bridge's secured start
        control.close()
        control = None
        control_graph.close()

        # gui_bridge as a command-line driver: refused without security, fine with it
        plain = subprocess.run(["ip", "netns", "exec", hosts.pc, bin_path("gui_bridge"), "once", *map(str, TARGET),
                                "--timeout", "5"], capture_output=True, text=True, timeout=60,
                               env={**os.environ, **NO_SECURITY, "ROS_DOMAIN_ID": str(domain)})
        assert plain.returncode == 1, f"gui_bridge once without security exited {plain.returncode}\n{plain.stderr}"
        secure = subprocess.run(["ip", "netns", "exec", hosts.pc, bin_path("gui_bridge"), "once", "0.19", "0.02", "0.16",
                                 "--timeout", str(HANDSHAKE_TIMEOUT), "--ros-args", "--enclave", "/eezybot/pc"],
                                capture_output=True, text=True, timeout=60,
                                env={**os.environ, **security_env(keystore), "ROS_DOMAIN_ID": str(domain)})
        assert secure.returncode == 0, f"gui_bridge once with the pc enclave exited {secure.returncode}\n{secure.stderr}"
    finally:
        for o in (outsider, control):
            if o is not None:
                o.close()
        codes = {f"control {name}": code for name, code in control_graph.close().items()}
        close(graph, peer, stranger)
        assert all(c == 0 for c in codes.values()), f"exit codes {codes}"


@two_hosts
def test_a_publisher_the_permissions_do_not_grant_fails_with_a_clear_log_line(hosts, domain, keystore):
    """gui_bridge under an enclave whose permissions (re-signed by the keystore's CA)
    lack xyz_target: its xyz_target publisher is refused, it says so naming the topic,
    and compute_ik receives nothing from it."""
    keystore.without_topic("/eezybot/pc", "/test/no_xyz", "xyz_target")
    graph = SecureGraph(hosts, domain, keystore)
    peer = graph.operator(pubs=(), subs=("servo_angles",))
    try:
        wait_matched(peer, graph, pubs=(), subs=("servo_angles",))
        r = subprocess.run(["ip", "netns", "exec", hosts.pc, bin_path("gui_bridge"), "once", *map(str, TARGET),
                            "--timeout", "5"], capture_output=True, text=True, timeout=60,
                           env={**os.environ, **security_env(keystore, "/test/no_xyz"), "ROS_DOMAIN_ID": str(domain)})
        out = r.stdout + r.stderr
        print(f"\ngui_bridge once under /test/no_xyz: exit {r.returncode}\n{out[-1500:]}")
        assert r.returncode != 0, "gui_bridge published a target its permissions do not grant"
        lines = [line for line in out.splitlines() if "xyz_target" in line
                 and any(w in line.lower() for w in ("permission", "denied", "not allowed", "not granted", "access"))]
        assert lines, f"no log line names xyz_target and the permissions:\n{out}"
        assert not peer.received("servo_angles"), "compute_ik answered a target from the refused publisher"
    finally:
        close(graph, peer)


# ---------------------------------------------------------------------------------------
# a link outage: new handshakes

# The participants' leases: our nodes announce every second with a 5 s lease
# (ros_plumbing's SPDP_PUBLISH_PERIOD), the Fast DDS operator with Fast DDS' default 20 s.
# The link stays down until both ends have reported the loss, so the outage is as long
# as the longest lease and no longer.
LOSS_TIMEOUT = 60.0
# Issue 8's 5 s from the link's return to the first answer is the soak's to measure
# (tests/soak/secure_outages.py, release build, exits 1 past it). In this debug build on
# a busy host it took 1.6-5.2 s at load 15-21 and up to 16 s at load 50: no bound with
# 3x headroom there would check the 5 s. So this test judges the order (lost each other,
# link back, new handshakes, a target sent after it answered); the wait only bounds a
# failure.
RESUME_TIMEOUT = 60.0


def lost_lines(graph):
    """serial_node's log lines saying a watched topic lost its last peer."""
    return [line for line in graph.serial.output().splitlines() if " lost (" in line]


# secured only: test_link_outages.py cuts the Pi's end for 25 s without security (one
# trial per outage length there); tests/soak/secure_outages.py runs 20 trials of it,
# and as many without security with --unsecured
@two_hosts
@pytest.mark.parametrize("secured", [True], ids=["secured"])
def test_the_graph_resumes_after_a_link_outage_longer_than_every_lease(hosts, domain, keystore, secured):
    """The Pi's end of the link down, while the operator keeps sending at 10 Hz, until
    the participants have lost each other: the operator dropped serial_node, and
    serial_node lost compute_ik (servo_angles) and every servo_state subscriber (the
    operator's lease is the longest). After the link comes back the handshakes are
    redone and a target sent after it is answered."""
    graph = SecureGraph(hosts, domain, keystore if secured else None)
    peer = graph.operator()
    try:
        wait_matched(peer, graph)
        sent, answered = drive(peer, TARGET)
        assert answered, f"no servo_state before the outage\n{graph.logs_tail()}"
        lost_before = len(lost_lines(graph))
        # serial_node's participant: the one across the link, the writer of servo_state
        across = peer.endpoint_participants("writer", "servo_state")
        assert across, f"the operator knows no servo_state writer\n{graph.logs_tail()}"
        hosts.cut("pi")
        t_cut = time.monotonic()

        def dropped():
            """serial_node's participant if the operator dropped it since the cut and has
            not found it again. (One of the operator's own host that a loaded host starved
            past its lease may be dropped too, and comes back on its own: it is not what
            this test is about, and its handshake may well be redone before the link
            returns.)"""
            gone = {}
            for t, line in peer.said("participant "):
                what, prefix = line.split()[1:3]
                if t >= t_cut and what in ("dropped", "removed"):
                    gone[prefix] = t
                elif what == "discovered" and gone.get(prefix, t + 1) <= t:
                    del gone[prefix]
            for t, line in peer.said("auth ok "):
                prefix = line.split()[2]
                if gone.get(prefix, t + 1) <= t:
                    del gone[prefix]
            return sorted(set(gone) & across)

        def serial_lost():
            return " ".join(lost_lines(graph)[lost_before:])

        def lost_each_other():
            s = serial_lost()
            return bool(dropped()) and "/servo_angles: publisher lost" in s and "/servo_state: subscriber lost" in s

        while time.monotonic() - t_cut < LOSS_TIMEOUT and not lost_each_other():
            peer.publish("xyz_target", point_target(*TARGET)[0])
            time.sleep(0.1)
        outage_s = time.monotonic() - t_cut
        assert lost_each_other(), (
            f"after {outage_s:.0f} s of outage the participants have not lost each other (the test would not test "
            f"lost peers): the operator dropped {dropped()}; serial_node said {lost_lines(graph)[lost_before:]}")
        lost = dropped()
        hosts.restore("pi")
        t_restore = time.monotonic()
        after = []
        resumed_s = None
        while time.monotonic() - t_restore < RESUME_TIMEOUT:
            x = TARGET[0] + 0.01 * math.sin(len(after))
            payload, st = point_target(x, TARGET[1], TARGET[2])
            peer.publish("xyz_target", payload)
            after.append(st)
            wanted = set(after)
            hit = [t for t, p in peer.received("servo_state") if t >= t_restore and stamp(joint_state(p)) in wanted]
            if hit:
                resumed_s = hit[0] - t_restore
                break
            time.sleep(0.1)
        # the handshakes with the participants lost across the link, redone after it returned
        rehandshakes = [line for t, line in peer.said("auth ok ") if t >= t_restore and line.split()[2] in lost]
        print(f"\n{'secured' if secured else 'plain'}: {outage_s:.1f} s outage: resumed "
              f"{resumed_s if resumed_s is None else round(resumed_s, 2)} s after the link returned; the operator "
              f"lost {len(lost)} participant(s) across the link, new handshakes {len(rehandshakes)}")
        seen = [f"{t - t_restore:+.2f} s {line}" for t, line in peer.lines if t >= t_cut and line.split(" ")[0] in
                ("participant", "auth", "matched") and " changed " not in line]
        assert resumed_s is not None, (f"no servo_state for a new target within {RESUME_TIMEOUT:g} s; the operator, "
                                       f"relative to the link's return:\n" + "\n".join(seen) + f"\n{graph.logs_tail()}")
        if secured:
            assert rehandshakes, "the operator did not re-authenticate serial_node after the link returned"
    finally:
        close(graph, peer)


# ---------------------------------------------------------------------------------------
# bad keystore files: Enforce stops the node with exit status 2, naming the file

def spoil(keystore, foreign_keystore, case):
    """(enclave name, the file the message must name)."""
    name = f"/test/{case}"
    if case == "corrupt_key":
        d = keystore.with_corrupt_key("/eezybot/pi", name)
        return name, d / "key.pem"
    if case == "expired_certificate":
        d = keystore.with_expired_certificate("/eezybot/pi", name)
        return name, d / "cert.pem"
    if case == "wrong_ca":
        d = keystore.with_identity_ca_of("/eezybot/pi", name, foreign_keystore)
        return name, d / "identity_ca.cert.pem"
    if case == "missing_enclave":
        return name, keystore.enclave(name)
    raise ValueError(case)


@pytest.mark.parametrize("node", ["serial_node", "compute_ik"])
@pytest.mark.parametrize("case", ["corrupt_key", "expired_certificate", "wrong_ca", "missing_enclave"])
def test_a_bad_keystore_file_stops_the_node_naming_it(domain, keystore, foreign_keystore, case, node):
    enclave, bad = spoil(keystore, foreign_keystore, case)
    args = ["--ros-args", "-p", "port:=mock"] if node == "serial_node" else []
    p = NodeProcess(node, args, domain, env=security_env(keystore, enclave))
    try:
        p.proc.wait(20)
    except subprocess.TimeoutExpired:
        pass
    running = p.proc.poll() is None
    code = p.stop()
    out = p.log_path.read_text()
    assert not running, f"{node} kept running with {case} under Enforce:\n{out[-2000:]}"
    assert code == 2, f"{node} exited {code}, not 2:\n{out[-2000:]}"
    assert str(bad) in out, f"{node}'s message does not name {bad}:\n{out[-2000:]}"


# ---------------------------------------------------------------------------------------
# certificates that expire are seen before they do (issue 36, item 5)

def test_a_secured_node_reports_its_certificate_expiry_and_warns_a_month_before(domain, keystore):
    """A secured node's every diagnostics report carries its certificate's end
    (`certificate_expires`, `certificate_days_left`); within 30 days it is a warning naming
    the file to renew. serial_node's enclave re-issued to end in 10 days; compute_ik's the
    keystore's own (ten years). Read by a Fast DDS peer with the PC's enclave."""
    from diagnostic_msgs.msg import DiagnosticArray

    from interop import cdr
    now = time.time()
    fmt = lambda t: time.strftime("%Y%m%d%H%M%SZ", time.gmtime(t))  # noqa: E731
    soon = keystore.with_certificate_dates("/eezybot/pi", "/test/expires_soon", fmt(now - 86400), fmt(now + 10 * 86400))
    nodes = [NodeProcess("serial_node", ["--ros-args", "-p", "port:=mock", "-p", "diagnostics_period:=0.2"], domain,
                         env=security_env(keystore, "/test/expires_soon")),
             NodeProcess("compute_ik", ["--ros-args", "-p", "diagnostics_period:=0.2"], domain,
                         env=security_env(keystore, "/eezybot/pc"))]
    peer = SecurePeer(domain, enclave=keystore.enclave("/eezybot/pc"), subs=["diagnostics"])
    try:
        def reports():
            out = {}
            for _, payload in peer.received("diagnostics"):
                for s in cdr.deserialize(payload, DiagnosticArray()).status:
                    out[s.name.split(":")[0]] = s
            return out
        assert peer.wait(lambda: {"serial_node", "compute_ik"} <= set(reports()), 30), (peer.stderr(), reports().keys())
        serial = reports()["serial_node"]
        v = {kv.key: kv.value for kv in serial.values}
        assert v["certificate_days_left"] in ("9", "10"), v
        assert v["certificate_expires"] == time.strftime("%Y-%m-%d", time.gmtime(now + 10 * 86400)), v
        level = serial.level[0] if isinstance(serial.level, bytes) else serial.level
        assert level >= 1, serial  # at least a warning
        assert f"{soon / 'cert.pem'} expires on {v['certificate_expires']}" in serial.message, serial.message
        ik = {kv.key: kv.value for kv in reports()["compute_ik"].values}
        assert int(ik["certificate_days_left"]) >= 3600, ik
    finally:
        peer.close()
        codes = [n.stop() for n in nodes]
    assert codes == [0, 0], codes


# ---------------------------------------------------------------------------------------
# secured samples of every size, with Fast DDS (issue 36, item 3)

# String lengths: unfragmented; each residue mod 4 just past the fragmentation threshold
# (about 1.4 KB) and at 64 KiB, whose last fragment needs 1-3 bytes of padding (RustDDS's
# DATA_FRAG had none: the SRTPS_POSTFIX after it landed unaligned and Fast DDS dropped the
# message, patches/README.md rustdds entry 33)
SIZES = [1, 2, 3, 4, 1500, 1501, 1502, 1503, 65524, 65525, 65526, 65527]


def test_fast_dds_and_our_nodes_exchange_secured_samples_of_every_size(domain, keystore):
    """Under Enforce, a Fast DDS tool (tools enclave) receives state_publisher's
    robot_description, the whole URDF (12 KB: fragmented), and our own samples of each
    size up to 64 KiB (ros_plumbing's ros_probe example, on RosNode as every node,
    pc enclave); and it sends samples of the same sizes that ours receives, byte for
    byte. The 1,000-sample run: tests/soak/secure_sizes.py."""
    urdf = (REPO / "urdf" / "eezybot.urdf").read_bytes()
    publisher = NodeProcess("state_publisher", [], domain, env=security_env(keystore, "/eezybot/pc"))
    tool = SecurePeer(domain, enclave=keystore.enclave("/eezybot/tools"), pubs=["robot_description"],
                      subs=["robot_description"], name="fastdds_tool")
    ours = SecurePeer(domain, enclave=keystore.enclave("/eezybot/pc"), pubs=["robot_description"],
                      subs=["robot_description"], name="ros_probe", binary=bin_path("examples/ros_probe"))
    try:
        tool.wait_ready()
        ours.wait_ready()
        description = b"\x00\x01\x00\x00" + (len(urdf) + 1).to_bytes(4, "little") + urdf + b"\x00"
        assert tool.wait(lambda: description in [p for _, p in tool.received("robot_description")],
                         HANDSHAKE_TIMEOUT), (f"the Fast DDS tool has no robot_description "
                                              f"({len(tool.received('robot_description'))} other samples)\n"
                                              f"{tool.stderr()[-2000:]}")
        assert ours.wait(lambda: ours.matched("robot_description", "pub") >= 1
                         and tool.matched("robot_description", "pub") >= 1, HANDSHAKE_TIMEOUT)
        # each way in turn: the other side's copy of a latched sample is in already
        to_tool = exchange(ours, tool, "robot_description", SIZES)
        to_ours = exchange(tool, ours, "robot_description", SIZES, first_index=len(SIZES))
        print(f"\nrobot_description ({len(urdf)} B) received; ours -> Fast DDS "
              f"{[(s, v) for s, v, _ in to_tool]}; Fast DDS -> ours {[(s, v) for s, v, _ in to_ours]}")
        assert all(v == "ok" for _, v, _ in to_tool), (to_tool, tool.stderr()[-2000:])
        assert all(v == "ok" for _, v, _ in to_ours), (to_ours, ours.stderr()[-2000:])
    finally:
        codes = [p.close() for p in (tool, ours)]
        codes.append(publisher.stop())
    assert codes == [0, 0, 0], codes
