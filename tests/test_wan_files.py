"""The WAN mode's certificates and the router's start (issue 20, item 2), without a
graph: launch_scripts/wan_certs.sh makes a CA, a router certificate valid for each HOST
and client certificates that `openssl` itself accepts for mutual TLS; router.sh refuses
an unusable file, endpoint or port with one line and exit status 2; a bridge dialling a
HOST that is not in the router's certificate is not let in (tls tests across namespaces:
test_wan.py)."""
import os
import sys
import subprocess
import time

import pytest

import wanhost
from conftest import REPO

CERTS_SH = REPO / "launch_scripts" / "wan_certs.sh"
ROUTER_SH = REPO / "launch_scripts" / "router.sh"


def openssl(*args):
    return subprocess.run(["openssl", *args], capture_output=True, text=True, timeout=30)


@pytest.fixture
def lo_ns():
    """A network namespace with only its loopback: what runs in it stays on this host."""
    name = f"ezbf{os.getpid() % 100000}"
    subprocess.run(["ip", "netns", "del", name], capture_output=True)
    subprocess.run(["ip", "netns", "add", name], check=True)
    subprocess.run(["ip", "-n", name, "link", "set", "lo", "up"], check=True)
    yield ["ip", "netns", "exec", name]
    subprocess.run(["ip", "netns", "del", name], capture_output=True)


def router(ns, env, timeout=30):
    """router.sh in `ns` with `env` (and the WAN binaries); (exit status, output) once it exits."""
    env = {**os.environ, "EEZYBOT_WAN_BIN_DIR": str(wanhost.wan_bin_dir()), **env}
    r = subprocess.run([*ns, str(ROUTER_SH)], capture_output=True, text=True, env=env, timeout=timeout)
    return r.returncode, r.stdout + r.stderr


