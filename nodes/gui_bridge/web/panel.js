"use strict";
const $ = (id) => document.getElementById(id);
let ws = null, hello = null, target = [0.186, 0, 0.229], reachable = true, pose = null, estop = false, mode = "xyz";
// the arm (from robot_description, else the EezyBot): joint sliders, reach, EezyBot or not
let robot = { name: "eezybot", eezybot: true, joints: [], reach: 0.33, from_urdf: false };
// the calibration wizard as gui_bridge last told it (null: never told); the small arm pictures
let cal = null, calRefusal = null, calSentAt = -1e9;
const pictures = [];
// what moves the arm: not sent while the wizard calibrates the arm's servos (compute_ik refuses it then)
const MOTION = new Set(["target", "jog", "joints", "gripper"]);
const send = (msg) => {
  if (MOTION.has(msg.t)) {
    if (calBusy()) return;
    calSentAt = -1e9; // a refusal now is this request's
  }
  if (ws && ws.readyState === 1) ws.send(JSON.stringify(msg));
};

// Access token: from the URL gui_bridge printed (#token=..., or ?token=...), kept in this
// origin's localStorage, which no other port or site can read (a cookie would go to every
// server on this host), and taken out of the address bar. The page sends it itself: as a
// WebSocket subprotocol "token.…" and as an Authorization header, never in a URL.
const TOKEN_KEY = "eezybot_panel_token";
const query = new URLSearchParams(location.search), frag = new URLSearchParams(location.hash.slice(1));
let TOKEN = frag.get("token") || query.get("token");
const store = { get: () => { try { return localStorage.getItem(TOKEN_KEY); } catch (e) { return null; } },
                set: (t) => { try { if (t) localStorage.setItem(TOKEN_KEY, t); else localStorage.removeItem(TOKEN_KEY); } catch (e) { /* private mode */ } } };
if (TOKEN) {
  store.set(TOKEN);
  query.delete("token"); frag.delete("token");
  history.replaceState(null, "", location.pathname + (query.toString() ? "?" + query : "") + (frag.toString() ? "#" + frag : ""));
} else {
  TOKEN = store.get();
}
const authHeaders = () => (TOKEN ? { Authorization: "token " + TOKEN } : {});

function showAccess(text, askToken) {
  $("access-text").textContent = text;
  $("access").className = text ? "shown" : "";
  $("token-form").hidden = !askToken;
}
$("token-form").onsubmit = (ev) => {
  ev.preventDefault();
  TOKEN = $("token-input").value.trim() || null;
  $("token-input").value = "";
  store.set(TOKEN);
  showAccess("");
  clearTimeout(retry);
  if (ws && ws.readyState <= 1) ws.close(); else connect();
};

// A refused WebSocket upgrade shows the browser no reason: ask the same URL over plain
// HTTP, which answers 401/403 with the reason (or 4xx of another kind when access is fine).
async function explainRefusal() {
  try {
    const r = await fetch("/ws", { cache: "no-store", headers: authHeaders() });
    if (r.status === 401 || r.status === 403) {
      const why = (await r.text()).trim();
      if (/token/.test(why)) { TOKEN = null; store.set(null); } // e.g. of an earlier run: forget it
      showAccess("The panel refused this page: " + why, /token/.test(why));
      return true;
    }
  } catch (e) { /* the node is not running: the red gui_bridge dot says it */ }
  return false;
}

let retry = null;
function connect() {
  let opened = false;
  ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws",
                     TOKEN ? ["eezybot.panel.v1", "token." + TOKEN] : ["eezybot.panel.v1"]);
  // the first message takes this page's place among the panel's clients (without a token,
  // a connection that has said nothing holds none)
  ws.onopen = () => { opened = true; send({ t: "hello" }); showAccess(""); $("ws-dot").className = "dot up"; };
  ws.onclose = async (ev) => {
    $("ws-dot").className = "dot down";
    if (ev.code === 1009 || ev.code === 1013) showAccess("The panel closed the connection: " + ev.reason);
    const refused = !opened && await explainRefusal();
    retry = setTimeout(connect, refused ? 5000 : 1000);
  };
  ws.binaryType = "blob";
  // a binary message is the camera view's image (a JPEG or PNG file); the rest is JSON
  ws.onmessage = (ev) => (typeof ev.data === "string" ? handle(JSON.parse(ev.data)) : showCamera(ev.data));
}

function handle(m) {
  switch (m.t) {
    case "hello":
      hello = m; target = m.target; applyRobot(m.robot); setSliders(target);
      if (m.pose) handle(m.pose);
      if (m.program) showProgram(m.program);
      if (m.calibration) showCalibration(m.calibration);
      if (m.leader) showLeader(m.leader);
      if (m.recorder) showRecorder(m.recorder);
      if (m.cube) showCube(m.cube);
      showRefusedInputs(m.inputs_refused || []);
      cameraTopic = m.camera || null;
      $("camera-caption").textContent = cameraTopic || "";
      if (!cameraTopic) hideCamera();
      break;
    case "robot": applyRobot(m.robot); break;
    case "ack": reachable = true; target = m.target; showReach(true, ""); if (mode === "xyz") setSliders(target, true); break;
    case "refused":
      if (calRefusedNow()) { calRefusal = m.reason; renderCalibration(); break; }
      if (recRefusedNow()) { recRefusal = m.reason; recSentAt = -1e9; renderRecorder(); break; }
      reachable = false; showReach(false, m.reason); break;
    case "check": showReach(m.reachable, m.reason || ""); break;
    case "pose": pose = m; draw(); showPose(m); posed3d(m); break;
    case "program": showProgram(m); break;
    case "calibration": showCalibration(m); break;
    case "leader": showLeader(m); break;
    case "recorder": showRecorder(m); break;
    case "status": showStatus(m); break;
    case "latency": $("latency").textContent = m.ms.toFixed(1) + " ms (median " + m.median_ms.toFixed(1) + ")"; break;
    case "estop": setEstop(m.on); break;
    case "sent": window.__sent = (window.__sent || 0) + 1; break;
    case "cube": showCube(m); break;
    case "inputs_refused": showRefusedInputs(m.inputs); break;
  }
}

// samples gui_bridge refused for being over its limits (a URDF of thousands of joints, …):
// one line each, "robot_description refused: 16000 joints > 256", while they hold
function showRefusedInputs(inputs) {
  const box = $("refused-inputs");
  box.textContent = inputs.map((r) => r.topic + " refused: " + r.reason).join("; ");
  box.hidden = inputs.length === 0;
}

