"""SROS2 and the WAN together (issue 36, item 1): both sites' LANs secured (Enforce, a
keystore of launch_scripts/keystore.sh) and the WAN leg under mutual TLS, in the
network namespaces `pc`, `wan` and `pi` of wanhost.py. pc.sh and pi.sh run with
ROS_SECURITY_ENABLE=true and ZENOH_ROUTER together; each site's bridge joins its LAN
under its own enclave, /eezybot/bridge_pc or /eezybot/bridge_pi (Cyclone DDS's
security plugins, built into the bridge: docs/security.md, "SROS2 with the WAN").

The secured operator in `pc` is ros_plumbing's ros_probe (RustDDS, as gui_bridge) under
the /eezybot/pc enclave: Fast DDS 2.9 (tests/interop/sros2_peer) starts its handshakes
with DH+MODP, whose key Cyclone DDS reads differently, so it cannot authenticate with the
bridge. The unsecured outsiders are rclpy (tests/site_user.py). Each check has its
control in the same test: the same graph without SROS2 and with plain TCP on the WAN,
where the outsiders do see the data and every capture does carry it.

Judged by order and content (which samples, which bytes), never by durations."""
import json
import math
import os
import re
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest

import wanhost
from conftest import REPO, TOPICS, NodeProcess, bin_path
from robot_facts import servo_deg
from security_rig import (KEYSTORE_SH, NO_SECURITY, Capture, SecurePeer, _run, drive, joint_state, make_keystore,
                          point_target, security_env, tcp_streams, udp_datagrams, wait_at)
from split_graph import VirtualArduinoPty

# in a process of its own beside the other modules (network namespaces and their
# processes; judged by order and content)
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=110)]
needs_hosts = pytest.mark.skipif(wanhost.available() is not None, reason=f"WAN hosts: {wanhost.available()}")

TARGET = (0.2, 0.0, 0.15)
OTHER_TARGET = (0.18, 0.04, 0.17)
HANDSHAKES_S = 60.0  # only bounds a failure: the operator matched in 2-10 s here
OUTSIDER_TOPICS = ("/servo_state", "/servo_angles", "/diagnostics", "/estop")
CONTRACT = {f"/{name}" for name in TOPICS}
BRIDGE = "eezybot_wan_bridge"


@pytest.fixture(scope="module")
def keystore(tmp_path_factory):
    return make_keystore(tmp_path_factory.mktemp("keystore") / "keystore")


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    """Our CA with the clients pc, pi and pc2 (a second operator PC)."""
    return wanhost.make_certs(tmp_path_factory.mktemp("wan-certs") / "certs", "pc2")


def bins():
    return {"EEZYBOT_BIN_DIR": str(Path(bin_path("serial_node")).parent),
            "EEZYBOT_WAN_BIN_DIR": str(wanhost.wan_bin_dir())}


def site_user(hosts, site, domain, seconds, *args):
    """tests/site_user.py (rclpy, no security) at `site` with ARGS; `.result()` waits for
    its JSON."""
    argv = [sys.executable, str(REPO / "tests" / "site_user.py"), "--domain", str(domain), "--for", str(seconds),
            *args]
    p = hosts.popen(site, ["env", *(f"{k}={v}" for k, v in NO_SECURITY.items()), *argv], stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE, text=True)

    def result():
        out, err = p.communicate(timeout=seconds + 60)
        lines = [line for line in out.splitlines() if line.startswith("{")]
        assert p.returncode == 0 and lines, f"site_user at {site}: exit {p.returncode}\n{out[-2000:]}\n{err[-2000:]}"
        return json.loads(lines[-1])

    p.result = result
    return p


def outsider(hosts, site, domain, seconds):
    """An unsecured rclpy peer at `site` (site_user) subscribed to the topics that
    cross, listing the topics its DDS graph has."""
    return site_user(hosts, site, domain, seconds, "--topics", *(a for t in OUTSIDER_TOPICS for a in ("--sub", t)))


def urdf_summary():
    """What site_user says of the URDF state_publisher serves (urdf/eezybot.urdf)."""
    text = (REPO / "urdf" / "eezybot.urdf").read_text()
    return {"len": len(text), "head": text[:200]}


def robot_name():
    """The URDF's robot name as it appears in robot_description's text."""
    urdf = (REPO / "urdf" / "eezybot.urdf").read_text()
    return re.search(r'<robot name="[^"]+"', urdf).group(0).encode()


