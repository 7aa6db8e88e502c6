"""The WAN mode (issue 20): the operator's PC and the Pi on different networks, joined
only through a Zenoh router with mutual TLS. Network namespaces `pc`, `wan` and `pi`
(wanhost.py): `pc` and `pi` each reach only the router's address in `wan`, which does
not forward. launch_scripts/router.sh runs in `wan`; launch_scripts/pc.sh and pi.sh run
with ZENOH_ROUTER and ZENOH_TLS_DIR, so each starts its bridge beside its nodes; real
rclpy (Fast DDS) processes are the users at each site.

Its checks count samples and compare values, with generous timeouts, never durations:
it runs in the background beside the other tests (conftest: `background`), as the
outage modules do. One trial of each kind: the outages are in test_wan_outages.py, 20
of each length in tests/soak/outages.py --mode wan, the latency in
tests/bench/wan_e2e.py (BENCHMARKS.md)."""
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, String

import wanhost
from conftest import REPO, NodeProcess, bin_path
from robot_facts import servo_deg
from split_graph import SplitGraph, seconds, streaming_summary

pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=120)]
# the tests that set up the sites (network namespaces: root); the launch scripts' own
# checks need none
needs_hosts = pytest.mark.skipif(wanhost.available() is not None, reason=f"WAN hosts: {wanhost.available()}")

PC_LAN_ONLY = {"/xyz_target", "/xyz_line_target", "/pose_target", "/joint_target", "/gripper_target", "/joint_states", "/tf", "/tf_static",
               "/robot_description"}


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    """Our CA with the clients pc, pi and pc2 (a second operator PC), and another CA's
    set (a stranger's)."""
    ours = wanhost.make_certs(tmp_path_factory.mktemp("wan-certs") / "ours", "pc2")
    theirs = wanhost.make_certs(tmp_path_factory.mktemp("wan-certs") / "theirs")
    return ours, theirs


def start(sites, domain, tmp_path, certs, impaired=None, device="virtual", target_hz=20.0):
    hosts = wanhost.WanHosts(tag="w", sites=sites, impaired=impaired)
    try:
        hosts.start_router(certs[0], tmp_path / "router.log")
        g = SplitGraph(hosts, domain, tmp_path, device=device, env=hosts.graph_env(certs[0]), target_hz=target_hz)
    except BaseException:
        hosts.close()
        raise
    return hosts, g


def close(hosts, g):
    try:
        codes = g.close()
    finally:
        hosts.close()
    assert all(c == 0 for c in codes.values()), f"exit codes {codes}"
    assert hosts.router_code == 0, f"the router exited with {hosts.router_code}"