// ---- the physics twin: its cube in the 3D view, its camera in the small view
// the cube as gui_bridge last told it: {p, q}, p null when no cube frame comes (hidden)
let cube = null;
function showCube(m) {
  cube = m.p ? m : null;
  if (view3d) view3d.setCube(cube ? cube.p : null, cube ? cube.q : null);
}
// the camera view: each image a blob: URL (the CSP's img-src allows blob:), the previous
// one revoked once the next is shown; hidden when no image came for CAMERA_STALE_MS
const CAMERA_STALE_MS = 2000;
let cameraTopic = null, cameraUrl = null, cameraTimer = null, cameraDecoding = false;
window.__camera = { shown: 0 };
function showCamera(blob) {
  if (cameraDecoding) return; // still showing the last one: skip, never queue
  cameraDecoding = true;
  const url = URL.createObjectURL(blob);
  const img = $("camera-img");
  img.onload = () => {
    cameraDecoding = false;
    if (cameraUrl) URL.revokeObjectURL(cameraUrl);
    cameraUrl = url;
    $("camera-view").hidden = false;
    window.__camera.shown++;
  };
  img.onerror = () => { cameraDecoding = false; URL.revokeObjectURL(url); };
  img.src = url;
  clearTimeout(cameraTimer);
  cameraTimer = setTimeout(hideCamera, CAMERA_STALE_MS);
}
function hideCamera() {
  clearTimeout(cameraTimer);
  $("camera-view").hidden = true;
}

function showReach(ok, reason) {
  $("reach").textContent = ok === null ? "not checked" : ok ? "reachable" : "unreachable";
  $("reach").className = ok === false ? "bad" : "ok";
  $("reason").textContent = reason;
  draw();
}

function setSliders(t, keepFocus) {
  ["x", "y", "z"].forEach((k, i) => {
    if (!keepFocus || document.activeElement !== $(k)) $(k).value = t[i];
    if (document.activeElement !== $(k + "_num")) $(k + "_num").value = t[i].toFixed(3);
  });
  if (!keepFocus || document.activeElement !== $("tz")) { $("tz").value = t[2]; $("tz_val").textContent = t[2].toFixed(3); }
}

function sliderTarget() { return ["x", "y", "z"].map((k) => parseFloat($(k).value)); }

["x", "y", "z"].forEach((k) => {
  $(k).addEventListener("input", () => { $(k + "_num").value = parseFloat($(k).value).toFixed(3); send({ t: "target", xyz: sliderTarget() }); });
  $(k + "_num").addEventListener("input", () => {
    const v = parseFloat($(k + "_num").value);
    if (!isFinite(v)) return;
    const t = sliderTarget(); t["xyz".indexOf(k)] = v;
    send({ t: "check", xyz: t });
  });
  $(k + "_num").addEventListener("change", () => {
    const v = parseFloat($(k + "_num").value);
    if (!isFinite(v)) return;
    $(k).value = v;
    const t = sliderTarget(); t["xyz".indexOf(k)] = v;
    send({ t: "target", xyz: t });
  });
});
$("gripper").addEventListener("input", () => { const v = parseFloat($("gripper").value); $("gripper_val").textContent = v.toFixed(2); send({ t: "gripper", v }); });

const deg = (r) => (r * 180 / Math.PI).toFixed(1) + "°";

// The joint mode's sliders, one per joint the arm's URDF lets an operator move (for the
// EezyBot: base, shoulder, elbow within config/arm.yaml's limits).
function buildJoints(joints) {
  const panel = $("joint-panel"); panel.innerHTML = "";
  for (const { name, lower, upper } of joints) {
    const row = document.createElement("div"); row.className = "row";
    const label = document.createElement("label"); label.htmlFor = `j_${name}`; label.textContent = name.replace(/_joint$/, "");
    const input = document.createElement("input"); input.type = "range"; input.id = `j_${name}`;
    input.min = lower; input.max = upper; input.step = 0.001;
    // where the arm is, else 0 within the limits (set after min and max, which clamp it)
    const now = pose && name in pose.joints ? pose.joints[name] : Math.min(upper, Math.max(lower, 0));
    input.value = now;
    const val = document.createElement("span"); val.id = `j_${name}_val`; val.textContent = deg(now);
    row.append(label, input, val);
    panel.appendChild(row);
    input.addEventListener("input", (ev) => {
      const v = parseFloat(ev.target.value);
      val.textContent = deg(v);
      send({ t: "joints", q: { [name]: v } });
    });
  }
}

function applyRobot(r) {
  if (!r) return;
  robot = r;
  scene3d(r);
  buildJoints(r.joints);
  $("gripper-row").hidden = !r.eezybot;  // gripper_target drives the EezyBot's claw
  if (!r.eezybot) {
    const reach = r.reach.toFixed(2);
    for (const k of ["x", "y"]) { $(k).min = -reach; $(k).max = reach; }
    $("z").min = 0; $("z").max = reach;
  }
  draw();
}

$("mode-xyz").onclick = () => { mode = "xyz"; $("xyz-panel").hidden = false; $("joint-panel").hidden = true; $("mode-xyz").className = "active"; $("mode-joint").className = ""; draw(); };
$("mode-joint").onclick = () => {
  mode = "joint"; $("xyz-panel").hidden = true; $("joint-panel").hidden = false; $("mode-joint").className = "active"; $("mode-xyz").className = "";
  if (pose) for (const [n, v] of Object.entries(pose.joints)) { const s = $(`j_${n}`); if (s) { s.value = v; $(`j_${n}_val`).textContent = deg(v); } }
  draw();
};

function setEstop(on) {
  estop = on;
  $("estop").className = on ? "engaged" : "";
  $("estop-state").textContent = on ? "E-STOP ENGAGED: no servo moves until released" : "e-stop released";
}
$("estop").onclick = () => { send({ t: "estop", on: true }); setEstop(true); };
$("release").onclick = () => { send({ t: "estop", on: false }); setEstop(false); };

const KEYS = { w: [1, 0, 0], arrowup: [1, 0, 0], s: [-1, 0, 0], arrowdown: [-1, 0, 0], a: [0, 1, 0], arrowleft: [0, 1, 0], d: [0, -1, 0], arrowright: [0, -1, 0], q: [0, 0, 1], e: [0, 0, -1] };
document.addEventListener("keydown", (ev) => {
  if (ev.target.tagName === "INPUT" && ev.target.type === "number") return;
  if (ev.target.id === "rec-task") { if (ev.key === "Enter") $("rec-start").click(); return; } // typing, not jogging
  const key = ev.key.toLowerCase();
  if (key === " ") { ev.preventDefault(); $("estop").click(); return; }
  if (calKey(ev)) return;
  const dir = KEYS[key];
  if (!dir || calOpen()) return; // the arm's jog keys do nothing while the Calibrate view is open
  ev.preventDefault();
  const step = parseFloat($("step").value);
  send({ t: "jog", d: dir.map((c) => c * step) });
});