def target_pattern(payload):
    """A PointStamped target's CDR (little-endian, encapsulation header first) as a
    pattern of the bytes the operator writes on the wire: rclpy's serializer, which made
    the payload, leaves the alignment padding after the frame name uninitialised, which
    the probe (RustDDS) writes as zeros, so those bytes may be anything."""
    body = payload[4:]
    header = 8 + 4 + struct.unpack("<I", body[8:12])[0]  # stamp, frame name (length, text, NUL)
    pad = -header % 8  # the point's doubles are 8-aligned
    return re.compile(re.escape(body[:header]) + b"(?s:.)" * pad + re.escape(body[header + pad:]))


def leg_bytes(pcap):
    """Every UDP payload and every TCP connection's bytes of a capture, joined, and the
    counts: (bytes, RTPS datagrams, RTPS datagrams with an SRTPS_PREFIX, TCP streams)."""
    datagrams = udp_datagrams(pcap)
    streams = tcp_streams(pcap)
    rtps = [d for d in datagrams if d.startswith(b"RTPS")]
    protected = sum(1 for d in rtps if len(d) > 20 and d[20] == 0x33)
    return b"\0".join(datagrams + list(streams.values())), len(rtps), protected, streams


class Run:
    """What one run of the graph across the sites left: the operator (its published and
    received samples), each leg's capture, what each outsider saw, the scripts' logs."""


def run_graph(secured, domain, workdir, keystore, certs):
    """The graph across the WAN, secured (SROS2 on both LANs, TLS to the router) or not
    (neither: plain TCP to the router): a target from the operator in `pc` answered by
    serial_node in `pi` at ROBOT.md's angles, then 10 s more of targets while an
    unsecured outsider listens on each LAN; every interface of `pc`, `wan` and `pi`
    captured throughout. A second operator PC (`pc2`, its LAN unsecured, its bridge with
    the certificate pc2) takes robot_description from state_publisher in `pc`: a sample
    larger than a datagram, through the pc bridge's secured participant."""
    workdir.mkdir()
    r = Run()
    hosts = wanhost.WanHosts(tag="q", sites=("pc", "pi", "pc2"))
    captures, procs, peer, arduino, outsiders, second = {}, [], None, None, [], None
    codes = {}
    try:
        for leg, ns in (("pc", hosts.pc), ("wan", hosts.wan), ("pi", hosts.pi)):
            captures[leg] = Capture(ns, "any", workdir / f"{leg}.pcap", expression="udp or tcp")
        endpoint = f"{'tls' if secured else 'tcp'}/{wanhost.ROUTER}:{wanhost.PORT}"
        hosts.start_router(certs, workdir / "router.log", listen=endpoint)
        env = {**hosts.graph_env(certs), **bins(), "ZENOH_ROUTER": endpoint, "GUI_BIND": "127.0.0.1:8080",
               **(security_env(keystore) if secured else NO_SECURITY)}
        arduino = VirtualArduinoPty(workdir)
        procs.append(NodeProcess(str(REPO / "launch_scripts" / "pc.sh"), [], domain, env=env, netns=hosts.pc))
        procs.append(NodeProcess(str(REPO / "launch_scripts" / "pi.sh"), [], domain,
                                 env={**env, "SERIAL_PORT": str(arduino.path)}, netns=hosts.pi))
        procs.append(NodeProcess(str(wanhost.wan_bin_dir() / BRIDGE), ["pc", "--cert", "pc2"], domain,
                                 env={**env, **NO_SECURITY}, netns=hosts.ns["pc2"]))
        second = site_user(hosts, "pc2", domain, 60, "--sub", "/robot_description", "--until", "/robot_description")
        # the operator joins once compute_ik is up, as an operator's tool would (a
        # RustDDS participant that starts its handshakes with a node still starting
        # sometimes never completes one: BENCHMARKS.md, SROS2, start)
        deadline = time.monotonic() + 60  # only bounds a failure
        while "/compute_ik ready" not in procs[0].output():
            assert time.monotonic() < deadline and procs[0].proc.poll() is None, procs[0].output()[-3000:]
            time.sleep(0.1)
        peer = SecurePeer(domain, enclave=keystore.enclave("/eezybot/pc") if secured else None,
                          pubs=("xyz_target",), subs=("servo_angles", "servo_state"), netns=hosts.pc,
                          name="operator", binary=bin_path("examples/ros_probe"))

        def logs():
            return "\n".join(f"--- {p.name}\n{p.output()[-3000:]}" for p in procs) + f"\n--- operator\n{peer.stderr()}"

        assert peer.wait(lambda: peer.matched("xyz_target", "pub") > 0 and peer.matched("servo_state", "sub") > 0,
                         HANDSHAKES_S), f"the operator matched nothing\n{logs()}"
        sent, answered = drive(peer, TARGET, timeout=60)
        assert answered, f"no servo_state answered a target through the router\n{logs()}"
        expected = servo_deg(*TARGET)
        r.state = wait_at(peer, "servo_state", expected)
        assert max(abs(math.degrees(a) - e) for a, e in zip(r.state.position[:3], expected)) < 0.1, \
            (list(r.state.position), expected)

        # the outsiders listen while the operator goes on sending targets
        outsiders = [outsider(hosts, site, domain, 10) for site in ("pc", "pi")]
        n = 0
        while any(o.poll() is None for o in outsiders):
            n += 1
            payload, _ = point_target(*(OTHER_TARGET if n % 2 else TARGET))
            peer.publish("xyz_target", payload)
            peer.wait(lambda: False, 0.25)
        r.seen = dict(zip(("pc", "pi"), (o.result() for o in outsiders)))
        r.second = second.result()
        assert len(peer.received("servo_state")) > len(sent), "the targets of the outsiders' window got no answer"
    finally:
        r.pcaps = {leg: c.stop() for leg, c in captures.items()}
        for o in [*outsiders, *([second] if second else [])]:
            if o.poll() is None:
                o.kill()
                o.wait(10)
        if peer is not None:
            codes["operator"] = peer.close()
        for p in procs:
            codes[p.name] = p.stop()
        if arduino is not None:
            arduino.stop()
        hosts.close()
    assert all(c == 0 for c in codes.values()), f"exit codes {codes}"
    assert hosts.router_code == 0, f"the router exited with {hosts.router_code}"
    r.peer, r.logs = peer, [p.log_path.read_text() for p in procs]
    return r


