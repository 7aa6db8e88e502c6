"""The web panel over HTTPS and WSS (issue 36 item 4, and item 5's panel part): a bind or
foxglove_bind beyond loopback speaks TLS with the certificate of tls_cert/tls_key, or
does not start unless insecure_http says the token may travel in the clear;
launch_scripts/panel_certs.sh makes the certificate; Chromium, trusting that CA, drives
the panel across a veth between two network namespaces while tcpdump on the link finds
no token (and finds it in the plain-HTTP control); the certificate's expiry is in
diagnostics, with a warning 30 days before."""
import datetime
import json
import os
import re
import secrets
import socket
import ssl
import subprocess
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray

import twohost
from conftest import CHROMIUM, CHROMIUM_ARGS, REPO, NodeProcess
from launch_script import Script, node_processes, reap_scripts  # noqa: F401 (a fixture)
from security_rig import Capture
from test_gui_bridge import panel_status, run_cli, start_panel

# in a process of its own (network namespaces, a browser of its own), beside the others
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=45)]
needs_namespaces = pytest.mark.skipif(twohost.available() is not None, reason=f"namespaces: {twohost.available()}")

PANEL_CERTS = REPO / "launch_scripts" / "panel_certs.sh"
UP = "() => document.getElementById('ws-dot').className.includes('up')"