// Gamepad: moves only while the deadman button (LB, button 4) is held.
const PAD = { deadman: 4, open: 0, close: 1, speed: 0.05, deadzone: 0.15 };
let lastPad = performance.now();
function pollPad() {
  const now = performance.now(), dt = Math.min(0.1, (now - lastPad) / 1000); lastPad = now;
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  const pad = pads && Array.from(pads).find((p) => p);
  if (!pad) { $("pad-state").textContent = "gamepad: none"; requestAnimationFrame(pollPad); return; }
  const held = pad.buttons[PAD.deadman] && pad.buttons[PAD.deadman].pressed;
  $("pad-state").textContent = `gamepad: ${pad.id || "connected"} — deadman ${held ? "HELD" : "released"}`;
  if (held && !calBusy()) {
    const ax = (i) => { const v = pad.axes[i] || 0; return Math.abs(v) < PAD.deadzone ? 0 : v; };
    const d = [-ax(1), -ax(0), -ax(3)].map((v) => v * PAD.speed * dt);
    if (d.some((v) => v !== 0)) send({ t: "jog", d });
    if (pad.buttons[PAD.open] && pad.buttons[PAD.open].pressed) send({ t: "gripper", v: 1 });
    if (pad.buttons[PAD.close] && pad.buttons[PAD.close].pressed) send({ t: "gripper", v: 0 });
  }
  requestAnimationFrame(pollPad);
}
window.addEventListener("gamepadconnected", () => { lastPad = performance.now(); });
requestAnimationFrame(pollPad);
setInterval(() => { if (document.hidden) pollPad(); }, 50);

// one dot per node heard on diagnostics (gui_bridge lists them by the names they run
// under, and the graph's expected ones as missing until heard)
function showStatus(m) {
  const box = $("nodes"), keep = new Set();
  for (const s of m.nodes) {
    const id = "status-" + s.name;
    keep.add(id);
    let el = $(id);
    if (!el) {
      el = document.createElement("span");
      el.id = id;
      el.append(Object.assign(document.createElement("span"), { className: "dot" }), document.createTextNode(s.name));
      el.append(" ");
    }
    box.append(el); // in the order listed
    el.querySelector(".dot").className = "dot " + (!s.up ? "down" : s.level === 0 ? "up" : "warn");
    el.title = (s.task ? s.task + ": " : "") + s.message + (s.hardware_id ? " (" + s.hardware_id + ")" : "");
  }
  for (const el of [...box.children]) if (!keep.has(el.id)) el.remove();
  $("last_rejection").textContent = m.last_rejection || "";
  $("controllers").textContent = m.controllers || "";
  // a refused switch, or the arm given back by itself (a calibration's lease ran out)
  $("last_switch").textContent = m.last_switch && m.last_switch !== "done" ? m.last_switch : "";
}

function showPose(m) {
  const tool = m.tool ? `  ${robot.eezybot ? "tool0" : robot.tool_link} (${m.tool.map((v) => v.toFixed(3)).join(", ")}) m` : "";
  if (robot.eezybot) {
    $("pose").textContent = `base ${deg(m.joints.base_joint)}  shoulder ${deg(m.joints.shoulder_joint)}  elbow ${deg(m.joints.elbow_joint)}` + tool;
  } else {
    $("pose").textContent = robot.joints.filter((j) => j.name in m.joints).map((j) => `${j.name.replace(/_joint$/, "")} ${deg(m.joints[j.name])}`).join("  ") + tool;
  }
}

function drawView(canvas, project, origin, scale, segments, marker, grid, step = 0.05, extent = 0.4) {
  const c = canvas.getContext("2d");
  c.clearRect(0, 0, canvas.width, canvas.height);
  c.strokeStyle = "#e4e4ea"; c.lineWidth = 1;
  for (let g = -extent; g <= extent + 1e-4; g += step) {
    const [gx, gy] = [origin[0] + g * scale, origin[1] - g * scale];
    c.beginPath(); c.moveTo(gx, 0); c.lineTo(gx, canvas.height); c.stroke();
    c.beginPath(); c.moveTo(0, gy); c.lineTo(canvas.width, gy); c.stroke();
  }
  c.fillStyle = "#999"; c.font = "11px sans-serif"; c.fillText(grid, 6, canvas.height - 6);
  c.lineCap = "round";
  const MAIN = /^(turntable|main_arm|forearm|front_plate|tool0|claw_)/;
  for (const [s, child] of segments) {
    const a = project(s.slice(0, 3)), b = project(s.slice(3, 6));
    const main = !robot.eezybot || MAIN.test(child);
    c.strokeStyle = main ? "#f07818" : "#3060d0"; c.lineWidth = main ? 6 : 3;
    c.beginPath(); c.moveTo(origin[0] + a[0] * scale, origin[1] - a[1] * scale); c.lineTo(origin[0] + b[0] * scale, origin[1] - b[1] * scale); c.stroke();
  }
  if (marker) {
    const p = project(marker);
    c.strokeStyle = reachable ? "#1a9850" : "#d73027"; c.lineWidth = 2;
    c.beginPath(); c.arc(origin[0] + p[0] * scale, origin[1] - p[1] * scale, 7, 0, 2 * Math.PI); c.stroke();
  }
}

// ---- 3D live view (three + urdf-loader, bundled as /viewer3d.js); the 2D views are the fallback
let view3d = null, urdf3d = null, envelope3d = undefined, show3d = true;
try {
  view3d = EezyViewer3D.create($("view3d"));
  window.__view3d = view3d;
} catch (e) {
  show3d = false;
  $("view3d-msg").textContent = "3D view unavailable here (" + e.message + "): the 2D views are shown.";
}
function showView(three) {
  show3d = three && view3d !== null;
  $("view3d").hidden = !show3d;
  $("view2d").hidden = show3d;
  $("show-3d").className = show3d ? "active" : ""; $("show-2d").className = show3d ? "" : "active";
  if (show3d) view3d.resize();
  draw();
}
$("show-3d").onclick = () => showView(true);
$("show-2d").onclick = () => showView(false);
// the URDF from robot_description (sent with the robot) and the workspace envelope
// (the pictures of the calibration and the leader's view draw it too, in 3D or 2D)
let urdfUrl = null, urdfText = null;
function scene3d(r) {
  // the URDF comes over HTTP (robot.urdf?rev=N), each new description with a new rev
  if (r.urdf && r.urdf !== urdfUrl) {
    urdfUrl = r.urdf;
    fetch(r.urdf, { cache: "no-store", headers: authHeaders() })
      .then((res) => { if (!res.ok) throw new Error("robot.urdf: HTTP " + res.status); return res.text(); })
      .then((text) => {
        if (urdfUrl !== r.urdf) return;
        urdfText = text;
        if (view3d) { view3d.setRobot(text); urdf3d = text; if (pose) posed3d(pose); }
        pictures.forEach((p) => p.draw());
      })
      .catch((e) => { if (view3d) $("view3d-msg").textContent = "3D view: " + e.message; });
  }
  if (view3d && r.envelope !== envelope3d) { envelope3d = r.envelope; view3d.setEnvelope(r.envelope || null); }
}
function posed3d(m) {
  if (!view3d || !urdf3d) return;
  const q = Object.assign({}, m.all || m.joints);
  if (m.gripper !== null && m.gripper !== undefined && !("gripper_joint" in q)) q.gripper_joint = m.gripper;
  view3d.setJoints(q);
}
showView(view3d !== null);

