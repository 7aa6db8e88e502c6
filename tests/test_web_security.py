"""The web side probed as an attacker would, on loopback (issue 18 item 7): each probe that
got through is a test here, run against the real gui_bridge binary. The panel's own
guards (Origin, DNS rebinding, token, floods) are tests/test_gui_bridge.py's."""
import os
import re
import socket
import struct
import time

import pytest
from geometry_msgs.msg import PointStamped
from rclpy.serialization import serialize_message

from conftest import LATCHED, REPO
from foxglove_client import free_port
from test_gui_bridge import RawWs, another_site, http_get, panel_status, rss_kib, start_panel

# in a process of its own, beside the other modules (conftest: `background`): its
# timeouts are judged from before the connection, so a busy host only makes them later
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=25)]

FOXGLOVE = {"Sec-WebSocket-Protocol": "foxglove.sdk.v1"}


def foxglove_ws(port, path="/", headers=None):
    """A raw WebSocket to the Foxglove server with the subprotocol and any headers."""
    return RawWs(port, path=path, headers={**FOXGLOVE, **(headers or {})})


def peak_rss_kib(pid):
    """The process's peak resident set (VmHWM)."""
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    raise RuntimeError("no VmHWM")


def printed_token(proc, port):
    deadline = time.monotonic() + 10
    while not (m := re.search(rf"web panel: http://127\.0\.0\.1:{port}/[#?]token=([0-9a-f]+)", proc.output())):
        assert time.monotonic() < deadline, proc.output()
        time.sleep(0.05)
    return m.group(1)


def start_panel_with_foxglove(launch, observer, host, *params):
    """gui_bridge with its Foxglove server on `host` and a free port, once that server
    runs: (process, panel port, Foxglove port)."""
    fox = free_port()
    proc, port = start_panel(launch, observer, "-p", f"foxglove_bind:={host}:{fox}", *params)
    deadline = time.monotonic() + 10
    while "Foxglove WebSocket server on" not in proc.output():
        assert time.monotonic() < deadline, proc.output()
        time.sleep(0.05)
    return proc, port, fox


def try_to_publish(ws, observer, xyz, seconds=3.0):
    """Advertise xyz_target and publish a target on it for a while (as the issue's probe)."""
    target = PointStamped()
    target.header.frame_id = "base_link"
    target.point.x, target.point.y, target.point.z = 0.2, 0.05, 0.15
    ws.send({"op": "advertise", "channels": [{"id": 1, "topic": "/xyz_target", "encoding": "cdr",
                                              "schemaName": "geometry_msgs/msg/PointStamped"}]})
    deadline = time.monotonic() + seconds
    while not xyz and time.monotonic() < deadline:
        ws.sock.sendall(RawWs.frame(struct.pack("<BI", 1, 1) + serialize_message(target), opcode=0x2))
        observer.spin_for(0.2)
    return bool(xyz)


def test_foxglove_on_the_network_publishes_only_with_the_panel_s_token(launch, observer):
    """High: panel on loopback, foxglove_bind:=0.0.0.0, foxglove_publish:=true. A Foxglove
    client of another origin, or without the token, published xyz_target and the base
    turned. Now a Foxglove server beyond loopback makes the panel's token required for
    both, and every Foxglove client passes the panel's rules."""
    xyz = observer.sub("/xyz_target", PointStamped)
    # (plain HTTP beyond loopback, as before TLS: the rules are the same over HTTPS)
    proc, port, fox = start_panel_with_foxglove(launch, observer, "0.0.0.0", "-p", "foxglove_publish:=true",
                                                "-p", "insecure_http:=true")
    for headers, path, status in (({"Origin": "http://evil.example"}, "/", 403),
                                  ({}, "/", 401),
                                  ({}, "/?token=" + "0" * 48, 403),
                                  ({"Origin": "http://evil.example"}, "/?token={token}", 403)):
        if "{token}" in path:
            path = path.format(token=printed_token(proc, port))
        ws = foxglove_ws(fox, path, headers)
        if ws.status == 101:  # the probe of the issue: publish and see whether the arm moves
            moved = try_to_publish(ws, observer, xyz)
            ws.close()
            assert False, f"{headers} {path}: admitted; a target reached ROS: {moved}"
        assert ws.status == status, (headers, path, ws.status, ws.body)
    observer.spin_for(0.3)
    assert not xyz
    token = printed_token(proc, port)
    # the operator's own Foxglove, with the printed token, publishes
    ws = foxglove_ws(fox, f"/?token={token}")
    assert ws.status == 101, ws.body
    info = ws.recv_json(lambda m: m.get("op") == "serverInfo")
    assert "clientPublish" in info["capabilities"]
    assert try_to_publish(ws, observer, xyz, seconds=10), "the token holder's target never reached ROS"
    ws.close()
    # the panel needs the token too now (it is printed, and the same)
    assert RawWs(port).status == 401
    assert RawWs(port, path=f"/ws?token={token}").status == 101