def panel_certs(directory, *hosts):
    r = subprocess.run([str(PANEL_CERTS), str(directory), *hosts], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return r


def openssl(*args, stdin=None):
    return subprocess.run(["openssl", *args], capture_output=True, text=True, input=stdin, timeout=30)


def trusting_home(tmp_path, ca):
    """A HOME whose NSS store (~/.pki/nssdb, Chromium's on Linux) trusts `ca` for web
    sites, as a user who imported it in the browser's settings."""
    home = tmp_path / "home"
    db = home / ".pki" / "nssdb"
    db.mkdir(parents=True)
    for argv in (["certutil", "-N", "-d", f"sql:{db}", "--empty-password"],
                 ["certutil", "-A", "-d", f"sql:{db}", "-n", "eezybot panel test CA", "-t", "C,,", "-i", str(ca)]):
        r = subprocess.run(argv, capture_output=True, text=True, timeout=30)
        assert r.returncode == 0, (argv, r.stderr)
    return home


def test_panel_certs_makes_a_ca_and_a_certificate_for_each_host_once(tmp_path):
    """The panel's certificate names every HOST (and loopback) as a SAN and verifies
    against ca.pem; a second run changes nothing; the CA signs for nothing beyond private
    addresses, local names and the hosts it was made for."""
    d = tmp_path / "certs"
    panel_certs(d, "192.168.1.5", "mypc.local")
    san = openssl("x509", "-in", str(d / "panel.pem"), "-noout", "-ext", "subjectAltName").stdout
    for name in ("IP Address:192.168.1.5", "DNS:mypc.local", "DNS:localhost", "IP Address:127.0.0.1"):
        assert name in san, san
    assert openssl("verify", "-CAfile", str(d / "ca.pem"), str(d / "panel.pem")).returncode == 0
    assert (d / "panel.key").stat().st_mode & 0o077 == 0 and (d / "private" / "ca.key").stat().st_mode & 0o077 == 0
    before = {f: (d / f).read_bytes() for f in ("ca.pem", "panel.pem", "panel.key")}
    panel_certs(d, "192.168.1.5", "mypc.local")
    assert {f: (d / f).read_bytes() for f in before} == before
    # a public address is outside the CA's name constraints: refused, the old files kept
    r = subprocess.run([str(PANEL_CERTS), str(d), "192.168.1.5", "203.0.113.9"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "--new-ca" in r.stderr, r.stderr
    assert (d / "panel.pem").read_bytes() == before["panel.pem"]
    # a certificate the CA's key signs for another site anyway does not verify
    rogue = tmp_path / "rogue"
    openssl("req", "-new", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", str(rogue) + ".key",
            "-subj", "/CN=bank.example", "-addext", "subjectAltName=DNS:bank.example", "-out", str(rogue) + ".csr")
    signed = openssl("x509", "-req", "-in", str(rogue) + ".csr", "-CA", str(d / "ca.pem"), "-CAkey", str(d / "private" / "ca.key"),
                     "-copy_extensions", "copy", "-days", "30", "-out", str(rogue) + ".pem")
    assert signed.returncode == 0, signed.stderr
    check = openssl("verify", "-CAfile", str(d / "ca.pem"), str(rogue) + ".pem")
    assert check.returncode != 0 and "subtree" in check.stdout + check.stderr, check.stdout + check.stderr
    # another host list: the panel's certificate again, the CA kept
    panel_certs(d, "10.1.2.3")
    assert (d / "ca.pem").read_bytes() == before["ca.pem"]
    assert "IP Address:10.1.2.3" in openssl("x509", "-in", str(d / "panel.pem"), "-noout", "-ext", "subjectAltName").stdout
    r = subprocess.run([str(PANEL_CERTS), str(d)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and "usage: panel_certs.sh" in r.stderr, r.stderr


def test_a_bind_beyond_loopback_needs_tls_or_insecure_http(domain, tmp_path):
    """Without a certificate and without insecure_http, a bind or foxglove_bind beyond
    loopback does not start (exit 2) and says what to do; half a pair, or a file that is
    not there, neither."""
    for params, named in ((["bind:=0.0.0.0:0", "foxglove_bind:="], "bind 0.0.0.0:0"),
                          (["bind:=127.0.0.1:0", "foxglove_bind:=0.0.0.0:0"], "foxglove_bind 0.0.0.0:0"),
                          (["bind:=127.0.0.1:0", f"tls_cert:={tmp_path}/panel.pem"], "tls_key is empty"),
                          (["bind:=0.0.0.0:0", f"tls_cert:={tmp_path}/panel.pem", f"tls_key:={tmp_path}/panel.key"],
                           f"tls_cert {tmp_path}/panel.pem: no such file")):
        r = run_cli(domain, "--ros-args", *[a for p in params for a in ("-p", p)])
        assert r.returncode == 2 and named in r.stderr, (params, r.returncode, r.stderr)
        if "beyond loopback" in r.stderr:
            for hint in ("tls_cert and tls_key", "panel_certs.sh", "insecure_http:=true", "in the clear"):
                assert hint in r.stderr, r.stderr


def test_insecure_http_warns_at_start_and_in_diagnostics(launch, observer):
    diags = observer.sub("/diagnostics", DiagnosticArray)
    proc, port = start_panel(launch, observer, "-p", "insecure_http:=true", "-p", "foxglove_bind:=", bind_host="0.0.0.0")
    assert re.search(r"WARN.*plain HTTP beyond loopback \(bind 0\.0\.0\.0:\d+; insecure_http:=true\): the access token travels in the clear",
                     proc.output()), proc.output()
    assert observer.spin_until(lambda: panel_status(diags) is not None, 10)
    level, message, values = panel_status(diags)
    assert level == 1 and "the access token travels in the clear" in message, (level, message)
    assert values["tls"] == "off (insecure_http)", values
    assert re.search(rf"web panel: http://127\.0\.0\.1:{port}/#token=", proc.output())


def short_lived_certificate(tmp_path, ca_dir, days):
    """A panel certificate for 127.0.0.1 from the CA in `ca_dir`, valid `days` (with
    launch_scripts/certs.sh, as panel_certs.sh issues them)."""
    out = tmp_path / f"panel-{days}.pem"
    script = f"""set -e
WORK=$(mktemp -d); trap 'rm -rf "$WORK"' EXIT
. {REPO}/launch_scripts/certs.sh
certs_issue eezybot-panel {ca_dir}/panel.key {out} {days} $'basicConstraints = critical, CA:FALSE\\nextendedKeyUsage = serverAuth\\nsubjectAltName = IP:127.0.0.1' {ca_dir}/ca.pem {ca_dir}/private/ca.key
"""
    r = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return out


def not_after(pem):
    text = openssl("x509", "-in", str(pem), "-noout", "-enddate").stdout.strip().split("=", 1)[1]
    return datetime.datetime.strptime(text, "%b %d %H:%M:%S %Y %Z").date().isoformat()


def test_the_certificate_s_expiry_is_in_diagnostics_and_warned_of_30_days_before(launch, observer, tmp_path):
    """HTTPS on loopback with panel_certs.sh's certificate: diagnostics carry its expiry
    (OK, 825 days); one with 20 days left makes the report a warning that names the file."""
    d = tmp_path / "certs"
    panel_certs(d, "127.0.0.1")
    for cert, days, level in ((d / "panel.pem", 825, 0), (short_lived_certificate(tmp_path, d, 20), 20, 1)):
        diags = observer.sub("/diagnostics", DiagnosticArray)
        proc, port = start_panel(launch, observer, "-p", f"tls_cert:={cert}", "-p", f"tls_key:={d / 'panel.key'}",
                                 "-p", "foxglove_bind:=", "-r", f"__node:=gui_bridge_{days}")
        url = f"https://127.0.0.1:{port}/"
        assert observer.spin_until(lambda: (s := panel_status(diags)) is not None and s[2].get("url") == url, 10), \
            panel_status(diags)
        got_level, message, values = panel_status(diags)
        assert values["certificate_expires"] == not_after(cert), values
        assert int(values["certificate_days_left"]) in (days - 1, days), values
        assert values["tls"] == "on", values
        assert got_level == level, (got_level, message)
        if level:
            assert f"{cert} expires on" in message and "renew it" in message, message
        # the page over HTTPS, the WebSocket's Origin https://
        ctx = ssl.create_default_context(cafile=str(d / "ca.pem"))
        with ctx.wrap_socket(socket.create_connection(("127.0.0.1", port), timeout=5), server_hostname="127.0.0.1") as s:
            s.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n\r\n".encode())
            assert s.recv(64).startswith(b"HTTP/1.1 200"), "no page over HTTPS"
        # a plain HTTP request to the HTTPS port gets no page
        assert b"<html" not in plain_get(port)
        proc.stop()


def plain_get(port):
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n\r\n".encode())
        data = b""
        try:
            while chunk := s.recv(4096):
                data += chunk
        except OSError:
            pass
        return data


def sent_xyz(frame, z):
    """Is this WebSocket frame gui_bridge's word that it published an xyz_target at `z`?"""
    try:
        m = json.loads(frame)
    except (TypeError, ValueError):
        return False
    return m.get("t") == "sent" and m.get("topic") == "xyz_target" and abs(m["xyz"][2] - z) < 1e-9


def foxglove_hello(host, port, token, context):
    """Upgrade to the Foxglove server with ?token= (as Foxglove's URL carries it), over
    `context` (TLS) or plain; the first bytes after the answer's head."""
    raw = socket.create_connection((host, port), timeout=10)
    s = context.wrap_socket(raw, server_hostname=host) if context else raw
    with s:
        s.sendall((f"GET /?token={token} HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                   "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
                   "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n").encode())
        data = b""
        while b"serverInfo" not in data:
            chunk = s.recv(4096)
            assert chunk, data
            data += chunk
        return data


@needs_namespaces
def test_chromium_drives_the_panel_over_https_and_the_link_carries_no_token(domain, tmp_path):
    """gui_bridge in namespace `pc` on its veth address (panel and Foxglove server),
    Chromium in `pi` trusting panel_certs.sh's CA: the page opens at
    https://ADDRESS:PORT/#token=…, its WebSocket comes up and a slider's target goes out
    on xyz_target (gui_bridge's `sent` to the page); a Foxglove client connects over
    wss:// with ?token=. tcpdump on the link sees the handshakes and no byte sequence of
    the token. The control, insecure_http with the
    same steps over http://, shows the token on the link (so the capture can fail)."""
    from playwright.sync_api import sync_playwright
    hosts = twohost.TwoHosts(tag="tls")
    try:
        certs = tmp_path / "certs"
        panel_certs(certs, hosts.pc_addr)
        home = trusting_home(tmp_path, certs / "ca.pem")
        token = secrets.token_hex(24)
        for tls in (True, False):
            web, fox = 8443 if tls else 8080, 8765
            transport = (["-p", f"tls_cert:={certs / 'panel.pem'}", "-p", f"tls_key:={certs / 'panel.key'}"] if tls
                         else ["-p", "insecure_http:=true"])
            gui = NodeProcess("gui_bridge", ["--ros-args", "-p", f"bind:={hosts.pc_addr}:{web}",
                                             "-p", f"foxglove_bind:={hosts.pc_addr}:{fox}", "-p", f"token:={token}",
                                             "--log-level", "debug", *transport], domain, netns=hosts.pc)
            capture = Capture(hosts.pi, hosts.pi_if, tmp_path / f"link-{tls}.pcap", "tcp", promiscuous=False)
            try:
                deadline = time.monotonic() + 15
                while not ("Foxglove WebSocket server on" in gui.output() and "web panel:" in gui.output()):
                    assert time.monotonic() < deadline and gui.proc.poll() is None, gui.output()
                    time.sleep(0.05)
                scheme = "https" if tls else "http"
                assert f"web panel: {scheme}://{hosts.pc_addr}:{web}/#token={token}" in gui.output(), gui.output()
                with twohost.netns(hosts.pi), sync_playwright() as p:
                    b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, env={**os.environ, "HOME": str(home)})
                    try:
                        page = b.new_page()
                        console = []
                        page.on("console", lambda m: console.append((m.type, m.text)))
                        frames = []
                        page.on("websocket", lambda ws: (console.append(("websocket", ws.url)),
                                                         ws.on("framereceived", lambda f: frames.append(f))))
                        page.goto(f"{scheme}://{hosts.pc_addr}:{web}/#token={token}")
                        try:
                            page.wait_for_function(UP, timeout=30000)
                        except Exception as e:
                            raise AssertionError(f"{e}; the page's console: {console}") from None
                        assert "token" not in page.url
                        # a target from the slider goes out on xyz_target: gui_bridge says
                        # so to the page (`sent`, with the target)
                        z = 0.16 if tls else 0.17
                        page.eval_on_selector("#z", "(el, v) => { el.value = v; el.dispatchEvent(new Event('input')); }", z)
                        deadline = time.monotonic() + 15
                        while not any(sent_xyz(f, z) for f in frames):
                            assert time.monotonic() < deadline, frames[-5:]
                            page.wait_for_timeout(50)
                    finally:
                        b.close()
                    if tls:  # a browser that does not trust the CA gets no page (README)
                        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS,
                                              env={**os.environ, "HOME": str(tmp_path)})
                        try:
                            with pytest.raises(Exception, match="ERR_CERT_AUTHORITY_INVALID"):
                                b.new_page().goto(f"https://{hosts.pc_addr}:{web}/")
                        finally:
                            b.close()
                    context = ssl.create_default_context(cafile=str(certs / "ca.pem")) if tls else None
                    hello = foxglove_hello(hosts.pc_addr, fox, token, context)
                    assert b"101 Switching Protocols" in hello and b"serverInfo" in hello
            finally:
                pcap = capture.stop()
                code = gui.stop()
            assert code == 0, gui.output()
            assert len(pcap) > 5000, len(pcap)
            pieces = {token[i:i + 12] for i in range(0, len(token) - 11, 6)}
            seen = sorted(p for p in pieces if p.encode() in pcap)
            if tls:
                assert b"\x16\x03" in pcap  # TLS handshake records crossed the link
                assert not seen, f"parts of the token in the clear on the link: {seen}"
                assert b"GET /" not in pcap and b"eezybot.panel.v1" not in pcap
            else:
                assert token.encode() in pcap and b"token." + token.encode() in pcap, "the control saw no token"
    finally:
        hosts.close()


def test_pc_sh_gives_gui_bridge_the_certificate_of_gui_tls_dir(domain, tmp_path):
    """GUI_TLS_DIR: gui_bridge gets tls_cert and tls_key from it and the banner says
    https://; a GUI_TLS_DIR without the files stops the script before anything starts
    (exit 2)."""
    certs = tmp_path / "certs"
    panel_certs(certs, "127.0.0.1")
    s = Script("pc.sh", env={"ROS_DOMAIN_ID": str(domain), "GUI_TLS_DIR": str(certs)})
    try:
        argv = s.nodes(3)["gui_bridge"]
        assert f"tls_cert:={certs}/panel.pem" in argv and f"tls_key:={certs}/panel.key" in argv, argv
        deadline = time.monotonic() + 20
        while "web panel: https://127.0.0.1:0/" not in s.output():
            assert time.monotonic() < deadline, s.output()
            time.sleep(0.1)
    finally:
        code = s.stop()
    assert code == 0, s.output()
    s = Script("pc.sh", env={"ROS_DOMAIN_ID": str(domain), "GUI_TLS_DIR": str(tmp_path / "nothing")})
    assert s.proc.wait(30) == 2, s.output()
    assert "no readable TLS file" in s.output() and "panel_certs.sh" in s.output(), s.output()
    assert not node_processes(s.proc.pid)