function draw() {
  if (view3d) {
    const t3 = mode === "xyz" ? sliderTarget() : target;
    view3d.setTarget(t3.every(isFinite) && (robot.eezybot || mode === "xyz") ? t3 : null, reachable);
  }
  if (show3d) return; // the 2D views are hidden: not drawn
  const segs = pose && pose.segments ? pose.segments : [];
  // the arm's plane: the base angle (EezyBot), else the tool's direction from the z axis
  const yaw = !pose ? 0 : robot.eezybot ? pose.joints.base_joint : pose.tool ? Math.atan2(pose.tool[1], pose.tool[0]) : 0;
  const t = mode === "xyz" ? sliderTarget() : target;
  // side view: horizontal = distance along the base direction, vertical = z
  const side = (p) => [p[0] * Math.cos(yaw) + p[1] * Math.sin(yaw), p[2]];
  // top view: x up, y left (looking down on base_link)
  const top = (p) => [-p[1], p[0]];
  // the Cartesian target; for an arm without a closed form only while it is being set
  const marker = t.every(isFinite) && (robot.eezybot || mode === "xyz") ? t : null;
  if (robot.eezybot) {
    drawView($("side"), side, [80, 310], 1000, segs, marker, "grid 5 cm");
    drawView($("top"), top, [170, 250], 850, segs, marker, "grid 5 cm");
  } else {  // any arm: scaled to its reach, the base in the middle
    const extent = Math.ceil(robot.reach * 10) / 10 + 0.1;
    drawView($("side"), side, [210, 320], 300 / robot.reach, segs, marker, "grid 10 cm", 0.1, extent);
    drawView($("top"), top, [170, 170], 160 / robot.reach, segs, marker, "grid 10 cm", 0.1, extent);
  }
}

// ---- touch: a joystick for x/y and a slider for z, moving only while MOVE (the deadman) is held
const TOUCH = { speed: 0.05 /* m/s at full deflection */, radius: 90 };
const touch = { held: false, stick: [0, 0], last: performance.now() };
function setHeld(on) {
  touch.held = on;
  $("deadman").className = on ? "held" : ""; $("deadman").setAttribute("aria-pressed", String(on));
  $("deadman").textContent = on ? "MOVING" : "hold to MOVE";
  $("touch").classList.toggle("disabled", !on);
  if (!on) { touch.stick = [0, 0]; knob(0, 0); $("tz").value = target[2]; }
}
const dm = $("deadman");
const capture = (el, ev) => { try { el.setPointerCapture(ev.pointerId); } catch (e) { /* a synthetic pointer */ } };
dm.addEventListener("pointerdown", (ev) => { ev.preventDefault(); capture(dm, ev); touch.last = performance.now(); setHeld(true); });
for (const end of ["pointerup", "pointercancel", "lostpointercapture"]) dm.addEventListener(end, () => setHeld(false));
dm.addEventListener("contextmenu", (ev) => ev.preventDefault());
window.addEventListener("blur", () => setHeld(false));
function knob(x, y) { $("knob").style.transform = `translate(${x * TOUCH.radius * 0.65}px, ${y * TOUCH.radius * 0.65}px)`; }
const stick = $("stick");
function stickAt(ev) {
  const r = stick.getBoundingClientRect();
  let x = (ev.clientX - (r.left + r.width / 2)) / (r.width / 2), y = (ev.clientY - (r.top + r.height / 2)) / (r.height / 2);
  const n = Math.hypot(x, y); if (n > 1) { x /= n; y /= n; }
  touch.stick = [x, y]; knob(x, y);
}
stick.addEventListener("pointerdown", (ev) => { ev.preventDefault(); capture(stick, ev); stickAt(ev); });
stick.addEventListener("pointermove", (ev) => { if (stick.hasPointerCapture(ev.pointerId)) stickAt(ev); });
for (const end of ["pointerup", "pointercancel"]) stick.addEventListener(end, () => { touch.stick = [0, 0]; knob(0, 0); });
$("tz").addEventListener("input", () => {
  const z = parseFloat($("tz").value);
  $("tz_val").textContent = z.toFixed(3);
  if (!touch.held) { $("tz").value = target[2]; return; }
  send({ t: "target", xyz: [target[0], target[1], z] });
});
function touchTick() {
  const now = performance.now(), dt = Math.min(0.1, (now - touch.last) / 1000); touch.last = now;
  if (touch.held && !calBusy()) {
    // up on the stick: away from the operator (+x); left: +y
    const [sx, sy] = touch.stick;
    const d = [-sy * TOUCH.speed * dt, -sx * TOUCH.speed * dt, 0];
    if (Math.abs(sx) > 0.08 || Math.abs(sy) > 0.08) send({ t: "jog", d });
  }
}
setInterval(touchTick, 20);
setHeld(false);

