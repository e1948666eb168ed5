// koopguide dashboard page: plain JavaScript and a canvas, no libraries.
// Data arrive over the WebSocket /ws (see koopguide/dashboard/server.py for the messages).
// Frame: local NED metres; on screen North is up and East is right (x = E, y = -N).
"use strict";

const ARROW_SECONDS = 10;          // a velocity arrow is this many seconds of travel long
const PALETTE = ["#e63946", "#2a9d8f", "#f4a261", "#6a4c93", "#1982c4", "#8ac926", "#ff595e", "#5e548e"];

const vehicles = new Map();        // id -> {msg, trail: [[N, E]], arrivedAt: ms, updates, heading}
const fields = new Map();          // id -> field message
const pending = new Map();         // id -> {action, nonce}
let controlAllowed = false;
let malformed = 0;                 // statuses the server refused (decode_status)
let frames = 0;

const canvas = document.getElementById("map");
const ctx = canvas.getContext("2d");
const tbody = document.querySelector("#vehicles tbody");

// ------------------------------------------------------------------------------- data in
function connect() {
  const link = document.getElementById("link");
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  ws.onopen = () => { link.textContent = "live"; link.className = "link up"; link.dataset.state = "up"; };
  ws.onclose = () => {
    link.textContent = "reconnecting"; link.className = "link down"; link.dataset.state = "down";
    setTimeout(connect, 1000);
  };
  ws.onmessage = (event) => receive(JSON.parse(event.data));
}

function receive(msg) {
  if (typeof msg.malformed === "number") malformed = msg.malformed;
  if (msg.type === "hello") {
    vehicles.clear();
    fields.clear();
    controlAllowed = msg.control;
    document.getElementById("control").hidden = !controlAllowed;
    for (const v of msg.vehicles) update(v, v.trail || []);
    for (const f of msg.fields) fields.set(f.vehicle_id, f);
  } else if (msg.type === "status") {
    for (const v of msg.vehicles) update(v, null);
  } else if (msg.type === "field") {
    fields.set(msg.vehicle_id, msg);
  }
}

function update(v, trail) {
  let entry = vehicles.get(v.vehicle_id);
  if (!entry) {
    entry = {trail: [], updates: 0, heading: null};
    vehicles.set(v.vehicle_id, entry);
  }
  if (trail) entry.trail = trail.slice();
  const s = v.status;
  if (s && (!entry.msg || !entry.msg.status || s.seq !== entry.msg.status.seq)) {
    entry.updates += 1;
    entry.arrivedAt = performance.now();
    if (!trail && s.position_ned) {
      entry.trail.push(s.position_ned);
      if (entry.trail.length > 600) entry.trail.shift();
    }
    const vel = s.velocity_ned;
    if (typeof s.heading_rad === "number") entry.heading = s.heading_rad;  // when the service sends it
    else if (vel && Math.hypot(vel[0], vel[1]) > 0.02) entry.heading = Math.atan2(vel[1], vel[0]);
  }
  entry.msg = v;
}

// --------------------------------------------------------------------------------- map
function colour(id) {
  const ids = [...vehicles.keys()].sort();
  return PALETTE[Math.max(0, ids.indexOf(id)) % PALETTE.length];
}

function extent() {
  const pts = [];
  for (const f of fields.values()) if (f.corners_ned) pts.push(...f.corners_ned);
  for (const [id, v] of vehicles) {
    pts.push(...v.trail);
    const s = v.msg && v.msg.status;
    if (s && s.goal_ned) pts.push(s.goal_ned);
    if (s && s.position_ned) pts.push(s.position_ned);
  }
  if (!pts.length) return null;
  let [n0, e0, n1, e1] = [Infinity, Infinity, -Infinity, -Infinity];
  for (const [n, e] of pts) { n0 = Math.min(n0, n); n1 = Math.max(n1, n); e0 = Math.min(e0, e); e1 = Math.max(e1, e); }
  const pad = 0.08 * Math.max(n1 - n0, e1 - e0, 1.0);
  return {n0: n0 - pad, n1: n1 + pad, e0: e0 - pad, e1: e1 + pad};
}

function projection(box) {
  const scale = Math.min(canvas.width / (box.e1 - box.e0), canvas.height / (box.n1 - box.n0));
  const ox = (canvas.width - scale * (box.e1 - box.e0)) / 2, oy = (canvas.height - scale * (box.n1 - box.n0)) / 2;
  return {scale, xy: ([n, e]) => [ox + (e - box.e0) * scale, oy + (box.n1 - n) * scale]};
}

function arrow(p, [x1, y1], colourText, width) {
  const [x0, y0] = p;
  const a = Math.atan2(y1 - y0, x1 - x0), len = Math.hypot(x1 - x0, y1 - y0);
  if (len < 2) return;
  ctx.strokeStyle = ctx.fillStyle = colourText;
  ctx.lineWidth = width;
  ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke();
  const h = Math.min(8, len / 2);
  ctx.beginPath(); ctx.moveTo(x1, y1);
  ctx.lineTo(x1 - h * Math.cos(a - 0.4), y1 - h * Math.sin(a - 0.4));
  ctx.lineTo(x1 - h * Math.cos(a + 0.4), y1 - h * Math.sin(a + 0.4));
  ctx.closePath(); ctx.fill();
}

