"""Outages of the Pi's WAN link in the WAN mode (issue 20): launch_scripts/pc.sh in `pc`,
pi.sh in `pi` (serial_node driving the firmware in simavr), each with its bridge, the router in
`wan` (wanhost.py), an rclpy operator in `pc` sending targets at 20 Hz all the time; one
graph lives through every trial. Each trial takes the Pi's interface down for 3, 12, 25
or 60 s (Zenoh's lease is 10 s: the longer ones end the bridge's session, which it
opens again by itself) and brings it back. The Pi's interface is its LAN too, as a
Pi's Wi-Fi is: serial_node and its bridge then talk over the host only.

Mostly waiting, so this module runs in the background beside the other tests (conftest:
`background`); tests/soak/outages.py --mode wan runs 20 trials of each length (BENCHMARKS.md)."""
import time

import pytest

import wanhost
from split_graph import SplitGraph, hold_across_the_outage

pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=140),
              pytest.mark.skipif(wanhost.available() is not None, reason=f"WAN hosts: {wanhost.available()}")]


@pytest.fixture(scope="module")
def wan_graph(tmp_path_factory):
    from conftest import DomainLease

    lease = DomainLease()
    work = tmp_path_factory.mktemp("wan-outages")
    certs = wanhost.make_certs(work / "certs")
    hosts = wanhost.WanHosts(tag="x")
    try:
        hosts.start_router(certs, work / "router.log")
        g = SplitGraph(hosts, lease.id, work, device="simavr", env=hosts.graph_env(certs))
    except BaseException:
        hosts.close()
        lease.release()
        raise
    yield g
    try:
        codes = g.close()
        assert all(c == 0 for c in codes.values()), f"exit codes {codes}"
    finally:
        hosts.close()
        lease.release()
    assert hosts.router_code == 0, f"the router exited with {hosts.router_code}"


@pytest.mark.parametrize("length", [3, 12, 25, 60], ids=["pi-3", "pi-12", "pi-25", "pi-60"])
def test_the_graph_resumes_after_an_outage_of_the_pis_wan_link(wan_graph, length):
    """The Pi's WAN link down for `length` s while the operator keeps sending: the arm
    holds still (judged at the firmware's pins, in simulated time, from the last command
    the board got before the heal: targets already on the Pi's side when the link went
    down may still reach it), and after the link returns the newest target is applied and
    no command from the outage is (no stale burst)."""
    from safety_rig import BoardEvents

    r = wan_graph.outage(length, "pi")
    print(f"\nWAN outage {length} s at the Pi: resumed after {r['resume_s']} s, stale {r['stale']}")
    assert r["resumed"], f"no servo_state for a new target after the link returned: {r}\n{wan_graph.logs_tail()}"
    assert r["settled"], f"no servo_state for a second new target after the first: {r}\n{wan_graph.logs_tail()}"
    assert r["stale"] == 0, f"commands from the outage applied after it: {r}"
    assert r["out_of_order"] == 0, r
    ev = BoardEvents(wan_graph.uno.events_path)
    assert hold_across_the_outage(ev, int(r["t_restore"] * 1e9)) == []


def test_an_estop_pressed_during_an_outage_holds_the_pi_when_it_returns(wan_graph):
    """The e-stop pressed on the PC while the Pi's WAN link is down for longer than
    Zenoh's lease: when the link returns, the Pi's bridge (a new session) gets the
    current e-stop from the PC's bridge, and serial_node holds; the release moves again."""
    from std_msgs.msg import Bool

    g = wan_graph
    g.wait_flowing()
    estop = g.o.pub("/estop", Bool)  # the contract's QoS: latched
    g.hosts.cut("pi")
    g.pump(2)
    estop.publish(Bool(data=True))
    g.pump(13)
    g.diags.clear()
    g.hosts.restore("pi")
    try:
        assert g.pump_until(lambda: g.diag_values("serial_node")[2].get("estop") == "true", 20), \
            f"the Pi did not get the e-stop pressed during the outage: {g.diag_values('serial_node')}\n{g.logs_tail()}"
        # 20 targets while it holds: none is applied, then or after the release (judged
        # once the release's first answer is in: a held-back target would come before it)
        n_sent = len(g.sent)
        assert g.pump_until(lambda: len(g.sent) >= n_sent + 20, 30), "the operator sent no targets"
        during = {s for _, s in g.sent[n_sent:]}
    finally:
        estop.publish(Bool(data=False))
    t_release = time.time()
    assert g.pump_until(lambda: g.answers_after(t_release), 20), \
        f"no motion after the release\n{g.logs_tail()}"
    assert not [s for _, s in g.replies_after(0) if s in during], "a target sent during the e-stop was applied"