// ---- waypoint program (kept by gui_bridge, shared by every browser; files on its host)
let program = { points: [] }, player = null;
const progSend = (op, extra) => send(Object.assign({ t: "program", op }, extra || {}));
function showProgram(m) {
  if (m.program) program = m.program;
  player = m.player || null;
  if (m.files) {
    const sel = $("prog-files"), keep = sel.value;
    sel.innerHTML = '<option value="">load…</option>';
    for (const f of m.files) sel.append(Object.assign(document.createElement("option"), { value: f, textContent: f }));
    sel.value = keep;
  }
  if (m.message !== undefined) $("prog-msg").textContent = m.message || "";
  if (m.name && document.activeElement !== $("prog-name")) $("prog-name").value = m.name;
  renderProgram();
  // this page's save found a program of that name: replace it only if the operator says so
  if (pendingSave && m.confirm_overwrite === pendingSave) {
    const name = pendingSave;
    pendingSave = null;
    if (confirm("A program named " + name + " exists already. Replace it?")) progSend("save", { name, overwrite: true });
  } else if (m.message && !/^saving /.test(m.message)) {
    pendingSave = null;
  }
}
let pendingSave = null;
function renderProgram() {
  const list = $("prog-list"), el = document.activeElement;
  // not while a name or a dwell is being typed (rebuilt when it loses the focus)
  if (el && el.closest && el.closest("#prog-list") && (el.tagName === "INPUT" || el.tagName === "SELECT")) return;
  list.innerHTML = "";
  program.points.forEach((p, i) => {
    const li = document.createElement("li");
    if (player && player.index === i && ["moving", "dwelling"].includes(player.phase)) li.className = "current";
    const name = Object.assign(document.createElement("input"), { className: "name", value: p.name || `P${i + 1}`, title: `(${p.xyz.map((v) => v.toFixed(3)).join(", ")}) m` });
    name.addEventListener("change", () => progSend("rename", { i, name: name.value }));
    const dwell = Object.assign(document.createElement("input"), { className: "dwell", type: "number", min: 0, step: 0.1, value: p.dwell_s, title: "dwell (s)" });
    dwell.addEventListener("change", () => progSend("dwell", { i, s: parseFloat(dwell.value) }));
    const modeSel = document.createElement("select");
    for (const [v, label] of [["", "default"], ["joint", "joint"], ["line", "line"]]) modeSel.append(Object.assign(document.createElement("option"), { value: v, textContent: label }));
    modeSel.value = p.mode || ""; modeSel.title = "how to get there: line = the tool on a straight line (xyz_line_target); joint = xyz_target, as compute_ik's motion says (joint space unless started otherwise); default = joint here, line under gui_bridge play --line";
    modeSel.addEventListener("change", () => progSend("mode", { i, mode: modeSel.value || null }));
    const tools = document.createElement("span");
    const btn = (label, title, f) => { const b = Object.assign(document.createElement("button"), { textContent: label, title }); b.onclick = f; tools.append(b); };
    btn("↑", "earlier", () => progSend("move", { from: i, to: i - 1 }));
    btn("↓", "later", () => progSend("move", { from: i, to: i + 1 }));
    btn("✕", "delete", () => progSend("remove", { i }));
    li.append(Object.assign(document.createElement("span"), { textContent: i + 1 }), name, dwell, modeSel, tools);
    list.append(li);
  });
  const st = player ? `${player.phase}${player.index !== null && player.index !== undefined ? " at " + (player.index + 1) : ""}${player.loop ? ", loop " + player.loop : ""}${player.reason ? ": " + player.reason : ""}` : "";
  $("prog-state").textContent = `${program.points.length} point${program.points.length === 1 ? "" : "s"}${st ? " — " + st : ""}`;
}
$("prog-list").addEventListener("focusout", () => setTimeout(renderProgram, 0));
$("prog-teach").onclick = () => progSend("teach");
$("prog-play").onclick = () => progSend("play", { loop: $("prog-loop").checked });
$("prog-stop").onclick = () => progSend("stop");
$("prog-save").onclick = () => {
  pendingSave = $("prog-name").value.trim().replace(/\.csv$/, "");
  // the message shown until the node answers is about this save, not an earlier one
  $("prog-msg").textContent = `saving ${pendingSave}…`;
  progSend("save", { name: pendingSave });
};
$("prog-files").addEventListener("change", () => { const f = $("prog-files").value; if (f) { progSend("load", { name: f }); $("prog-name").value = f; } $("prog-files").value = ""; });

// ---- small pictures of the arm at a pose (the calibration's references, the leader arm): the
// URDF in 3D like the live view, else (no WebGL) drawView's 2D view of the URDF's kinematics
function makePicture(box) {
  let v = null, q = null, loaded = null;
  if (view3d) try { v = EezyViewer3D.create(box); } catch (e) { /* out of WebGL contexts: 2D */ }
  const canvas = v ? null : box.appendChild(Object.assign(document.createElement("canvas"), { width: 220, height: 180 }));
  const pic = {
    view: "side", // 2D only: "side" or "top"
    set(joints) { q = joints; pic.draw(); },
    draw() {
      if (!q) return;
      const all = withPassive(q);
      if (!v) { drawPicture(canvas, all, pic.view); return; }
      if (urdfText && loaded !== urdfText) {
        loaded = urdfText;
        try { v.setRobot(urdfText); } catch (e) { /* the live view says why */ }
      }
      v.setJoints(all);
    },
    resize() { if (v) v.resize(); },
  };
  pictures.push(pic);
  return pic;
}

// The EezyBot's passive and mimic joints follow from its actuated ones (the terms of
// eezybot_kinematics::PassiveJoints); joints given win. Any other arm: as given.
function withPassive(q) {
  if (!robot.eezybot || !("shoulder_joint" in q && "elbow_joint" in q)) return q;
  const a = q.shoulder_joint, phi = a + q.elbow_joint;
  const p = { wrist_joint: -phi, crank_joint: phi, drive_link_joint: -q.elbow_joint, level_link_joint: a, triangle_joint: -a, upper_link_joint: phi };
  if ("gripper_joint" in q) p.gripper_mimic_joint = -q.gripper_joint;
  return Object.assign(p, q);
}