def in_clear(r, what):
    """{leg: {marker kind: how many of them the leg's capture holds in clear}} for run
    `r`: the targets, servo_angles and servo_state samples its operator sent and
    received, the joints' names, the URDF's robot name; each leg's capture checked to
    hold its traffic (DDS on the LANs, RTPS-protected only when secured; TLS on the WAN
    only when secured)."""
    secured = what == "secured"
    targets = [target_pattern(p) for t, p in r.peer.published if t == "xyz_target"]
    angles = [p[4:] for _, p in r.peer.received("servo_angles")]
    states = [p[4:] for _, p in r.peer.received("servo_state")]
    names = [n.encode() for n in r.state.name]
    markers = {"targets": targets, "servo_angles": angles, "servo_state": states, "joint names": names,
               "URDF": [robot_name()]}
    found = {}
    for leg, pcap in r.pcaps.items():
        wire, rtps, protected, streams = leg_bytes(pcap)
        found[leg] = {k: sum(1 for m in ms if (m.search(wire) if isinstance(m, re.Pattern) else m in wire))
                      for k, ms in markers.items()}
        tls = [s for s in streams.values() if s.startswith(b"\x16\x03")]
        print(f"{what}: {leg}: {len(pcap)} bytes captured, {rtps} RTPS datagrams ({protected} RTPS-protected), "
              f"{len(streams)} TCP streams ({len(tls)} TLS); in clear: {found[leg]} of "
              f"{({k: len(v) for k, v in markers.items()})}")
        # the capture saw the leg's traffic: DDS on the LANs, the bridges' connections on the WAN
        if leg == "wan":
            assert sum(len(s) for s in streams.values()) > 10_000, f"{what}, {leg}: almost no TCP captured"
            assert (len(tls) == len(streams)) == secured, f"{what}, {leg}: {len(tls)} of {len(streams)} streams are TLS"
        else:
            assert rtps > 20, f"{what}, {leg}: almost no RTPS captured"
            assert (protected > 0) == secured, f"{what}, {leg}: {protected} RTPS-protected datagrams"
    return found


def outsiders_saw(r, what):
    """{site: (samples per topic, contract topics of others it discovered)}."""
    out = {}
    for site, seen in r.seen.items():
        others = set(seen["topics"]) - set(OUTSIDER_TOPICS)
        out[site] = ({t: v["count"] for t, v in seen["got"].items()}, sorted(others & CONTRACT))
        print(f"{what}: outsider at {site}: samples {out[site][0]}, contract topics of others {out[site][1]}")
    return out


