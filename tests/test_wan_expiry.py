"""Certificates that expire are seen before they do, in the WAN mode (issue 36, item 5):
each bridge puts its certificate's end in its own `diagnostics` (the nodes' keys
`certificate_expires`, `certificate_days_left`; a warning within 30 days naming the
file), and the router says its own at start, with a WARNING within 30 days.

Namespaces `pc`, `wan` and `pi` (wanhost.py): the router in `wan` with a certificate
that ends in 20 days, the PC's bridge with one that ends in 10 days (same CA, role pc),
the Pi's with the usual 825 days; an rclpy observer on the PC's LAN reads both bridges'
statuses (the Pi's crosses the router, as serial_node's does)."""
import datetime
import shutil
import subprocess

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

import wanhost
from conftest import NodeProcess, Observer, latest_status, status_values

pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=40),
              pytest.mark.skipif(wanhost.available() is not None, reason=f"WAN hosts: {wanhost.available()}")]


def issue(certs, name, cn, days, ext):
    """NAME.pem for the key KEY.pem of an existing party (cn's), from the CA of `certs`,
    valid from now for `days` days; returns its notAfter as a UTC date."""
    key = certs / f"{cn if cn != 'eezybot-wan-router' else 'router'}.key"
    ext_file = certs / f"{name}.ext"
    ext_file.write_text(ext)
    csr = subprocess.run(["openssl", "req", "-new", "-key", str(key), "-subj", f"/CN={cn}"],
                         capture_output=True, check=True).stdout
    subprocess.run(["openssl", "x509", "-req", "-CA", str(certs / "ca.pem"), "-CAkey", str(certs / "private" / "ca.key"),
                    "-days", str(days), "-extfile", str(ext_file), "-out", str(certs / f"{name}.pem")],
                   input=csr, capture_output=True, check=True)
    if name != "router":
        shutil.copy(key, certs / f"{name}.key")
    end = subprocess.run(["openssl", "x509", "-in", str(certs / f"{name}.pem"), "-noout", "-enddate", "-dateopt", "iso_8601"],
                         capture_output=True, text=True, check=True).stdout
    return end.split("=", 1)[1][:10]


def test_bridges_report_their_certificates_end_and_the_router_warns_of_its_own(domain, tmp_path):
    certs = wanhost.make_certs(tmp_path / "certs")
    leaf = "basicConstraints = critical, CA:FALSE\nkeyUsage = critical, digitalSignature\n"
    router_end = issue(certs, "router", "eezybot-wan-router", 20,
                       leaf + f"extendedKeyUsage = serverAuth\nsubjectAltName = IP:{wanhost.ROUTER}\n")
    pc_end = issue(certs, "pc-short", "pc", 10, leaf + "extendedKeyUsage = clientAuth\n")
    pi_end = subprocess.run(["openssl", "x509", "-in", str(certs / "pi.pem"), "-noout", "-enddate", "-dateopt", "iso_8601"],
                            capture_output=True, text=True, check=True).stdout.split("=", 1)[1][:10]
    today = datetime.datetime.now(datetime.timezone.utc).date()
    hosts = wanhost.WanHosts(tag="e", sites=("pc", "pi"))
    bridges, o = [], None
    try:
        router_log = tmp_path / "router.log"
        hosts.start_router(certs, router_log)
        env = hosts.graph_env(certs)
        exe = str(wanhost.wan_bin_dir() / "eezybot_wan_bridge")
        bridges = [NodeProcess(exe, ["pc", "--cert", "pc-short"], domain, env=env, netns=hosts.pc),
                   NodeProcess(exe, ["pi"], domain, env=env, netns=hosts.pi)]
        o = Observer(domain, name="pc_lan", netns=hosts.pc)
        diags = o.sub("/diagnostics", DiagnosticArray)

        def both():
            return all(latest_status(diags, f"eezybot_wan_bridge_{s}: WAN link") is not None
                       and status_values(latest_status(diags, f"eezybot_wan_bridge_{s}: WAN link")).get("connected") == "true"
                       for s in ("pc", "pi"))

        assert o.spin_until(both, 60), \
            (f"no WAN link status of both bridges on the PC's LAN: {[s.name for _, a in diags for s in a.status]}\n"
             + "\n".join(b.output()[-1500:] for b in bridges))
        pc = latest_status(diags, "eezybot_wan_bridge_pc: WAN link")
        pi = latest_status(diags, "eezybot_wan_bridge_pi: WAN link")
        pcv, piv = status_values(pc), status_values(pi)
    finally:
        if o is not None:
            o.close()
        codes = [b.stop() for b in bridges]
        hosts.close()
    # the PC's: 10 days (9 once a second has passed), a warning naming the file
    assert pcv["certificate_expires"] == pc_end and pcv["certificate_days_left"] in ("9", "10"), pcv
    assert pcv["certificate"].endswith("pc-short.pem"), pcv
    assert pc.level == DiagnosticStatus.WARN and f"pc-short.pem expires on {pc_end}" in pc.message, (pc.level, pc.message)
    # the Pi's: far off, OK; its days as the date says
    assert piv["certificate_expires"] == pi_end, piv
    days = (datetime.date.fromisoformat(pi_end) - today).days
    assert int(piv["certificate_days_left"]) in (days - 1, days), (piv, days)
    assert pi.level == DiagnosticStatus.OK and pi.message.startswith("connected to the router"), (pi.level, pi.message)
    # the router's, at start
    log = router_log.read_text()
    assert f"WARNING: {certs / 'router.pem'} expires on {router_end} (" in log, log[-2000:]
    assert codes == [0, 0] and hosts.router_code == 0, (codes, hosts.router_code)