// The URDF's joints, parsed once per text, for the 2D pictures' forward kinematics.
let urdfTree = { text: null, joints: [] };
function urdfJoints() {
  if (urdfTree.text === urdfText) return urdfTree.joints;
  const doc = new DOMParser().parseFromString(urdfText || "<robot/>", "text/xml");
  const one = (el, tag) => [...el.children].find((c) => c.tagName === tag) || null;
  const vec = (el, d) => (el && el.getAttribute("xyz") !== null ? el.getAttribute("xyz").trim().split(/\s+/).map(Number) : d);
  const attr = (el, name, d) => (el && el.getAttribute(name) !== null ? el.getAttribute(name) : d);
  const joints = [...doc.documentElement.children].filter((e) => e.tagName === "joint").map((j) => {
    const o = one(j, "origin"), m = one(j, "mimic");
    return {
      name: j.getAttribute("name"), type: j.getAttribute("type"),
      parent: attr(one(j, "parent"), "link", ""), child: attr(one(j, "child"), "link", ""),
      xyz: vec(o, [0, 0, 0]), rpy: attr(o, "rpy", "0 0 0").trim().split(/\s+/).map(Number), axis: vec(one(j, "axis"), [1, 0, 0]),
      mimic: m && { joint: m.getAttribute("joint"), k: +attr(m, "multiplier", 1), off: +attr(m, "offset", 0) },
    };
  });
  urdfTree = { text: urdfText, joints };
  return joints;
}
// 3x3 rotations, row-major
const mat = (A, B) => A.map((_, i) => { const r = i - (i % 3), c = i % 3; return A[r] * B[c] + A[r + 1] * B[3 + c] + A[r + 2] * B[6 + c]; });
const rot = (R, v) => [0, 3, 6].map((r) => R[r] * v[0] + R[r + 1] * v[1] + R[r + 2] * v[2]);
function axisAngle(axis, t) {
  const n = Math.hypot(...axis) || 1, [x, y, z] = axis.map((a) => a / n), c = Math.cos(t), s = Math.sin(t), k = 1 - c;
  return [c + x * x * k, x * y * k - z * s, x * z * k + y * s, y * x * k + z * s, c + y * y * k, y * z * k - x * s, z * x * k - y * s, z * y * k + x * s, c + z * z * k];
}
const rpyRot = ([r, p, y]) => mat(axisAngle([0, 0, 1], y), mat(axisAngle([0, 1, 0], p), axisAngle([1, 0, 0], r)));
// Segments (parent origin -> child origin, child link) at joint values q, like pose.segments.
function urdfSegments(q) {
  const joints = urdfJoints(), frames = {}, children = new Set(joints.map((j) => j.child));
  for (const j of joints) if (!children.has(j.parent)) frames[j.parent] = { R: [1, 0, 0, 0, 1, 0, 0, 0, 1], p: [0, 0, 0] };
  const value = (j) => (j.name in q ? q[j.name] : j.mimic && j.mimic.joint in q ? j.mimic.k * q[j.mimic.joint] + j.mimic.off : 0);
  for (let grew = true; grew;) {
    grew = false;
    for (const j of joints) {
      const f = frames[j.parent];
      if (!f || frames[j.child]) continue;
      let R = mat(f.R, rpyRot(j.rpy)), p = rot(f.R, j.xyz).map((v, i) => v + f.p[i]);
      if (j.type === "revolute" || j.type === "continuous") R = mat(R, axisAngle(j.axis, value(j)));
      else if (j.type === "prismatic") p = rot(R, j.axis.map((a) => a * value(j))).map((v, i) => v + p[i]);
      frames[j.child] = { R, p };
      grew = true;
    }
  }
  return joints.filter((j) => frames[j.parent] && frames[j.child])
    .map((j) => [frames[j.parent].p.concat(frames[j.child].p), j.child])
    .filter(([s]) => Math.hypot(s[3] - s[0], s[4] - s[1], s[5] - s[2]) > 1e-6);
}
function drawPicture(canvas, q, view) {
  const segs = urdfText ? urdfSegments(q) : [], reach = robot.eezybot ? 0.3 : robot.reach, scale = 150 / reach;
  const [step, extent, grid] = robot.eezybot ? [0.05, 0.4, "grid 5 cm"] : [0.1, Math.ceil(reach * 10) / 10 + 0.1, "grid 10 cm"];
  if (view === "top") { drawView(canvas, (p) => [-p[1], p[0]], [110, 165], scale, segs, null, "top, " + grid, step, extent); return; }
  const yaw = robot.eezybot ? q.base_joint || 0 : 0;
  drawView(canvas, (p) => [p[0] * Math.cos(yaw) + p[1] * Math.sin(yaw), p[2]], [40, 170], scale, segs, null, "side, " + grid, step, extent);
}

// ---- calibration wizard: gui_bridge runs it and tells every browser where it is; this view
// shows that and sends the operator's operations
const calBusy = () => !!(cal && cal.active && cal.arm === "follower"); // the servos are the wizard's
const calOpen = () => !$("calibrate").hidden;
const calSend = (op, extra) => {
  calRefusal = null; calSentAt = performance.now();
  $("cal-error").textContent = cal && cal.error || "";
  send(Object.assign({ t: "calibrate", op }, extra || {}));
};
// a refusal within 2 s of this page's last calibrate request answers that request
const calRefusedNow = () => performance.now() - calSentAt < 2000;
// after the marks (gui_bridge says "saving" and "done"; the contract, "saved" and "tested")
const AFTER_SAVE = ["saving", "saved", "testing", "tested", "done", "failed"];
const num = (v, digits) => (typeof v === "number" && isFinite(v) ? v.toFixed(digits) : "–");
const refsOf = (s) => [s.references[0], s.use_alternative && s.alternative_b ? s.alternative_b : s.references[1]].filter(Boolean);
const short = (v, digits) => (typeof v === "number" && isFinite(v) ? String(Number(v.toFixed(digits))) : "–");
const fmtInput = (s, v) => (s.unit === "opening" ? "opening " + short(v, 2) : short(v, 1) + "°");
const fmtMark = (v) => (v === null || v === undefined ? "not marked" : cal.arm === "leader" ? short(v, 1) + " counts" : num(v, 1) + "°");
function fmtDerived(s) {
  const d = s.derived;
  if ("offset_deg" in d) return `offset ${num(d.offset_deg, 1)}°, gain ${num(d.gain, 3)} (×${num(d.gain_ratio, 2)} of shipped), ${d.direction}`;
  return `${short(d.counts_a, 1)} counts = ${fmtInput(s, d.input_a)}, ${short(d.counts_b, 1)} counts = ${fmtInput(s, d.input_b)}`;
}

function openCalibrate(on) {
  $("calibrate").hidden = !on;
  $("show-calibrate").className = on ? "active" : "";
  renderCalibration();
  if (on) $("calibrate").scrollIntoView({ block: "nearest" });
}
$("show-calibrate").onclick = () => openCalibrate(true);
$("cal-close").onclick = () => openCalibrate(false);
// a button clicked with the mouse gives the focus back, so Enter marks rather than clicks it again
const calButton = (id, f) => { $(id).onclick = (ev) => { if (ev.detail) $(id).blur(); f(); }; };
calButton("cal-start-follower", () => calSend("start", { arm: "follower" }));
calButton("cal-start-leader", () => calSend("start", { arm: "leader" }));
for (const [id, sign, size] of [["cal-jog-fine-minus", -1, "fine_deg"], ["cal-jog-fine-plus", 1, "fine_deg"], ["cal-jog-coarse-minus", -1, "coarse_deg"], ["cal-jog-coarse-plus", 1, "coarse_deg"]]) {
  calButton(id, () => calSend("jog", { deg: sign * jogSize(size) }));
}
for (const op of ["mark", "back", "save", "test", "finish", "cancel"]) calButton("cal-" + op, () => calSend(op));
$("cal-alternative").addEventListener("change", () => calSend("alternative", { on: $("cal-alternative").checked }));
function jogSize(size) { const j = cal && cal.jog; return j && j[size] > 0 ? j[size] : size === "fine_deg" ? 0.5 : 5; }

// [ ] fine, { } coarse, Enter marks: only while the view is open and nothing is being typed
const CAL_KEYS = { "[": "cal-jog-fine-minus", "]": "cal-jog-fine-plus", "{": "cal-jog-coarse-minus", "}": "cal-jog-coarse-plus", Enter: "cal-mark" };
function calKey(ev) {
  const id = CAL_KEYS[ev.key], el = ev.target;
  if (!id || !calOpen() || ev.ctrlKey || ev.metaKey || ev.altKey) return false;
  const typing = (el.tagName === "INPUT" && !["checkbox", "radio", "range", "button"].includes(el.type)) || el.tagName === "SELECT" || el.tagName === "TEXTAREA" || el.isContentEditable;
  if (typing || (ev.key === "Enter" && (el.tagName === "BUTTON" || el.tagName === "A"))) return false;
  ev.preventDefault();
  $(id).click(); // nothing when disabled
  return true;
}