def test_foxglove_refuses_other_origins_rebinding_and_connections_over_its_cap(launch, observer):
    """Medium: the Foxglove server checked no Origin or Host (a page in the operator's
    browser, or a rebinding name, read robot_description) and took 200 of 200
    connections."""
    from diagnostic_msgs.msg import DiagnosticArray
    diags = observer.sub("/diagnostics", DiagnosticArray)
    proc, port, fox = start_panel_with_foxglove(launch, observer, "127.0.0.1")
    evil = foxglove_ws(fox, headers={"Origin": "http://evil.example"})
    assert evil.status == 403 and "evil.example" in evil.body, (evil.status, evil.body)
    rebound = foxglove_ws(fox, headers={"Host": f"evil.example:{fox}", "Origin": f"http://evil.example:{fox}"})
    assert rebound.status == 403, (rebound.status, rebound.body)
    rebound = foxglove_ws(fox, headers={"Host": f"evil.example:{fox}"})
    assert rebound.status == 403 and "not a loopback name" in rebound.body, (rebound.status, rebound.body)
    # Foxglove's web app (the default foxglove_origins) and programs are let in
    app = foxglove_ws(fox, headers={"Origin": "https://app.foxglove.dev"})
    assert app.status == 101, app.body
    app.recv_json(lambda m: m.get("op") == "serverInfo")
    app.close()
    # 200 connections: at most 16 at once, the rest refused with 503
    opened, refused = [], 0
    for _ in range(200):
        ws = foxglove_ws(fox)
        if ws.status == 101:
            opened.append(ws)
        else:
            assert ws.status == 503, (ws.status, ws.body)
            refused += 1
    print(f"200 connections: {len(opened)} accepted, {refused} refused with 503")
    assert len(opened) == 16 and refused == 184
    for ws in opened:
        ws.close()
    # counted in gui_bridge's diagnostics, logged once per address and status
    def counted():
        status = panel_status(diags)
        return status and status[2].get("foxglove_refused") == "3" and status[2].get("foxglove_refused_busy") == "184"
    assert observer.spin_until(counted, 10), panel_status(diags)
    assert proc.output().count("Foxglove client 127.0.0.1") == 1, proc.output()