def site_user(hosts, site, domain, seconds, *args):
    """tests/site_user.py at `site` (a process of its own): started; `.result()` waits
    for it and returns its JSON."""
    p = hosts.popen(site, [sys.executable, str(REPO / "tests" / "site_user.py"), "--domain", str(domain),
                           "--for", str(seconds), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def result():
        out, err = p.communicate(timeout=seconds + 60)
        lines = [line for line in out.splitlines() if line.startswith("{")]
        assert p.returncode == 0 and lines, f"site_user at {site}: exit {p.returncode}\n{out[-2000:]}\n{err[-2000:]}"
        return json.loads(lines[-1])

    p.result = result
    return p


def connected_line(router=f"tls/{wanhost.ROUTER}:{wanhost.PORT}"):
    """The line a bridge prints once the router let it in (the line it prints while not
    let in says "not connected to the router")."""
    return f"eezybot_wan_bridge: connected to the router {router}"


def bridge(hosts, site, domain, *args, env=None, side="pc"):
    """eezybot_wan_bridge SIDE ARGS... at `site` (a second PC, a stranger), with its log."""
    return NodeProcess(str(wanhost.wan_bin_dir() / "eezybot_wan_bridge"), [side, *args], domain,
                       env=env, netns=hosts.ns[site])


@needs_hosts
def test_a_target_crosses_the_router_and_the_estop_holds_across_it(domain, tmp_path, certs):
    """rclpy in `pc` -> compute_ik (pc) -> bridge -> router -> bridge -> serial_node (pi)
    -> the virtual Arduino; servo_state comes back to rclpy in `pc` with ROBOT.md's
    servo angles. Only the contract crosses. An e-stop from `pc` holds the Pi; a Pi that
    starts again during it sees it (latched across the router); a release moves again."""
    hosts, g = start(("pc", "pi"), domain, tmp_path, certs)
    try:
        g.wait_flowing(timeout=60)
        goal = (0.2, 0.05, 0.15)
        g.send_goal(goal)
        expected = servo_deg(*goal)

        def at(goal_deg):
            reply = g.states[-1][1]
            return max(abs(math.degrees(a) - e) for a, e in zip(reply.position[:3], goal_deg)) < 0.1

        assert g.pump_until(lambda: at(expected), 10, send=False), (list(g.states[-1][1].position), expected)
        assert g.states[-1][1].name[:3] == ["base_servo", "shoulder_servo", "elbow_servo"]

        # what crosses: the Pi's LAN has the PC's servo_angles and estop, not its targets,
        # joint_states, tf or robot_description; the PC's LAN has no node of the Pi's
        pi_user = site_user(hosts, "pi", domain, 15, "--sub", "/servo_angles", "--until", "/servo_angles", "--topics")
        g.pump_until(lambda: pi_user.poll() is not None, 30)
        pi_topics = set(pi_user.result()["topics"])
        assert {"/servo_angles", "/servo_state", "/estop"} <= pi_topics, pi_topics
        assert not pi_topics & PC_LAN_ONLY, f"PC-only topics on the Pi's LAN: {sorted(pi_topics & PC_LAN_ONLY)}"
        pc_nodes = set(g.o.node.get_node_names())
        assert "serial_node" not in pc_nodes and {"compute_ik", "eezybot_wan_bridge_pc"} <= pc_nodes, pc_nodes

        # e-stop from the PC, through the router
        estop = g.o.pub("/estop", Bool)  # the contract's QoS: latched
        estop.publish(Bool(data=True))
        assert g.pump_until(lambda: g.diag_values("serial_node")[2].get("estop") == "true", 15), \
            f"serial_node did not report the e-stop: {g.diag_values('serial_node')}\n{g.logs_tail()}"
        # targets keep coming (20 of them): none is applied, now or after the release (no
        # reply carries its stamp, judged at the end), and every servo_state stamped since
        # (serial_node's own reports, stamped when made) says one held position
        t_held, n_sent = time.time(), len(g.sent)

        def reports():
            return [list(m.position) for _, m in g.states if seconds(m.header.stamp) >= t_held]

        assert g.pump_until(lambda: len(g.sent) >= n_sent + 20 and len(reports()) >= 3, 30), \
            f"{len(g.sent) - n_sent} targets sent, {len(reports())} servo_state during the e-stop"
        during = {s for _, s in g.sent[n_sent:]}
        held = reports()
        assert all(max(abs(a - b) for a, b in zip(r, held[0])) < 1e-6 for r in held), \
            f"the arm moved during the e-stop: {held}"

        # a Pi that starts again (its bridge joins the router anew) sees the current e-stop
        assert g.pi.stop() == 0
        g.pi = NodeProcess(g.pi.argv[-1], [], domain, env={k: v for k, v in g.pi.env.items()}, netns=hosts.pi)
        g.procs[1] = g.pi
        g.diags.clear()
        assert g.pump_until(lambda: g.diag_values("serial_node")[2].get("estop") == "true", 30), \
            f"the restarted Pi does not hold the latched e-stop: {g.diag_values('serial_node')}\n{g.logs_tail()}"

        estop.publish(Bool(data=False))
        t_release = time.time()
        assert g.pump_until(lambda: g.answers_after(t_release), 30), \
            f"no motion after the release\n{g.logs_tail()}"
        # a target of the e-stop applied late would have come before the release's answer
        assert not [s for _, s in g.replies_after(t_held) if s in during], "a target sent during the e-stop was applied"
    finally:
        close(hosts, g)


@needs_hosts
def test_a_second_operator_pc_joins_late_and_a_stranger_gets_nothing(domain, tmp_path, certs):
    """A second operator PC (`pc2`, its own certificate from our CA) whose bridge joins
    after the e-stop was pressed gets the latched robot_description and the current
    e-stop, and servo_state; its release reaches the Pi and the first PC. A bridge with a
    certificate from another CA, and a plain-TCP client, get nothing through either way."""
    hosts, g = start(("pc", "pi", "pc2", "stranger"), domain, tmp_path, certs)
    extra = []
    try:
        g.wait_flowing(timeout=60)
        urdf = g.o.sub("/robot_description", String)
        pc_estop = g.o.sub("/estop", Bool)
        estop = g.o.pub("/estop", Bool)
        estop.publish(Bool(data=True))
        assert g.pump_until(lambda: g.diag_values("serial_node")[2].get("estop") == "true" and urdf, 15), \
            f"{g.diag_values('serial_node')}, robot_description {len(urdf)}\n{g.logs_tail()}"

        # the second PC: its bridge and a user (RViz2, the ros2 CLI) join now
        extra.append(bridge(hosts, "pc2", domain, env=hosts.graph_env(certs[0], cert="pc2")))
        late = site_user(hosts, "pc2", domain, 40, "--sub", "/robot_description", "--sub", "/estop",
                         "--sub", "/servo_state", "--until", "/robot_description", "--until", "/estop",
                         "--until", "/servo_state", "--estop", "false")
        t_join = time.time()
        assert g.pump_until(lambda: late.poll() is not None, 50), "the second PC's user did not finish"
        got = late.result()["got"]
        assert all(got[t]["count"] for t in got), f"the second PC got {got}\n{extra[0].output()[-3000:]}"
        text = urdf[-1][1].data
        assert got["/robot_description"]["first"] == {"len": len(text), "head": text[:200]}
        assert got["/estop"]["first"] is True, f"the second PC's first e-stop sample is not the current one: {got}"

        # its release (published once its subscriptions were served) reaches the Pi and the first PC
        assert g.pump_until(lambda: g.diag_values("serial_node")[2].get("estop") == "false"
                            and g.answers_after(t_join), 30), \
            f"the second PC's release did not reach the Pi: {g.diag_values('serial_node')}\n{g.logs_tail()}"
        assert g.pump_until(lambda: pc_estop and pc_estop[-1][1].data is False, 30), \
            f"the first PC did not hear it: {[m.data for _, m in pc_estop]}"

        # strangers: a bridge with another CA's certificate, and one on plain TCP to the
        # TLS port; their user presses the e-stop 5 times a second and listens
        theirs = hosts.graph_env(certs[1])
        extra.append(bridge(hosts, "stranger", domain, env=theirs))
        extra.append(bridge(hosts, "stranger", domain, "--router", f"tcp/{wanhost.ROUTER}:{wanhost.PORT}", env=theirs))
        stranger = site_user(hosts, "stranger", domain, 15, "--sub", "/servo_state", "--sub", "/diagnostics",
                             "--estop", "true", "--estop-rate", "5")
        g.pump_until(lambda: stranger.poll() is not None, 40)
        theirs_got = stranger.result()
        assert theirs_got["estops_sent"] > 30, theirs_got
        # an e-stop that got through would hold the Pi until a release: the arm follows a
        # target sent after the strangers' last one
        t_done = time.time()
        assert g.pump_until(lambda: g.answers_after(t_done), 30), \
            f"the arm stopped following while strangers tried: {g.diag_values('serial_node')}"
        assert g.diag_values("serial_node")[2].get("estop") == "false", "a stranger's e-stop reached the Pi"
        # nothing from the router; on the stranger's LAN only its own bridges' status,
        # which says they are not connected
        assert all(v["count"] == 0 for t, v in theirs_got["got"].items() if t != "/diagnostics"), \
            f"a stranger got {theirs_got}"
        own = theirs_got.get("statuses", {})
        assert set(own) <= {"eezybot_wan_bridge_pc: WAN link"} and \
            all(s["message"].startswith("not connected to the router") for s in own.values()), \
            f"a stranger got diagnostics other than its own bridges' not connected: {theirs_got}"
        # each stranger's bridge says it is not let in (every 10 s while it tries), and
        # never that it was; the second PC's was
        assert g.pump_until(lambda: all("not connected to the router" in p.output() for p in extra[1:]), 30), \
            [p.output()[-2000:] for p in extra[1:]]
        for p in extra[1:]:
            assert not [line for line in p.output().splitlines() if line.startswith("eezybot_wan_bridge: connected")], \
                p.output()[-2000:]
        assert connected_line() in extra[0].output().splitlines(), extra[0].output()[-2000:]
    finally:
        codes = [p.stop() for p in extra]
        close(hosts, g)
    assert codes == [0] * len(codes), codes


@needs_hosts
def test_streaming_over_an_impaired_wan(domain, tmp_path, certs):
    """40 +/- 10 ms each way and 2 % loss on the Pi's WAN link (linkem): streaming at
    50 Hz for 45 s continues through the router, the newest target wins, the round trip
    is reported (tests/bench/wan_e2e.py measures it), and the bridges' TLS links to the
    router hold: no Zenoh session ends (wan/patches/zenoh-link-tls: upstream's links
    broke about once a minute here, on both sides, and the routes were made again)."""
    hosts, g = start(("pc", "pi"), domain, tmp_path, certs, impaired=dict(delay_ms=40, jitter_ms=10, loss=0.02),
                     target_hz=50)
    angles = g.o.sub("/servo_angles", JointState)
    try:
        g.wait_flowing(timeout=60)
        t0 = time.time()
        g.pump(45)

        def settled():  # the device reports the servo_angles commanded last
            return angles and max(abs(a - b) for a, b in zip(g.states[-1][1].position, angles[-1][1].position)) < 0.2

        settled_ok = g.pump_until(settled, 30, send=False)
        replies = g.replies_after(t0)
        churn = {p.name: [line for line in p.output().splitlines() if "Remote ROS 2 bridge left" in line]
                 for p in g.procs}
    finally:
        close(hosts, g)
    r = streaming_summary(g, t0, replies, hosts.stats, "impaired WAN")
    assert not any(churn.values()), f"a bridge's session to the router ended while streaming: {churn}"
    assert r["longest_unanswered"] < 100, \
        f"streaming stalled: {r['longest_unanswered']} targets in a row (2 s at 50 Hz) got no answer"
    assert len(r["answered"]) >= 0.7 * len(r["sent"]), \
        f"only {len(r['answered'])} of {len(r['sent'])} targets reached the device"
    assert settled_ok, (list(g.states[-1][1].position), list(angles[-1][1].position))
    stamps = [s for _, s in r["replies"]]
    assert stamps == sorted(stamps), "an older target was applied after a newer one"


def test_without_a_router_no_bridge_runs_and_bad_tls_files_stop_the_scripts(domain, tmp_path, certs):
    """Without ZENOH_ROUTER pc.sh starts no bridge; with it, a missing TLS directory or
    a key that is not the certificate's ends pc.sh / pi.sh with status 2 before any node
    starts."""
    bins = {"EEZYBOT_BIN_DIR": str(Path(bin_path("serial_node")).parent), "EEZYBOT_WAN_BIN_DIR": str(wanhost.wan_bin_dir())}
    env = {**bins, "SERIAL_PORT": "mock", "ZENOH_ROUTER": ""}
    p = NodeProcess(str(REPO / "launch_scripts" / "pi.sh"), [], domain, env=env)

    def kids():
        """The script's child processes' names (one still named pi.sh is forked, not yet
        started as a binary)."""
        out = subprocess.run(["pgrep", "-l", "-P", str(p.proc.pid)], capture_output=True, text=True).stdout
        return sorted(line.split(None, 1)[1] for line in out.splitlines())

    # pi.sh starts everything it starts before its banner's last line: once that line is
    # out and each child runs its binary, what runs is all that will
    last_line = "expected on the PC (pc.sh"
    try:
        deadline = time.monotonic() + 30
        while not (last_line in p.output() and kids() and "pi.sh" not in kids()):
            assert time.monotonic() < deadline and p.proc.poll() is None, f"{kids()}\n{p.output()}"
            time.sleep(0.05)
        running = kids()
    finally:
        assert p.stop() == 0
    assert running == ["serial_node"], running
    assert "WAN" not in p.log_path.read_text()

    mixed = tmp_path / "mixed"
    mixed.mkdir()
    for f in ("ca.pem", "pc.pem", "pi.pem"):
        (mixed / f).write_bytes((certs[0] / f).read_bytes())
    for f in ("pc.key", "pi.key"):  # the other CA's keys: not these certificates' keys
        (mixed / f).write_bytes((certs[1] / f).read_bytes())
        (mixed / f).chmod(0o600)
    for script, tls_dir, says in (("pc.sh", tmp_path / "nonexistent", "is not a directory"),
                                  ("pi.sh", mixed, "does not go with")):
        env = {**bins, "SERIAL_PORT": "mock", "ZENOH_ROUTER": f"tls/{wanhost.ROUTER}:{wanhost.PORT}", "ZENOH_TLS_DIR": str(tls_dir)}
        p = NodeProcess(str(REPO / "launch_scripts" / script), [], domain, env=env)
        try:
            code = p.proc.wait(30)
        finally:
            p.stop()
        out = p.log_path.read_text()
        assert code == 2, f"{script}: exit {code}\n{out}"
        assert says in out and "not starting" in out, out
        assert "running here" not in out, out


@needs_hosts
def test_every_sample_arrives_once_after_the_ends_restart(domain, tmp_path, certs):
    """wan/patches/zenoh-plugin-ros2dds: with upstream's plugin, each time the subscriber
    on the PC and the publisher on the Pi were restarted, a removed route lived on and
    every sample then reached the PC once more (3, then 4 times). Five rounds of
    restarting both ends of servo_state: every sample arrives once, judged on the
    subscriber's first 100 samples (each sample's position is its number)."""
    probe = str(REPO / "wan" / "check" / "ros_probe.py")
    hosts = wanhost.WanHosts(tag="d")
    bridges = []
    try:
        hosts.start_router(certs[0], tmp_path / "router.log")
        env = hosts.graph_env(certs[0])
        bridges = [bridge(hosts, "pc", domain, env=env), bridge(hosts, "pi", domain, env=env, side="pi")]
        dds = {"ROS_DOMAIN_ID": str(domain)}
        for round_ in range(5):
            # the subscriber ends after 100 samples (60 s: only a deadline); the publisher
            # goes on until then. The second between their starts only orders them, as the
            # report did (subscriber first); a late start costs samples, not the verdict.
            sub = hosts.popen("pc", ["env", *(f"{k}={v}" for k, v in dds.items()), sys.executable, probe, "sub",
                                     "/servo_state", "joint", "--count", "100", "--timeout", "60"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            time.sleep(1)
            pub = hosts.popen("pi", ["env", *(f"{k}={v}" for k, v in dds.items()), sys.executable, probe, "pub",
                                     "/servo_state", "joint", "--rate", "20"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            try:
                out, err = sub.communicate(timeout=90)
            finally:
                pub.terminate()
                pub.wait(30)
            seen = [line.split("position=")[1].split(" ")[0] for line in out.splitlines() if "position=" in line]
            dups = {p: seen.count(p) for p in set(seen) if seen.count(p) > 1}
            assert sub.returncode == 0 and len(seen) == 100, \
                f"round {round_ + 1}: {len(seen)} samples\n{out[-1000:]}\n{err[-1000:]}"
            assert not dups, f"round {round_ + 1}: samples arrived more than once: {dict(list(dups.items())[:5])}"
    finally:
        codes = [b.stop() for b in bridges]
        hosts.close()
    assert codes == [0, 0] and hosts.router_code == 0, (codes, hosts.router_code)