function showCalibration(m) {
  const was = cal && cal.active;
  cal = m;
  if (m.active && !was) openCalibrate(true); // started here or in another browser
  else renderCalibration();
}

function renderCalibration() {
  document.body.classList.toggle("cal-busy", calBusy());
  const c = cal || { active: false, steps: [] }, steps = c.steps || [], s = steps[c.step] || null;
  const active = !!c.active, follower = c.arm !== "leader", phase = c.phase || "idle";
  $("cal-begin").hidden = active;
  $("cal-run").hidden = !active;
  $("cal-head").textContent = !active ? "no calibration running"
    : `${follower ? "arm servos" : "leader arm"} — step ${(c.step || 0) + 1} of ${steps.length}${s ? ": " + s.title : ""} — ${phase}`;
  $("cal-instruction").textContent = c.instruction || (active ? "" : "Calibrate the arm's servos (it moves one servo at a time; keep the e-stop at hand) or the leader arm's potentiometers.");
  $("cal-error").textContent = calRefusal || c.error || "";
  if (!active) return;
  // the active servo
  $("cal-servo").hidden = !follower;
  $("cal-commanded").textContent = typeof c.commanded_deg === "number" ? num(c.commanded_deg, 1) + "°" : "–";
  $("cal-state").textContent = typeof c.state_deg === "number" ? num(c.state_deg, 1) + "°" : "–";
  $("cal-range").textContent = c.jog ? `jog range ${num(c.jog.min_deg, 1)}° to ${num(c.jog.max_deg, 1)}°` : "";
  showCounts(follower ? null : c.counts, s);
  const jogging = follower && phase === "jog";
  $("cal-jog").hidden = !follower;
  for (const [id, sign, size] of [["cal-jog-fine-minus", "−", "fine_deg"], ["cal-jog-fine-plus", "+", "fine_deg"], ["cal-jog-coarse-minus", "−", "coarse_deg"], ["cal-jog-coarse-plus", "+", "coarse_deg"]]) {
    $(id).disabled = !jogging;
    $(id).textContent = sign + jogSize(size) + "°";
  }
  $("cal-mark").disabled = phase !== "jog";
  const marked = steps.some((x) => (x.marks || []).some((v) => v !== null && v !== undefined));
  $("cal-back").disabled = !(["jog", "review", "reading"].includes(phase) && (marked || c.step > 0 || phase === "reading"));
  $("cal-alternative-box").hidden = !(s && s.alternative_b);
  if (s && s.alternative_b) {
    $("cal-alternative").checked = !!s.use_alternative;
    $("cal-alternative").disabled = phase !== "jog";
    $("cal-alternative-text").textContent = `B cannot be reached: use ${fmtInput(s, s.alternative_b.input)} instead`;
  }
  const derived = steps.length > 0 && steps.every((x) => x.derived && !x.error);
  $("cal-save").disabled = !derived || AFTER_SAVE.includes(phase);
  $("cal-test").hidden = !follower;
  $("cal-test").disabled = !(c.saved && c.saved.path) || phase === "saving" || phase === "failed";
  $("cal-finish").disabled = !(c.saved || ["done", "tested", "failed"].includes(phase)) || phase === "saving";
  showCalSteps(c, steps);
  showSaved(c);
  $("cal-test-state").textContent = c.test ? `test move: ${c.test.description} — ${c.test.done ? "done" : phase === "testing" ? "moving…" : "not done"}` : "";
  if (calOpen()) showCalPictures(c, s);
}

function showCounts(counts, s) {
  const box = $("cal-counts");
  box.hidden = !counts;
  if (!counts) return;
  box.innerHTML = "";
  counts.forEach((v, i) => box.append(Object.assign(document.createElement("span"), {
    textContent: `A${i} ${short(v, 1)}`, className: s && s.channel === i ? "current" : "" })));
}

function showCalSteps(c, steps) {
  const list = $("cal-steps");
  list.innerHTML = "";
  steps.forEach((s, i) => {
    const li = document.createElement("li");
    li.className = [i === c.step ? "current" : "", s.error ? "bad" : s.derived ? "done" : ""].join(" ").trim();
    const line = (className, textContent) => li.append(Object.assign(document.createElement("div"), { className, textContent }));
    line("cal-title", `${i + 1}. ${s.title}`);
    refsOf(s).forEach((r, k) => line("small", `${"AB"[k]} at ${fmtInput(s, r.input)}: ${fmtMark((s.marks || [])[k])}`));
    if (s.derived) line("", fmtDerived(s));
    if (s.error) line("cal-err", s.error);
    if (i === c.step && s.holds && s.holds.length) line("small", "held: " + s.holds.join(", "));
    list.append(li);
  });
}

function showSaved(c) {
  const box = $("cal-saved");
  box.innerHTML = "";
  if (!c.saved) return;
  const line = (className, textContent) => box.append(Object.assign(document.createElement("div"), { className, textContent }));
  const sv = c.saved, applied = sv.applied || [], failed = sv.failed || [];
  if (sv.path) line("", `saved to ${sv.path}` + (sv.backup ? ` (the previous file kept as ${sv.backup})` : " (no previous file)"));
  else line("bad", "not saved");
  line("", "applied to: " + (applied.length ? applied.join(", ") : "no node"));
  if (failed.length) line("bad", "not applied: " + failed.join("; "));
}

// The references of the active step, A and B side by side, the next one to mark highlighted;
// after the save, the test move's pose.
let calPics = [];
function showCalPictures(c, s) {
  const shown = [], testing = !!c.test && AFTER_SAVE.includes(c.phase);
  if (testing) {
    shown.push({ title: "test move", text: c.test.description, pose: c.test.pose, note: c.test.done ? "done" : "" });
  } else if (s) {
    refsOf(s).forEach((r, k) => {
      const mark = (s.marks || [])[k], done = mark !== null && mark !== undefined;
      shown.push({ title: `${"AB"[k]}: ${s.title} at ${fmtInput(s, r.input)}`, text: r.description, pose: r.pose,
                   next: k === c.reference && !done, note: done ? "marked at " + fmtMark(mark) : k === c.reference ? "mark this next" : "" });
    });
  }
  const box = $("cal-picture");
  while (calPics.length < shown.length) {
    const cell = Object.assign(document.createElement("div"), { className: "cal-pic" });
    const title = document.createElement("b"), text = document.createElement("div"), note = document.createElement("div");
    const holder = Object.assign(document.createElement("div"), { className: "pic" });
    note.className = "small";
    cell.append(title, holder, text, note);
    box.append(cell);
    calPics.push({ cell, title, text, note, pic: makePicture(holder) });
  }
  calPics.forEach((p, i) => {
    const x = shown[i];
    p.cell.hidden = !x;
    if (!x) return;
    p.cell.className = "cal-pic" + (x.next ? " next" : "");
    p.title.textContent = x.title;
    p.text.textContent = x.text || "";
    p.note.textContent = x.note + (urdfText ? "" : " (no URDF yet: robot_description not heard)");
    // 2D: the base turns and the claw opens in the horizontal plane, seen from above
    p.pic.view = !testing && s && (s.servo === "base" || s.servo === "gripper") ? "top" : "side";
    p.pic.set(x.pose || {});
  });
}