function gridLines(box, P) {
  const span = Math.max(box.n1 - box.n0, box.e1 - box.e0);
  const step = span > 20 ? 5 : span > 8 ? 2 : span > 3 ? 1 : 0.5;
  ctx.strokeStyle = "#eef"; ctx.fillStyle = "#99a"; ctx.lineWidth = 1; ctx.font = "11px sans-serif";
  for (let n = Math.ceil(box.n0 / step) * step; n <= box.n1; n += step) {
    const [x0, y] = P.xy([n, box.e0]), [x1] = P.xy([n, box.e1]);
    ctx.beginPath(); ctx.moveTo(x0, y); ctx.lineTo(x1, y); ctx.stroke();
    ctx.fillText(`N ${n.toFixed(1)}`, 4, y - 2);
  }
  for (let e = Math.ceil(box.e0 / step) * step; e <= box.e1; e += step) {
    const [x, y0] = P.xy([box.n1, e]), [, y1] = P.xy([box.n0, e]);
    ctx.beginPath(); ctx.moveTo(x, y0); ctx.lineTo(x, y1); ctx.stroke();
    ctx.fillText(`E ${e.toFixed(1)}`, x + 2, canvas.height - 4);
  }
}

function fitCanvas() {  // the canvas fills its panel; its drawing buffer follows (no blurry scaling)
  const width = Math.max(300, Math.floor(canvas.parentElement.clientWidth));
  const height = Math.max(300, Math.floor(window.innerHeight - canvas.getBoundingClientRect().top - 60));
  if (canvas.width !== width || canvas.height !== height) { canvas.width = width; canvas.height = height; }
}

