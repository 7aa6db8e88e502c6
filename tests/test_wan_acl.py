"""Least privilege at the WAN router (issue 36, item 2): each client certificate has a
role (its common name, `pc` or `pi`: launch_scripts/wan_certs.sh), and the router lets
each role send only its own side's directions of CROSSING (wan/src/acl.rs). A bare Zenoh
client holding the Pi's certificate (wan/examples/acl_probe.rs: what a certificate
copied off a Pi's SD card allows) publishes `servo_angles`: nothing reaches the Pi's
LAN, the arm does not move, and the router says what it refused. The same client under
the PC's certificate gets through (the control).

Namespaces `pi`, `stranger` and `wan` (wanhost.py): launch_scripts/pi.sh (serial_node
on the mock device, and the Pi's bridge) in `pi`, the router in `wan`, the probe in
`stranger`; an rclpy observer on the Pi's LAN. Judged by order: the rogue publishes
throughout the control's run, so a rogue sample that passed would be among the
control's."""
import os
import subprocess

import pytest
from sensor_msgs.msg import JointState

import wanhost
from conftest import REPO, NodeProcess, Observer, bin_path

pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=60),
              pytest.mark.skipif(wanhost.available() is not None, reason=f"WAN hosts: {wanhost.available()}")]

SERVOS = ["base_servo", "shoulder_servo", "elbow_servo", "gripper_servo"]


class Probe:
    """acl_probe at `site` under certificate `cert`, publishing `positions` on servo_angles."""

    def __init__(self, hosts, site, certs, cert, positions, log_path):
        exe = wanhost.wan_bin_dir() / "examples" / "acl_probe"
        args = ["--router", f"tls/{wanhost.ROUTER}:{wanhost.PORT}", "--tls-dir", str(certs), "--cert", cert,
                "--rate", "20"]
        for name, p in zip(SERVOS, positions):
            args += ["--name", name, "--position", repr(p)]
        self.log_path = log_path
        self.log = open(log_path, "w")
        self.proc = hosts.popen(site, [str(exe), *args], stdout=self.log, stderr=subprocess.STDOUT)

    def output(self):
        if not self.log.closed:
            self.log.flush()
        return self.log_path.read_text()

    def zid(self):
        lines = [line for line in self.output().splitlines() if line.startswith("connected as ")]
        return lines[0].split()[-1] if lines else None

    def sent(self):
        counts = [int(line.split()[1]) for line in self.output().splitlines() if line.startswith("sent ")]
        return counts[-1] if counts else 0

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(20)
        self.log.close()
        return self.proc.returncode


def close_to(a, b, tol=1e-3):
    return len(a) == len(b) and all(abs(x - y) < tol for x, y in zip(a, b))


def test_a_pi_certificate_cannot_publish_servo_angles_and_a_pc_certificate_can(domain, tmp_path):
    certs = wanhost.make_certs(tmp_path / "certs")
    hosts = wanhost.WanHosts(tag="a", sites=("pi", "stranger"))
    procs, probes, o = [], [], None
    try:
        router_log = tmp_path / "router.log"
        hosts.start_router(certs, router_log)
        env = {**hosts.graph_env(certs), "EEZYBOT_BIN_DIR": str(os.path.dirname(bin_path("serial_node"))),
               "SERIAL_PORT": "mock"}
        pi = NodeProcess(str(REPO / "launch_scripts" / "pi.sh"), [], domain, env=env, netns=hosts.pi)
        procs.append(pi)
        o = Observer(domain, name="pi_lan", netns=hosts.pi)
        angles = o.sub("/servo_angles", JointState)
        states = o.sub("/servo_state", JointState)
        assert o.spin_until(lambda: len(states) >= 3 and "connected to the router" in pi.output(), 60), \
            f"the Pi did not come up: {len(states)} servo_state\n{pi.output()[-3000:]}"
        rest = list(states[-1][1].position)
        assert len(rest) == 4, rest
        # within the servos' range, away from where they are: either would move the arm
        rogue_pos = [r + 0.15 if r < 1.5 else r - 0.15 for r in rest]
        control_pos = [r - 0.1 if r >= 1.5 else r + 0.3 for r in rest]
        legit_refusals = [line for line in router_log.read_text().splitlines() if "refused:" in line]

        # the rogue: a Pi's certificate publishing servo_angles, 20 Hz from now to the end
        rogue = Probe(hosts, "stranger", certs, "pi", rogue_pos, tmp_path / "rogue.log")
        probes.append(rogue)
        assert o.spin_until(lambda: rogue.sent() >= 20, 40), f"the rogue did not publish\n{rogue.output()}"

        # the control: the same client under the PC's certificate
        control = Probe(hosts, "stranger", certs, "pc", control_pos, tmp_path / "control.log")
        probes.append(control)

        def control_samples():
            return [m for _, m in angles if close_to(list(m.position), control_pos)]

        assert o.spin_until(lambda: len(control_samples()) >= 20
                            and close_to(list(states[-1][1].position), control_pos, 1e-2), 60), \
            (f"the control did not get through: {len(control_samples())} samples, servo_state "
             f"{list(states[-1][1].position)} (wanted {control_pos})\n{control.output()[-1000:]}\n{pi.output()[-2000:]}")
        rogue_during = rogue.sent()
        n_control = len(control_samples())
        # the rogue goes on publishing while 20 more control samples arrive
        assert o.spin_until(lambda: len(control_samples()) >= n_control + 20 and rogue.sent() >= rogue_during + 20, 30)
        assert rogue.proc.poll() is None, rogue.output()
    finally:
        codes = [p.stop() for p in probes]
        if o is not None:
            o.close()
        codes += [p.stop() for p in procs]
        hosts.close()
    through = [list(m.position) for _, m in angles if close_to(list(m.position), rogue_pos)]
    assert not through, f"{len(through)} of the rogue's servo_angles reached the Pi's LAN"
    moved = [list(m.position) for _, m in states if close_to(list(m.position), rogue_pos, 1e-2)]
    assert not moved, f"the arm went where the rogue said: {moved[:3]}"
    assert all(list(m.position) == control_pos or close_to(list(m.position), control_pos) for _, m in angles), \
        "servo_angles on the Pi's LAN other than the control's"
    log = router_log.read_text()
    refusal = f"refused: pi (client {rogue.zid()}) may not publish servo_angles"
    # the Pi's own bridge was refused nothing, nor was the control; the rogue's refusal
    # was said once, then counted
    assert not legit_refusals, legit_refusals
    said = [line for line in log.splitlines() if refusal in line]
    assert said and "(Put ingress;" in said[0] and all("more times" in line for line in said[1:]), said
    assert not [line for line in log.splitlines() if "refused:" in line and control.zid() in line], log[-3000:]
    assert codes == [0, 0, 0] and hosts.router_code == 0, (codes, hosts.router_code)