def test_wan_certs_makes_a_ca_a_router_for_each_host_and_clients(tmp_path):
    d = tmp_path / "certs"
    r = subprocess.run([str(CERTS_SH), str(d), "10.1.2.3", "vps.example.org", "--client", "pc2"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    for name in ("router", "pc", "pi", "pc2"):
        assert (d / f"{name}.key").stat().st_mode & 0o777 == 0o600, name
        v = openssl("verify", "-CAfile", str(d / "ca.pem"), str(d / f"{name}.pem"))
        assert v.returncode == 0, v.stdout + v.stderr
        # each key is its certificate's
        pub_cert = openssl("x509", "-in", str(d / f"{name}.pem"), "-noout", "-pubkey").stdout
        pub_key = openssl("pkey", "-in", str(d / f"{name}.key"), "-pubout").stdout
        assert pub_cert and pub_cert == pub_key, name
    text = openssl("x509", "-in", str(d / "router.pem"), "-noout", "-ext", "subjectAltName,extendedKeyUsage").stdout
    assert "IP Address:10.1.2.3" in text and "DNS:vps.example.org" in text and "TLS Web Server Authentication" in text, text
    text = openssl("x509", "-in", str(d / "pc.pem"), "-noout", "-ext", "extendedKeyUsage").stdout
    assert "TLS Web Client Authentication" in text, text
    assert (d / "private").stat().st_mode & 0o777 == 0o700
    # each client's common name is its role (the router's access control matches it):
    # pc2 is a second PC
    for name, role in (("pc", "pc"), ("pi", "pi"), ("pc2", "pc")):
        subject = openssl("x509", "-in", str(d / f"{name}.pem"), "-noout", "-subject", "-nameopt", "RFC2253").stdout
        assert subject.strip() == f"subject=CN={role}", (name, subject)
    # a client certificate made before roles (CN=pc2) is issued again, with its key
    old = subprocess.run(["openssl", "req", "-new", "-key", str(d / "pc2.key"), "-subj", "/CN=pc2"],
                         capture_output=True, check=True).stdout
    subprocess.run(["openssl", "x509", "-req", "-CA", str(d / "ca.pem"), "-CAkey", str(d / "private" / "ca.key"),
                    "-days", "30", "-out", str(d / "pc2.pem")], input=old, capture_output=True, check=True)
    key_before = (d / "pc2.key").read_bytes()
    r = subprocess.run([str(CERTS_SH), str(d), "10.1.2.3", "vps.example.org", "--client", "pc2"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "made pc2.pem" in r.stderr + r.stdout, r.stderr
    subject = openssl("x509", "-in", str(d / "pc2.pem"), "-noout", "-subject", "-nameopt", "RFC2253").stdout
    assert subject.strip() == "subject=CN=pc" and (d / "pc2.key").read_bytes() == key_before, subject
    # again with the same hosts: nothing made anew; another host list: the router only
    before = {f: (d / f).read_bytes() for f in ("ca.pem", "router.pem", "pc.pem")}
    assert subprocess.run([str(CERTS_SH), str(d), "10.1.2.3", "vps.example.org"], capture_output=True,
                          timeout=120).returncode == 0
    assert {f: (d / f).read_bytes() for f in before} == before
    assert subprocess.run([str(CERTS_SH), str(d), "10.1.2.4"], capture_output=True, timeout=120).returncode == 0
    assert (d / "ca.pem").read_bytes() == before["ca.pem"] and (d / "pc.pem").read_bytes() == before["pc.pem"]
    text = openssl("x509", "-in", str(d / "router.pem"), "-noout", "-ext", "subjectAltName").stdout
    assert "10.1.2.4" in text and "10.1.2.3" not in text, text


@pytest.mark.parametrize("args", [[], ["DIR"], ["DIR", "bad host!"], ["DIR", "h", "--client", "router"],
                                  ["DIR", "h", "--client", "pickle"]],
                         ids=["nothing", "no-host", "bad-host", "client-named-router", "client-without-a-role"])
def test_wan_certs_usage_errors_exit_2(args, tmp_path):
    args = [str(tmp_path / "d") if a == "DIR" else a for a in args]
    r = subprocess.run([str(CERTS_SH), *args], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "usage: wan_certs.sh" in r.stderr, r.stderr


@pytest.mark.skipif(wanhost.available() is not None, reason=f"namespaces: {wanhost.available()}")
def test_router_refuses_unusable_files_endpoints_and_ports_with_status_2(tmp_path, lo_ns):
    certs = wanhost.make_certs(tmp_path / "certs")
    other = wanhost.make_certs(tmp_path / "other")
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    for f in ("ca.pem", "router.pem"):
        (mixed / f).write_bytes((certs / f).read_bytes())
    (mixed / "router.key").write_bytes((other / "router.key").read_bytes())
    port = 7447
    cases = [
        ({"ZENOH_TLS_DIR": str(tmp_path / "nonexistent")}, "is not a directory"),
        ({"ZENOH_TLS_DIR": str(mixed)}, "does not go with"),
        ({"ZENOH_TLS_DIR": str(other), "ZENOH_LISTEN": "udp/0.0.0.0:7447"}, "neither tls nor tcp"),
        ({"ZENOH_TLS_DIR": str(other), "ZENOH_LISTEN": "tls/0.0.0.0"}, "no :PORT"),
    ]
    for env, says in cases:
        code, out = router(lo_ns, {"ZENOH_LISTEN": f"tls/127.0.0.1:{port}", **env})
        assert code == 2 and says in out, (env, code, out)
    # a port in use (by a listener in the namespace)
    holder = subprocess.Popen([*lo_ns, sys.executable, "-c", f"""
import socket, sys, time
s = socket.socket(); s.bind(("127.0.0.1", {port})); s.listen(); print("ready", flush=True); time.sleep(60)"""],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "ready"
        code, out = router(lo_ns, {"ZENOH_TLS_DIR": str(certs), "ZENOH_LISTEN": f"tls/127.0.0.1:{port}"})
    finally:
        holder.kill()
        holder.wait()
    assert code == 2 and "in use" in out, out


@pytest.mark.skipif(wanhost.available() is not None, reason=f"namespaces: {wanhost.available()}")
def test_a_bridge_dialling_a_name_not_in_the_routers_certificate_is_not_let_in(tmp_path, domain, lo_ns):
    """The router's certificate names 127.0.0.2 only (wan_certs.sh DIR 127.0.0.2): a
    bridge that dials it as 127.0.0.1 refuses it (and so gets nothing through); dialled by its name, it
    connects. In a namespace of its own with only a loopback."""
    certs = wanhost.make_certs(tmp_path / "certs")
    d = tmp_path / "local"
    # the same CA, a router certificate for 127.0.0.2 only
    d.mkdir()
    for f in os.listdir(certs):
        if (certs / f).is_file():
            (d / f).write_bytes((certs / f).read_bytes())
            (d / f).chmod((certs / f).stat().st_mode)
    (d / "private").mkdir(mode=0o700)
    (d / "private" / "ca.key").write_bytes((certs / "private" / "ca.key").read_bytes())
    (d / "private" / "ca.key").chmod(0o600)
    assert subprocess.run([str(CERTS_SH), str(d), "127.0.0.2"], capture_output=True, timeout=120).returncode == 0
    port = 7447
    env = {**os.environ, "EEZYBOT_WAN_BIN_DIR": str(wanhost.wan_bin_dir()), "ZENOH_TLS_DIR": str(d),
           "ZENOH_LISTEN": f"tls/0.0.0.0:{port}", "ROS_DOMAIN_ID": str(domain)}
    logs = {n: tmp_path / f"{n}.log" for n in ("router", "127.0.0.1", "127.0.0.2")}

    def out(name):
        return logs[name].read_text(errors="replace") if logs[name].exists() else ""

    def start(argv, name, **kw):
        with open(logs[name], "w") as f:
            return subprocess.Popen([*lo_ns, *argv], stdout=f, stderr=subprocess.STDOUT, **kw)

    def wait_for(done, what, timeout=60):
        """Until done() (the deadline only bounds a failure)."""
        deadline = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < deadline, f"{what}\n" + "\n".join(f"--- {n}\n{out(n)[-2000:]}" for n in logs)
            time.sleep(0.05)

    r = start([str(ROUTER_SH)], "router", env=env)
    bridges = []
    try:
        # the bridges dial once the router listens (its own line), as a user's would
        wait_for(lambda: "eezybot_wan_router: listening on" in out("router") or r.poll() is not None,
                 "the router did not say it listens")
        assert r.poll() is None, out("router")
        bin_ = str(wanhost.wan_bin_dir() / "eezybot_wan_bridge")
        for host in ("127.0.0.1", "127.0.0.2"):
            bridges.append(start([bin_, "pc", "--router", f"tls/{host}:{port}"], host,
                                 env={**env, "RUST_LOG": "warn,zenoh::net::runtime::orchestrator=debug"}))
        # the one dialling its name gets in; the other is refused for the name (each
        # attempt's reason at debug level) and says it is not connected (every 10 s)
        wait_for(lambda: "eezybot_wan_bridge: connected to the router tls/127.0.0.2" in out("127.0.0.2")
                 and "not connected to the router" in out("127.0.0.1")
                 and ("NotValidForName" in out("127.0.0.1") or "not valid for name" in out("127.0.0.1")),
                 "the bridges did not show both outcomes")
    finally:
        for b in bridges:
            b.terminate()
            b.wait(20)
        r.terminate()
        r.wait(20)
    wrong = out("127.0.0.1")
    assert "eezybot_wan_bridge: connected to the router" not in wrong, wrong[-3000:]
    assert [b.returncode for b in bridges] == [0, 0] and r.returncode == 0