function draw() {
  fitCanvas();
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  const box = extent();
  let lines = 0, boats = 0;
  if (box) {
    const P = projection(box);
    gridLines(box, P);
    for (const f of fields.values()) {           // streamlines, with a small arrow head halfway along
      ctx.strokeStyle = "#b8bcc8"; ctx.lineWidth = 1;
      for (const line of f.streamlines || []) {
        ctx.beginPath();
        line.forEach((p, i) => { const [x, y] = P.xy(p); if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
        ctx.stroke();
        const k = Math.floor(line.length / 2);
        if (k > 0) arrow(P.xy(line[k - 1]), P.xy(line[k]), "#b8bcc8", 1);
        lines += 1;
      }
    }
    for (const [id, v] of vehicles) {
      const s = v.msg && v.msg.status, c = colour(id);
      if (!s) continue;
      const radius = fields.get(id) && fields.get(id).arrival_radius_m;
      if (s.goal_ned) {                            // goal and arrival radius
        const [gx, gy] = P.xy(s.goal_ned);
        ctx.strokeStyle = c; ctx.lineWidth = 2;
        ctx.beginPath(); ctx.moveTo(gx - 6, gy - 6); ctx.lineTo(gx + 6, gy + 6);
        ctx.moveTo(gx - 6, gy + 6); ctx.lineTo(gx + 6, gy - 6); ctx.stroke();
        if (radius) {
          ctx.setLineDash([4, 3]); ctx.beginPath(); ctx.arc(gx, gy, radius * P.scale, 0, 2 * Math.PI);
          ctx.stroke(); ctx.setLineDash([]);
        }
      }
      if (v.trail.length > 1) {                    // trail
        ctx.strokeStyle = c; ctx.globalAlpha = 0.6; ctx.lineWidth = 1.5; ctx.beginPath();
        v.trail.forEach((p, i) => { const [x, y] = P.xy(p); if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
        ctx.stroke(); ctx.globalAlpha = 1;
      }
      if (!s.position_ned) continue;
      const p = s.position_ned, at = P.xy(p);
      const tip = (vel) => P.xy([p[0] + ARROW_SECONDS * vel[0], p[1] + ARROW_SECONDS * vel[1]]);
      if (s.current_ned) arrow(at, tip(s.current_ned), "#0077b6", 2);
      arrow(at, tip(s.cmd_velocity_ned), "#d62828", 2);
      const h = v.heading === null ? 0 : v.heading;  // heading_rad, else course over ground; north until it moves
      ctx.save(); ctx.translate(at[0], at[1]); ctx.rotate(h);  // canvas angle from up = compass heading
      ctx.fillStyle = c; ctx.strokeStyle = "#222"; ctx.lineWidth = 1;
      ctx.beginPath(); ctx.moveTo(0, -11); ctx.lineTo(6, 8); ctx.lineTo(0, 4); ctx.lineTo(-6, 8); ctx.closePath();
      ctx.fill(); ctx.stroke(); ctx.restore();
      ctx.fillStyle = "#222"; ctx.font = "12px sans-serif"; ctx.fillText(id, at[0] + 9, at[1] - 9);
      boats += 1;
    }
  }
  frames += 1;
  canvas.dataset.frames = frames;
  canvas.dataset.streamlines = lines;
  canvas.dataset.boats = boats;
  requestAnimationFrame(draw);
}

// ------------------------------------------------------------------------------- table
function fmt(x, digits) { return x === null || x === undefined ? "-" : x.toFixed(digits); }

function row(id) {
  let tr = tbody.querySelector(`tr[data-vehicle="${CSS.escape(id)}"]`);
  if (!tr) {
    tr = document.createElement("tr");
    tr.dataset.vehicle = id;
    tr.id = `vehicle-${id}`;
    tr.innerHTML = "<td class=id></td><td class=state></td><td class=mode></td><td class=armed></td>" +
      "<td class=dist></td><td class=speed></td><td class=fixage></td><td class=msgage></td><td class=loop></td>" +
      "<td class=ctl></td>";
    const ids = [...tbody.children].map((r) => r.dataset.vehicle);
    const before = [...tbody.children][ids.findIndex((other) => other > id)];
    tbody.insertBefore(tr, before || null);
  }
  return tr;
}

function table() {
  document.getElementById("empty").hidden = vehicles.size > 0;
  const now = performance.now();
  for (const [id, v] of vehicles) {
    const tr = row(id), s = v.msg.status, cell = (k) => tr.querySelector(`td.${k}`);
    tr.classList.toggle("gone", v.msg.alive === false);
    cell("id").innerHTML = `<span class="swatch" style="background:${colour(id)}"></span>`;
    cell("id").append(id);
    tr.dataset.updates = v.updates;
    tr.dataset.alive = String(v.msg.alive);
    if (!s) continue;
    tr.dataset.state = s.state;
    tr.dataset.seq = s.seq;
    if (s.position_ned) { tr.dataset.n = s.position_ned[0]; tr.dataset.e = s.position_ned[1]; }
    const ack = s.control_ack, want = pending.get(id);
    let note = "";
    if (want && ack && ack.nonce === want.nonce) {  // the service's answer (docs/dashboard.md, "Control")
      note = ack.accepted ? ` (${want.action} acknowledged)` : ` (${want.action} refused: ${ack.reason})`;
    } else if (want) note = ` (${want.action} sent)`;
    tr.dataset.control = note.trim();
    cell("state").className = `state st-${s.state}`;
    cell("state").textContent = s.state + note;
    if (s.reason) { const r = document.createElement("small"); r.textContent = s.reason; cell("state").append(r); }
    if (v.msg.seq_regressions) {  // a restart, or someone else publishing on this vehicle's key
      const w = document.createElement("small");
      w.className = "warn";
      w.textContent = `seq went back ${v.msg.seq_regressions}x: restarted, or a second publisher`;
      cell("state").append(w);
    }
    cell("mode").textContent = s.mode || "-";
    cell("armed").textContent = s.armed === null ? "-" : s.armed ? "yes" : "no";
    cell("dist").textContent = fmt(s.distance_to_goal_m, 2);
    cell("speed").textContent = s.velocity_ned ? fmt(Math.hypot(...s.velocity_ned), 3) : "-";
    cell("fixage").textContent = fmt(s.position_age_s, 2);
    cell("msgage").textContent = fmt((now - v.arrivedAt) / 1000, 1);
    cell("loop").textContent = `${fmt(s.loop_latency_ms.p50, 2)}/${fmt(s.loop_latency_ms.p99, 2)}`;
    if (controlAllowed && !cell("ctl").firstChild) {
      const b = document.createElement("button");
      b.type = "button"; b.textContent = "hold"; b.className = "hold"; b.onclick = () => send("hold", id);
      cell("ctl").append(b);
    }
  }
  const alive = [...vehicles.values()].filter((v) => v.msg.alive !== false).length;
  document.getElementById("summary").textContent = `${vehicles.size} vehicle(s), ${alive} alive` +
    (malformed ? `, ${malformed} malformed status(es) ignored` : "");
}

// ----------------------------------------------------------------------------- control
async function send(action, id) {
  const out = document.getElementById("control-result");
  const token = document.getElementById("token").value;
  const reply = await fetch("/api/control", {
    method: "POST", headers: {"Content-Type": "application/json"},
    body: JSON.stringify({action, vehicle_id: id, token}),
  });
  const body = await reply.json();
  if (!reply.ok) { out.textContent = body.error; out.dataset.result = "refused"; return; }
  for (const [vid, nonce] of Object.entries(body.sent)) pending.set(vid, {action, nonce});
  out.textContent = `${action} sent to ${Object.keys(body.sent).join(", ") || "no vehicle"}`;
  out.dataset.result = "sent";
}
document.getElementById("hold-all").onclick = () => send("hold", "*");
document.getElementById("resume-all").onclick = () => send("resume", "*");
document.getElementById("arrow-seconds").textContent = ARROW_SECONDS;

connect();
requestAnimationFrame(draw);
setInterval(table, 100);
