"use strict";
const $ = (id) => document.getElementById(id);
let ws = null, hello = null, target = [0.186, 0, 0.229], reachable = true, pose = null, estop = false, mode = "xyz";
// the arm (from robot_description, else the EezyBot): joint sliders, reach, EezyBot or not
let robot = { name: "eezybot", eezybot: true, joints: [], reach: 0.33, from_urdf: false };
const send = (msg) => { if (ws && ws.readyState === 1) ws.send(JSON.stringify(msg)); };

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
  ws.onopen = () => { opened = true; showAccess(""); $("ws-dot").className = "dot up"; };
  ws.onclose = async (ev) => {
    $("ws-dot").className = "dot down";
    if (ev.code === 1009) showAccess("The panel closed the connection: " + ev.reason);
    const refused = !opened && await explainRefusal();
    retry = setTimeout(connect, refused ? 5000 : 1000);
  };
  ws.onmessage = (ev) => handle(JSON.parse(ev.data));
}

function handle(m) {
  switch (m.t) {
    case "hello": hello = m; target = m.target; applyRobot(m.robot); setSliders(target); if (m.pose) handle(m.pose); if (m.program) showProgram(m.program); break;
    case "robot": applyRobot(m.robot); break;
    case "ack": reachable = true; target = m.target; showReach(true, ""); if (mode === "xyz") setSliders(target, true); break;
    case "refused": reachable = false; showReach(false, m.reason); break;
    case "check": showReach(m.reachable, m.reason || ""); break;
    case "pose": pose = m; draw(); showPose(m); posed3d(m); break;
    case "program": showProgram(m); break;
    case "status": showStatus(m); break;
    case "latency": $("latency").textContent = m.ms.toFixed(1) + " ms (median " + m.median_ms.toFixed(1) + ")"; break;
    case "estop": setEstop(m.on); break;
    case "sent": window.__sent = (window.__sent || 0) + 1; break;
  }
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
  const key = ev.key.toLowerCase();
  if (key === " ") { ev.preventDefault(); $("estop").click(); return; }
  const dir = KEYS[key];
  if (!dir) return;
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
  if (held) {
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
let urdfUrl = null;
function scene3d(r) {
  if (!view3d) return;
  // the URDF comes over HTTP (robot.urdf?rev=N), each new description with a new rev
  if (r.urdf && r.urdf !== urdfUrl) {
    urdfUrl = r.urdf;
    fetch(r.urdf, { cache: "no-store", headers: authHeaders() })
      .then((res) => { if (!res.ok) throw new Error("robot.urdf: HTTP " + res.status); return res.text(); })
      .then((text) => { if (urdfUrl !== r.urdf) return; view3d.setRobot(text); urdf3d = text; if (pose) posed3d(pose); })
      .catch((e) => { $("view3d-msg").textContent = "3D view: " + e.message; });
  }
  if (r.envelope !== envelope3d) { envelope3d = r.envelope; view3d.setEnvelope(r.envelope || null); }
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
  if (touch.held) {
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
    if (player && player.index === i && ["moving", "dwelling", "setting_mode"].includes(player.phase)) li.className = "current";
    const name = Object.assign(document.createElement("input"), { className: "name", value: p.name || `P${i + 1}`, title: `(${p.xyz.map((v) => v.toFixed(3)).join(", ")}) m` });
    name.addEventListener("change", () => progSend("rename", { i, name: name.value }));
    const dwell = Object.assign(document.createElement("input"), { className: "dwell", type: "number", min: 0, step: 0.1, value: p.dwell_s, title: "dwell (s)" });
    dwell.addEventListener("change", () => progSend("dwell", { i, s: parseFloat(dwell.value) }));
    const modeSel = document.createElement("select");
    for (const [v, label] of [["", "default"], ["joint", "joint"], ["line", "line"]]) modeSel.append(Object.assign(document.createElement("option"), { value: v, textContent: label }));
    modeSel.value = p.mode || ""; modeSel.title = "move mode: joint space, or a straight Cartesian line";
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

connect();
draw();