@needs_hosts
def test_both_sites_secured_a_target_crosses_and_neither_outsiders_nor_captures_see_it(domain, tmp_path, keystore,
                                                                                       certs):
    """Secured (SROS2 on both LANs under Enforce, mutual TLS to the router): a target from
    the operator in `pc` -> compute_ik -> the pc bridge (enclave /eezybot/bridge_pc) ->
    the router -> the pi bridge (/eezybot/bridge_pi) -> serial_node -> the virtual
    Arduino, and servo_state back to the operator at ROBOT.md's servo angles. An
    unsecured rclpy outsider on each LAN gets no sample and sees none of the contract's
    topics; a capture of every interface of `pc`, of `wan` and of `pi` holds none of the
    targets, servo_angles and servo_state samples the operator sent and received, nor a
    joint's name or the URDF, only ciphertext (RTPS-protected on the LANs, TLS on the
    WAN). A second operator PC gets robot_description, a sample larger than a datagram,
    from state_publisher through the pc bridge's secured participant. The control, the
    same run with neither SROS2 nor TLS: the outsiders get the data, and each leg's
    capture holds what crosses it."""
    secured = run_graph(True, domain, tmp_path / "secured", keystore, certs)
    assert "SROS2 on: enclave /eezybot/bridge_pc" in secured.logs[0], secured.logs[0][-3000:]
    assert "SROS2 on: enclave /eezybot/bridge_pi" in secured.logs[1], secured.logs[1][-3000:]
    # each bridge's own diagnostics writer (a second participant, same enclave) is allowed
    for log in secured.logs[:2]:
        assert "no diagnostics on" not in log and "diagnostics not written" not in log, log[-3000:]
    for site, (counts, topics) in outsiders_saw(secured, "secured").items():
        assert not any(counts.values()), f"an unsecured peer at {site} got samples: {counts}"
        assert not topics, f"an unsecured peer at {site} sees {topics}"
    found = in_clear(secured, "secured")
    assert not any(any(f.values()) for f in found.values()), f"in clear on the wire: {found}"
    assert secured.second["got"]["/robot_description"]["first"] == urdf_summary(), \
        f"the second PC's robot_description: {secured.second}"

    plain = run_graph(False, domain, tmp_path / "plain", keystore, certs)
    saw = outsiders_saw(plain, "plain")
    assert saw["pc"][0]["/servo_state"] and saw["pi"][0]["/servo_angles"] and saw["pc"][1], saw
    found = in_clear(plain, "plain")
    # each leg carries what crosses it: the angles go out to the Pi and the states come
    # back over every leg; the targets and the URDF stay on the PC's LAN
    for leg in ("pc", "wan", "pi"):
        assert found[leg]["servo_angles"] and found[leg]["servo_state"] and found[leg]["joint names"], (leg, found[leg])
    assert found["pc"]["targets"] and found["pc"]["URDF"] and found["wan"]["URDF"], found
    assert not found["pi"]["targets"] and not found["wan"]["targets"], found
    assert plain.second["got"]["/robot_description"]["first"] == urdf_summary(), plain.second


def print_config(side, *args, env=None):
    """`eezybot_wan_bridge SIDE --router tcp/127.0.0.1:7447 ARGS... --print-config`:
    (exit status, the configuration's JSON or None, stderr)."""
    r = subprocess.run([str(wanhost.wan_bin_dir() / BRIDGE), side, "--router", "tcp/127.0.0.1:7447", *args,
                        "--print-config"], capture_output=True, text=True, timeout=60,
                       env={**os.environ, **NO_SECURITY, **(env or {})})
    return r.returncode, json.loads(r.stdout) if r.returncode == 0 else None, r.stderr


def grant(permissions_xml):
    """{publish: set, subscribe: set} of a permissions document's grant."""
    import xml.etree.ElementTree as ET

    rule = ET.parse(permissions_xml).getroot().find("permissions/grant/allow_rule")
    return {kind: {t.text for t in rule.findall(f"{kind}/topics/topic")} for kind in ("publish", "subscribe")}