def test_a_10_mib_foxglove_message_closes_that_client_and_memory_stays_flat(launch, observer):
    """Medium: the Foxglove server read 10 MiB messages (RSS 19 -> 101 MB). Now a message
    over 1 MiB closes the client at its header, before its payload is read."""
    proc, port, fox = start_panel_with_foxglove(launch, observer, "127.0.0.1")
    before, peak_before = rss_kib(proc.proc.pid), peak_rss_kib(proc.proc.pid)
    big = RawWs.frame(b"\0" * (10 * 1024 * 1024), opcode=0x2)
    for _ in range(5):
        ws = foxglove_ws(fox)
        assert ws.status == 101
        ws.recv_json(lambda m: m.get("op") == "serverInfo")
        try:
            ws.sock.sendall(big)
        except OSError:
            pass  # closed by the server while sending: the point
        # the server ends this client: a close frame (1009) or the connection itself. A
        # client kept open and silent is not ended: the read's timeout (a generous
        # deadline) is told apart from a close.
        ws.sock.settimeout(10)
        ended = None
        try:
            while (frame := ws.recv())[0] != 0x8:
                pass
            ended = struct.unpack(">H", frame[1][:2])[0]
        except TimeoutError:
            ended = "still open and silent after 10 s"
        except (OSError, ConnectionError):
            ended = "connection closed"
        assert ended in (1009, "connection closed"), ended
        ws.close()
    time.sleep(0.5)
    after, peak_after = rss_kib(proc.proc.pid), peak_rss_kib(proc.proc.pid)
    print(f"RSS {before} KiB -> {after} KiB, peak {peak_before} KiB -> {peak_after} KiB after five 10 MiB messages")
    assert peak_after - peak_before < 8 * 1024, (peak_before, peak_after)
    ok = foxglove_ws(fox)
    assert ok.status == 101, "the server no longer serves after the big messages"
    ok.close()


def test_the_token_goes_to_no_other_server_and_not_into_urls(launch, observer, browser):
    """Medium: the token lived in a cookie, and cookies are not isolated by port: another
    server on 127.0.0.1 received it; the ?token= URL stayed in the history. Now the page
    keeps it in its origin's localStorage and sends it as a WebSocket subprotocol."""
    seen = []
    with another_site(b"<p>another server</p>", seen) as other_port:
        proc, port = start_panel(launch, observer, "-p", "insecure_http:=true", bind_host="0.0.0.0")
        token = printed_token(proc, port)
        context = browser.new_context()
        page = context.new_page()
        sockets = []
        page.on("websocket", lambda ws: sockets.append(ws.url))
        page.goto(f"http://127.0.0.1:{port}/?token={token}")  # the old printed URL: the probe
        page.wait_for_function("() => document.getElementById('ws-dot').className.includes('up')")
        assert token not in page.url
        assert sockets and not [u for u in sockets if token in u], sockets
        assert not [c for c in context.cookies() if token in c["value"]], context.cookies()
        # a reload works from the origin's storage
        page.reload()
        page.wait_for_function("() => document.getElementById('ws-dot').className.includes('up')")
        # another server of this host, visited by the same browser, gets nothing of it
        page.goto(f"http://127.0.0.1:{other_port}/")
        assert seen, "the other server was not visited"
        leaked = [(p, h) for p, h in seen if token in p or any(token in v for v in h.values())]
        assert not leaked, leaked
        context.close()


def program_message(ws, pred, timeout=10.0):
    """The next `program` broadcast that satisfies `pred`."""
    return ws.recv_json(lambda m: m.get("t") == "program" and pred(m), timeout=timeout)


def test_a_fifo_in_program_dir_is_refused_and_another_client_s_e_stop_is_answered(launch, observer, tmp_path):
    """Medium: a FIFO named fifo.csv in program_dir froze gui_bridge's event loop when
    loaded; another client's e-stop went unanswered for 8.5 s. Now program files are
    opened O_NOFOLLOW|O_NONBLOCK and must be regular files (fstat), off the event loop."""
    from std_msgs.msg import Bool
    os.mkfifo(tmp_path / "fifo.csv")
    (tmp_path / "secret.txt").write_text("root:x:0:0:a line of a file outside\n")
    (tmp_path / "link.csv").symlink_to(tmp_path / "secret.txt")
    estop = observer.sub("/estop", Bool, LATCHED)
    proc, port = start_panel(launch, observer, "-p", f"program_dir:={tmp_path}")
    loader, other = RawWs(port), RawWs(port)
    for ws in (loader, other):
        ws.recv_json(lambda m: m["t"] == "hello")
    loader.send({"t": "program", "op": "load", "name": "fifo"})
    other.send({"t": "estop", "on": True})
    # the e-stop is answered (the old node never answered while the FIFO blocked it)
    other.recv_json(lambda m: m["t"] in ("ack", "estop"), timeout=10)
    assert observer.spin_until(lambda: estop and estop[-1][1].data, 10)
    m = program_message(loader, lambda m: "fifo" in m["message"] and "…" not in m["message"])
    assert m["message"] == "program fifo is not a regular file (symbolic links, FIFOs and devices are refused)", m
    loader.send({"t": "program", "op": "load", "name": "link"})
    m = program_message(loader, lambda m: "link" in m["message"] and "…" not in m["message"])
    assert "not a regular file" in m["message"] and "a line of a file outside" not in m["message"], m
    assert m["files"] == [], m["files"]
    loader.send({"t": "program", "op": "load", "name": "missing"})
    m = program_message(loader, lambda m: "missing" in m["message"] and "…" not in m["message"])
    assert str(tmp_path) not in m["message"], m["message"]
    loader.close()
    other.close()