// ---- the leader arm beside the follower: shown while its joint_states come
let leaderPic = null, leaderTimer = null;
function jointsText(q) {
  const names = robot.eezybot ? ACTUATED.filter((n) => n in q) : Object.keys(q);
  return names.map((n) => `${n.replace(/_joint$/, "")} ${deg(q[n])}`).join("  ");
}
const ACTUATED = ["base_joint", "shoulder_joint", "elbow_joint", "gripper_joint"];
function showLeader(m) {
  const q = m.joints || {};
  if ($("leader-view").hidden) {
    $("leader-view").hidden = false;
    $("leader-pose").hidden = false;
    if (!leaderPic) leaderPic = makePicture($("leader-3d"));
    leaderPic.resize();
  }
  leaderPic.set(q);
  $("leader-state").textContent = m.deadman ? "deadman held — following" : m.deadman === false ? "deadman released — holding" : "deadman not heard — holding";
  $("leader-state").className = m.deadman ? "held" : "";
  $("leader-pose").textContent = "leader: " + jointsText(q) + (m.deadman ? "" : " (not followed)");
  clearTimeout(leaderTimer);
  leaderTimer = setTimeout(() => { $("leader-view").hidden = true; $("leader-pose").hidden = true; }, 2000);
}

connect();
draw();

// The recording card: the recorder node as gui_bridge reports it (`recorder` messages:
// its diagnostics, the call in flight, the last call's outcome, which buttons work). The
// elapsed time ticks here between the recorder's reports (2 a second while recording).
let rec = null, recAt = 0, recSentAt = -1e9, recRefusal = null, recTaskEdited = false;
const recRefusedNow = () => performance.now() - recSentAt < 2000;
function showRecorder(m) {
  rec = m; recAt = performance.now();
  renderRecorder();
}
function recSend(op, extra) {
  recRefusal = null; recSentAt = performance.now();
  send(Object.assign({ t: "record", op }, extra || {}));
  renderRecorder();
}
$("rec-task").addEventListener("input", () => { recTaskEdited = true; });
$("rec-start").onclick = () => { if (rec && rec.can_start) recSend("start", { task: $("rec-task").value }); };
$("rec-save").onclick = () => { if (rec && rec.can_save) recSend("save"); };
$("rec-discard").onclick = () => { if (rec && rec.can_discard && confirm("Discard this episode?")) recSend("discard"); };
// seconds since the episode started: the last report's, plus how old it was when sent, plus the time since
function recElapsed() {
  if (!rec || typeof rec.elapsed_s !== "number") return null;
  if (rec.state !== "recording") return rec.elapsed_s;
  return rec.elapsed_s + (rec.age_s || 0) + (performance.now() - recAt) / 1000;
}
function clock(s) {
  if (s === null) return "–";
  const m = Math.floor(s / 60);
  return m + ":" + (s - 60 * m).toFixed(1).padStart(4, "0");
}
const recNum = (v) => (typeof v === "number" ? String(v) : "–");
function renderRecorder() {
  const m = rec, state = m && m.state, up = !!(m && m.up);
  const recording = up && state === "recording", saving = up && state === "saving";
  const stateEl = $("rec-state");
  stateEl.textContent = !m || !up ? (m && m.state ? "not reporting" : "no recorder") : m.busy ? m.busy + "…" : state;
  stateEl.className = "rec-state " + (!up ? "" : m.level === 1 && state !== "stopped" ? "warn " + state : state);
  $("rec-note").textContent = (m && m.note) || "";
  const task = $("rec-task");
  task.disabled = !(m && m.can_start);
  if (m && m.task && (!recTaskEdited || recording) && document.activeElement !== task) task.value = m.task;
  $("rec-start").disabled = !(m && m.can_start);
  $("rec-save").disabled = !(m && m.can_save);
  $("rec-discard").disabled = !(m && m.can_discard);
  $("rec-start").textContent = m && m.busy === "start" ? "● starting…" : "● Record";
  $("rec-save").textContent = m && m.busy === "save" ? "saving…" : "Save";
  document.querySelector("#record .rec-facts").hidden = !(m && m.state); // nothing heard yet: nothing to count
  $("rec-episodes").textContent = recNum(m && m.episodes);
  $("rec-episode").textContent = recNum(m && m.episode);
  $("rec-frames").textContent = recNum(m && m.frames);
  const dropped = m && typeof m.dropped === "number" ? m.dropped : null;
  $("rec-dropped").textContent = dropped === null ? "–" : dropped + (typeof m.dropped_total === "number" ? " (" + m.dropped_total + " in all)" : "");
  $("rec-dropped").className = dropped ? "bad" : "";
  const call = $("rec-call");
  if (recRefusal) { call.textContent = recRefusal; call.className = "bad"; }
  else if (m && m.call) { call.textContent = m.call.op + ": " + m.call.text; call.className = m.call.ok ? "ok" : "bad"; }
  else { call.textContent = ""; call.className = ""; }
  $("rec-reason").textContent = m && m.reason ? (state === "waiting" ? "waiting: " : "stopped: ") + m.reason : "";
  $("rec-message").textContent = m && m.message ? m.message + (m.last ? " · last: " + m.last : "") : "";
  $("rec-root").textContent = m && m.root ? "dataset " + m.root + (m.cameras ? " · cameras " + m.cameras : "") + (m.fps ? " · " + m.fps + " fps" : "") : "";
  document.body.classList.toggle("recording", recording);
  $("rec-banner").hidden = !(recording || saving);
  $("rec-banner").className = saving ? "saving" : "";
  tickRecorder();
}
function tickRecorder() {
  if (!rec) return;
  const e = clock(recElapsed());
  $("rec-elapsed").textContent = e;
  if (rec.up && (rec.state === "recording" || rec.state === "saving")) {
    $("rec-banner-text").textContent = (rec.state === "saving" ? "saving episode " : "REC episode ") + recNum(rec.episode) + " · " + e + (rec.task ? " · " + rec.task : "");
  }
}
setInterval(tickRecorder, 100);
renderRecorder();