@pytest.mark.parametrize("namespace", ["/", "/arm2"])
def test_the_bridges_enclaves_grant_exactly_what_the_bridges_carry(namespace, keystore):
    """Each bridge enclave keystore.sh makes may subscribe to exactly the topics its
    bridge sends out (the plugin's allow-list of local publishers, as the bridge itself
    prints its configuration), publish exactly those it brings in (local subscribers)
    and its own diagnostics, and use ros_discovery_info: nothing else. In a namespace too (`--namespace /arm2`,
    the nodes' `-r __ns:=/arm2`)."""
    for side in ("pc", "pi"):
        name = f"/eezybot/bridge_{side}"
        if namespace != "/":
            name = f"{namespace}/bridge_{side}"
            _run([KEYSTORE_SH, keystore.root, "--enclave", name, "--role", f"bridge_{side}", "--namespace", namespace],
                 env={**os.environ, "EEZYBOT_BIN_DIR": str(Path(bin_path("eezybot_sros2")).parent)})
        code, config, err = print_config(side, "--namespace", namespace)
        assert code == 0, err
        allow = config["plugins"]["ros2dds"]["allow"]
        ns = namespace.rstrip("/")
        # and its own diagnostics on its LAN (wan/src/health.rs), on either side
        want = {"subscribe": {f"rt{t}" for t in allow["publishers"]} | {"ros_discovery_info"},
                "publish": {f"rt{t}" for t in allow["subscribers"]} | {"ros_discovery_info", f"rt{ns}/diagnostics"}}
        assert allow["publishers"] and allow["subscribers"], allow
        assert grant(keystore.enclave(name) / "permissions.xml") == want, (side, namespace)


def test_an_enclave_cyclone_refuses_stops_the_bridge_under_enforce_and_warns_under_permissive(keystore):
    """The bridge checks its enclave with Cyclone DDS before the plugin starts (a
    participant that sends nothing): its own enclave is taken; one whose certificate has
    expired stops it with status 2 under Enforce, naming the enclave and Cyclone's
    reason, and under Permissive it warns and runs unsecured; a missing enclave is named
    with the command that makes it."""
    ks = security_env(keystore)
    expired = keystore.with_expired_certificate("/eezybot/bridge_pi", "/eezybot/bridge_expired")
    code, _, err = print_config("pi", env=ks)
    assert code == 0 and "SROS2 on: enclave /eezybot/bridge_pi" in err, err
    code, _, err = print_config("pi", "--enclave", "/eezybot/bridge_expired", env=ks)
    assert code == 2, err
    assert "enclave /eezybot/bridge_expired" in err and "Cyclone DDS refused it" in err, err
    assert "expired" in err.lower() and "not starting unsecured" in err, err
    code, _, err = print_config("pi", "--enclave", "/eezybot/bridge_expired", env={**ks, "ROS_SECURITY_STRATEGY": ""})
    assert code == 0 and "WARNING" in err and "runs unsecured" in err, err
    code, _, err = print_config("pc", "--enclave", "/eezybot/nowhere", env=ks)
    assert code == 2 and f"keystore.sh {keystore.root} --enclave /eezybot/nowhere" in err, err
    assert expired.is_dir()


def test_the_scripts_take_security_and_the_wan_together_and_check_the_bridges_enclave(keystore, tmp_path, domain):
    """pc.sh and pi.sh with ROS_SECURITY_ENABLE=true and ZENOH_ROUTER both set check the
    bridge's enclave with the nodes' before anything starts: under Enforce, a keystore
    without it ends the script with status 2, naming the enclave and the command that
    makes it."""
    old = tmp_path / "keystore"
    subprocess.run(["cp", "-a", str(keystore.root), str(old)], check=True)
    for side in ("pc", "pi"):
        subprocess.run(["rm", "-rf", str(old / "enclaves" / "eezybot" / f"bridge_{side}")], check=True)
    for script, side in (("pc.sh", "pc"), ("pi.sh", "pi")):
        env = {**bins(), **security_env(old), "SERIAL_PORT": "mock",
               "ZENOH_ROUTER": f"tls/{wanhost.ROUTER}:{wanhost.PORT}", "ZENOH_TLS_DIR": str(tmp_path)}
        p = NodeProcess(str(REPO / "launch_scripts" / script), [], domain, env=env)
        try:
            code = p.proc.wait(60)
        finally:
            p.stop()
        out = p.log_path.read_text()
        assert code == 2, f"{script}: exit {code}\n{out}"
        assert f"no enclave /eezybot/bridge_{side} in the keystore" in out and "--enclave /eezybot/bridge_" in out, out
        assert "running here" not in out and "do not go together" not in out, out