def test_saving_over_a_program_asks_first_and_formula_names_are_stored_as_text(launch, observer, browser, tmp_path):
    """Low: a saved program was overwritten silently, and a point named =HYPERLINK(…) was
    saved as is (a formula when the file is opened in a spreadsheet)."""
    proc, port = start_panel(launch, observer, "-p", f"program_dir:={tmp_path}")
    ws = RawWs(port)
    ws.recv_json(lambda m: m["t"] == "hello")
    ws.send({"t": "program", "op": "teach"})
    program_message(ws, lambda m: m["message"].startswith("taught"))
    ws.send({"t": "program", "op": "rename", "i": 0, "name": '=HYPERLINK("http://evil.example")'})
    program_message(ws, lambda m: m["program"]["points"][0]["name"].startswith("="))
    ws.send({"t": "program", "op": "save", "name": "p1"})
    program_message(ws, lambda m: m["message"] == "saved 1 points as p1")
    saved = (tmp_path / "p1.csv").read_text()
    name_cell = saved.splitlines()[1].split(",", 6)[6]
    assert name_cell == "'=HYPERLINK(\"http://evil.example\")", saved
    # read back as it was
    ws.send({"t": "program", "op": "load", "name": "p1"})
    m = program_message(ws, lambda m: m["message"].startswith("loaded p1"))
    assert m["program"]["points"][0]["name"] == '=HYPERLINK("http://evil.example")'
    # a second save under that name keeps the file and asks
    ws.send({"t": "program", "op": "teach"})
    program_message(ws, lambda m: m["message"].startswith("taught"))
    ws.send({"t": "program", "op": "save", "name": "p1"})
    m = program_message(ws, lambda m: "p1" in m["message"] and "…" not in m["message"])
    assert m["confirm_overwrite"] == "p1" and "exists already" in m["message"], m
    assert (tmp_path / "p1.csv").read_text() == saved, "overwritten without asking"
    ws.send({"t": "program", "op": "save", "name": "p1", "overwrite": True})
    program_message(ws, lambda m: m["message"] == "saved 2 points as p1")
    ws.close()
    # the panel asks the operator
    context = browser.new_context()
    page = context.new_page()
    asked = []
    page.on("dialog", lambda d: (asked.append(d.message), d.accept()))
    page.goto(f"http://127.0.0.1:{port}/")
    page.wait_for_function("() => document.getElementById('ws-dot').className.includes('up')")
    page.fill("#prog-name", "p1")
    page.click("#prog-save")
    page.wait_for_function("() => document.getElementById('prog-msg').textContent === 'saved 2 points as p1'")
    assert asked and "p1 exists already" in asked[0], asked
    context.close()


HEAD_TIMEOUT_S = 10  # gui_bridge's linger::HEAD_TIMEOUT


