"""Link outages between the two hosts of test_two_hosts.py (launch_scripts/pc.sh in a
network namespace `pc`, launch_scripts/pi.sh in `pi` with the virtual Arduino behind a
pty, an rclpy operator in `pc` sending targets at 20 Hz): one graph lives through every
trial, as in a long teleoperation session.

The trials are mostly waiting for the link to come back, so this module runs in the
background alongside the other tests (conftest: `background`); tests/soak/outages.py
runs 20 trials of each length at each end (results in BENCHMARKS.md)."""
import re
from collections import Counter

import pytest

import twohost
from split_graph import SplitGraph

pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=120),
              pytest.mark.skipif(twohost.available() is not None, reason=f"two hosts: {twohost.available()}")]


@pytest.fixture(scope="module")
def split_graph(tmp_path_factory):
    """One graph for every outage trial (pc.sh + pi.sh with the virtual Arduino behind a
    pty), in a domain and namespaces of its own."""
    from conftest import DomainLease

    lease = DomainLease()
    hosts = twohost.TwoHosts(tag="o")
    g = SplitGraph(hosts, lease.id, tmp_path_factory.mktemp("outages"), device="virtual")
    yield g
    try:
        codes = g.close()
        assert all(c == 0 for c in codes.values()), f"exit codes {codes}"
    finally:
        hosts.close()
        lease.release()


LEASE_S = 5  # our participants' lease (1 s announcements): longer outages lose peers

# RustDDS's (patched) warning when a send fails, once per sender and destination until a
# send there works again or the error changes: the node, the destination, the error
SEND_FAILED = re.compile(r"\[(\w+):rustdds::network::udp_sender\]: raw_send: .* to (\S+?):\d+ : Os \{ code: (\d+)")


def unreachable_lines(graph):
    """Every log line about an unreachable network so far, per launch script."""
    return {p.name: [line for line in p.log_path.read_text().splitlines() if re.search("unreachable", line, re.I)]
            for p in graph.procs}


# One trial per outage length, the cut end alternating (the Pi's end for 3 and 25 s,
# the PC's for 12 and 60 s; test_security.py cuts the Pi's end for 25 s, secured, and
# test_two_hosts.py's partition test for 5 s). tests/soak/outages.py runs every length
# at both ends, 20 trials each.
@pytest.mark.parametrize("length,side", [(3, "pi"), (12, "pc"), (25, "pi"), (60, "pc")],
                         ids=["pi-3", "pc-12", "pi-25", "pc-60"])
def test_the_graph_resumes_after_a_link_outage(split_graph, length, side):
    """Pull the cable at one end for `length` s while the operator keeps sending, plug it
    back (multicast route re-added, as a DHCP client does): the newest target is
    applied, no stale command from the outage is, peers lost for longer than the lease
    are reported lost and regained, and an unreachable network is logged once."""
    before = unreachable_lines(split_graph)
    r = split_graph.outage(length, side)
    logged = {script: lines[len(before.get(script, [])):] for script, lines in unreachable_lines(split_graph).items()}
    print(f"\noutage {length} s at {side}: resumed after {r['resume_s']} s, stale {r['stale']}, "
          f"lost/regained {r['serial_angles_lost']}/{r['serial_angles_regained']}, "
          f"unreachable log lines {r['unreachable_lines']}")
    assert r["resumed"], f"no servo_state for a new target after the link returned: {r}\n{split_graph.logs_tail()}"
    assert r["settled"], f"no servo_state for a second new target after the first: {r}\n{split_graph.logs_tail()}"
    assert r["stale"] == 0, f"commands from the outage applied after it: {r}"
    assert r["out_of_order"] == 0, r
    if length > LEASE_S + 2:
        assert r["serial_angles_lost"] >= 1 and r["serial_angles_regained"] >= 1, \
            f"serial_node did not report its servo_angles publisher lost and regained: {r}"
        assert r["ik_angles_lost"] >= 1 and r["ik_angles_regained"] >= 1, \
            f"compute_ik did not report its servo_angles subscriber lost and regained: {r}"
    # the end whose cable was pulled says so: one WARN per node, failing destination and
    # error, not ~20/s (and the other end, which kept its link, at most the same)
    assert logged[f"{side}.sh"], f"nothing logged about the unreachable network at {side}: {logged}"
    for script, lines in logged.items():
        keys = Counter(m.groups() if (m := SEND_FAILED.search(line)) else line for line in lines)
        assert all(n == 1 for n in keys.values()), f"{script} logged the same failure more than once: {keys}"