def test_a_half_open_http_connection_is_dropped_after_the_head_timeout(launch, observer):
    """Low: half-open HTTP connections were held with no header timeout, before
    authentication. Now a connection has 10 s to send its request head: it is held that
    long, then dropped."""
    proc, port = start_panel(launch, observer)
    # The server's deadline starts when it accepts, after connect() began here, and a
    # timer never fires early: a drop seen here less than HEAD_TIMEOUT_S after this
    # instant is a drop before the timeout, however busy the host.
    start = time.monotonic()
    # (the socket's timeout, 3x the head timeout, is only a deadline for the drop)
    with socket.create_connection(("127.0.0.1", port), timeout=3 * HEAD_TIMEOUT_S) as s:
        s.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n".encode())
        answer = b""
        try:
            while chunk := s.recv(4096):
                answer += chunk
            how = "closed"
        except TimeoutError:
            how = f"still open after {3 * HEAD_TIMEOUT_S} s"
        except OSError as e:
            how = f"reset ({e})"  # a reset is a drop too
        held = time.monotonic() - start
    print(f"a half-open connection was dropped after {held:.1f} s: {how}")
    assert not how.startswith("still open"), how
    assert held >= HEAD_TIMEOUT_S, f"dropped {held:.2f} s after connecting, before the head timeout: {how}, {answer[:200]}"
    assert held < 6 * HEAD_TIMEOUT_S, held  # bytes trickling in would renew the socket's timeout


def test_a_script_in_robot_description_does_not_run_in_the_panel_s_origin(launch, observer, browser, tmp_path):
    """Medium: a robot_description with an XHTML <script> (any DDS peer can publish one)
    was served at /robot.urdf as application/xml and ran in the panel's origin. Now it is
    text/plain with nosniff, and the page has a full Content-Security-Policy (no inline
    script) under which it still works."""
    urdf = (REPO / "urdf" / "eezybot.urdf").read_text()
    script = ('<h:script xmlns:h="http://www.w3.org/1999/xhtml">'
              'document.title = "pwned"; window.__pwned = document.domain;</h:script>')
    evil = urdf.replace('<robot name="eezybot_arm_mk2">', '<robot name="eezybot_arm_mk2">' + script, 1)
    assert script in evil
    path = tmp_path / "evil.urdf"
    path.write_text(evil)
    launch("state_publisher", "--ros-args", "-p", f"urdf:={path}")
    proc, port = start_panel(launch, observer)
    deadline = time.monotonic() + 15
    while (got := http_get(port, "/robot.urdf"))[0] != 200:
        assert time.monotonic() < deadline, got
        time.sleep(0.1)
    status, headers, body = got
    assert script in body
    context = browser.new_context()
    page = context.new_page()
    console = []
    page.on("console", lambda m: console.append((m.type, m.text)) if m.type in ("error", "warning") else None)
    page.goto(f"http://127.0.0.1:{port}/robot.urdf")
    page.wait_for_load_state("load")
    assert page.title() != "pwned" and page.evaluate("() => window.__pwned") is None, "the URDF's script ran"
    assert headers["content-type"] == ["text/plain; charset=utf-8"], headers
    assert headers["x-content-type-options"] == ["nosniff"], headers
    # the page: a full policy, and it works under it (3D view, WebSocket, no violation)
    _, headers, _ = http_get(port, "/")
    csp = headers["content-security-policy"][0]
    for directive in ("default-src 'self'", "script-src 'self';", "frame-ancestors 'none'", "object-src 'none'",
                      "base-uri 'none'", f"ws://127.0.0.1:{port}"):
        assert directive in csp, csp
    assert "unsafe-inline" not in csp and "unsafe-eval" not in csp, csp
    console.clear()
    page.goto(f"http://127.0.0.1:{port}/")
    page.wait_for_function("() => document.getElementById('ws-dot').className.includes('up')")
    # the style sheet applies (panel.css hides the empty access banner), no violation
    page.wait_for_function("() => window.getComputedStyle(document.getElementById('access')).display === 'none'")
    assert not [m for _, m in console if "Content Security Policy" in m], console
    # a script injected into the page does not run
    page.evaluate("""() => { const s = document.createElement('script');
                             s.textContent = 'window.__inline = 1'; document.body.append(s); }""")
    assert page.evaluate("() => window.__inline") is None, "an inline script ran under the page's policy"
    context.close()
