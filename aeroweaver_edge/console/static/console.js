// AeroWeaver console: draws one frame per world round on a canvas (live over server-sent
// events, or a replay of a trace), shows each UAV's decision on click, and offers the
// operator's actions behind a typed confirmation. No dependencies; served by the package.
"use strict";

const $ = (id) => document.getElementById(id);
const TOKEN = document.querySelector('meta[name="aw-token"]').content;
const PALETTE = ["#5cc8ff", "#ffb347", "#7ddc8a", "#d98cff", "#ff8fa3", "#f4e36b", "#6be0d0", "#c0a080"];
const MSG_LIFE_MS = 1200;

const S = {
  meta: {}, frames: [], base: 0, cur: -1, follow: true, playing: true,
  selected: null, approvals: {}, roleColour: {}, anim: null, msgs: [],
  drawn: [], markers: [], lastPlay: 0, es: null, backfilling: false,
  dirtySide: false, dirtyCharts: false, chartsAt: 0,
};
window.__aw = S; // for tests and the latency bench: state, drawn rounds, marker positions

// -- frames -----------------------------------------------------------------------------
function frameAt(i) { return S.frames[i - S.base]; }
function lastIndex() { return S.base + S.frames.length - 1; }

function addFrames(list) {
  for (const f of list) {
    if (S.frames.length === 0) S.base = f.i;
    const j = f.i - S.base;
    if (j < 0) continue;
    if (j < S.frames.length) { S.frames[j] = f; continue; }
    while (S.frames.length < j) S.frames.push(null); // a gap, filled by a backfill
    S.frames.push(f);
  }
  $("scrub").min = S.base;
  $("scrub").max = Math.max(S.base, lastIndex());
  if (S.follow) show(lastIndex());
  S.dirtyCharts = true;
}

async function backfill() {
  const gap = S.frames.findIndex((f) => f === null);
  if (gap < 0 || S.backfilling) return;
  S.backfilling = true;
  try {
    const r = await fetch(`/api/frames?since=${S.base + gap}`);
    addFrames((await r.json()).frames);
  } finally { S.backfilling = false; }
}

function show(i) {
  const f = frameAt(i);
  if (!f || i === S.cur) return;
  const prev = frameAt(S.cur);
  S.anim = { from: prev && prev.episode === f.episode ? positions(prev) : null, t0: performance.now(), ms: animMs() };
  S.cur = i;
  const now = performance.now();
  for (const m of f.messages || []) S.msgs.push({ ...m, t0: now, frame: f });
  S.msgs = S.msgs.filter((m) => now - m.t0 < MSG_LIFE_MS);
  $("scrub").value = i;
  S.dirtySide = true;
}

function animMs() {
  const r = Number(S.meta.round_s) || 0.5;
  return Math.min(200, 400 * r);
}

function positions(f) {
  const out = {};
  for (const b of f.bodies || []) out[b.id] = b.pos;
  return out;
}

// -- geometry ---------------------------------------------------------------------------
function view(canvas) {
  const half = Number(S.meta.arena_half_m) || 70;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  const scale = (Math.min(w, h) * 0.92) / (2 * half);
  return { half, scale, cx: w / 2, cy: h / 2 };
}
// positions are [north, east] in metres: north up, east right
function toScreen(v, p) { return [v.cx + p[1] * v.scale, v.cy - p[0] * v.scale]; }

function colourOf(role) {
  if (!(role in S.roleColour)) S.roleColour[role] = PALETTE[Object.keys(S.roleColour).length % PALETTE.length];
  return S.roleColour[role];
}

// -- drawing ----------------------------------------------------------------------------
function fitCanvas(canvas) {
  const dpr = window.devicePixelRatio || 1;
  const w = Math.round(canvas.clientWidth * dpr), h = Math.round(canvas.clientHeight * dpr);
  if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
  const ctx = canvas.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  return ctx;
}

function drawMap(now) {
  const canvas = $("map");
  const ctx = fitCanvas(canvas);
  const v = view(canvas);
  ctx.clearRect(0, 0, canvas.clientWidth, canvas.clientHeight);
  // grid every 10 m and the geofence (the arena)
  ctx.strokeStyle = "#1c2733"; ctx.lineWidth = 1;
  for (let m = -v.half; m <= v.half + 0.01; m += 10) {
    const [x0, y0] = toScreen(v, [v.half, m]), [x1, y1] = toScreen(v, [-v.half, m]);
    ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke();
    const [a0, b0] = toScreen(v, [m, -v.half]), [a1, b1] = toScreen(v, [m, v.half]);
    ctx.beginPath(); ctx.moveTo(a0, b0); ctx.lineTo(a1, b1); ctx.stroke();
  }
  const [gx, gy] = toScreen(v, [v.half, -v.half]);
  ctx.setLineDash([6, 4]); ctx.strokeStyle = "#ff6b6b"; ctx.lineWidth = 1.5;
  ctx.strokeRect(gx, gy, 2 * v.half * v.scale, 2 * v.half * v.scale);
  ctx.setLineDash([]);
  const f = frameAt(S.cur);
  if (!f) {
    ctx.fillStyle = "#8897a8"; ctx.font = "14px system-ui";
    ctx.fillText("waiting for the first round…", v.cx - 90, v.cy);
    S.markers = [];
    return;
  }
  for (const e of f.entities || []) drawEntity(ctx, v, e);
  const alpha = S.anim ? Math.max(0, Math.min(1, (now - S.anim.t0) / S.anim.ms)) : 1;
  const pos = {};
  for (const b of f.bodies || []) {
    const from = S.anim && S.anim.from && S.anim.from[b.id];
    pos[b.id] = from ? [from[0] + (b.pos[0] - from[0]) * alpha, from[1] + (b.pos[1] - from[1]) * alpha] : b.pos;
  }
  // the selected UAV's communication and sensing radii
  if (S.selected && pos[S.selected]) {
    const [x, y] = toScreen(v, pos[S.selected]);
    ctx.strokeStyle = "rgba(92,200,255,.55)"; ctx.fillStyle = "rgba(92,200,255,.06)";
    ctx.beginPath(); ctx.arc(x, y, (Number(S.meta.comm_radius_m) || 55) * v.scale, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
    ctx.setLineDash([3, 4]); ctx.strokeStyle = "rgba(92,200,255,.35)";
    ctx.beginPath(); ctx.arc(x, y, (Number(S.meta.sensing_radius_m) || 45) * v.scale, 0, 2 * Math.PI); ctx.stroke();
    ctx.setLineDash([]);
  }
  drawMessages(ctx, v, pos, now);
  const ours = new Set(f.uavs || []), held = new Set(f.held || []);
  S.markers = [];
  for (const b of f.bodies || []) {
    const [x, y] = toScreen(v, pos[b.id]);
    const heading = Math.atan2(-(b.vel ? b.vel[0] : 0), b.vel ? b.vel[1] : 0);
    const moving = b.vel && Math.hypot(b.vel[0], b.vel[1]) > 0.05;
    drawBody(ctx, x, y, heading, moving, colourOf(b.role || "uav"), ours.has(b.id), held.has(b.id), b.id === S.selected);
    ctx.fillStyle = "#d8e0ea"; ctx.font = "10px system-ui";
    ctx.fillText(b.id, x + 8, y - 7);
    S.markers.push({ id: b.id, x, y, ours: ours.has(b.id) });
  }
}

function drawEntity(ctx, v, e) {
  const [x, y] = toScreen(v, e.pos);
  ctx.lineWidth = 1.5;
  if (e.kind === "forest") {
    ctx.fillStyle = "rgba(60,140,70,.25)"; ctx.beginPath(); ctx.arc(x, y, 10 * v.scale, 0, 2 * Math.PI); ctx.fill();
  } else if (e.kind === "food") {
    ctx.fillStyle = "#7ddc8a"; ctx.beginPath(); ctx.arc(x, y, 4, 0, 2 * Math.PI); ctx.fill();
  } else if (e.kind === "treasure") {
    ctx.fillStyle = colourOf(`treasure:${e.role || ""}`);
    ctx.beginPath(); ctx.moveTo(x, y - 6); ctx.lineTo(x + 6, y); ctx.lineTo(x, y + 6); ctx.lineTo(x - 6, y); ctx.closePath(); ctx.fill();
  } else if (e.kind === "slot") {
    ctx.strokeStyle = "#6b7a8c"; ctx.strokeRect(x - 4, y - 4, 8, 8);
  } else {
    ctx.strokeStyle = "#9aa8b8"; ctx.beginPath(); ctx.arc(x, y, 6, 0, 2 * Math.PI); ctx.stroke();
    ctx.beginPath(); ctx.arc(x, y, 1.5, 0, 2 * Math.PI); ctx.fillStyle = "#9aa8b8"; ctx.fill();
  }
  ctx.fillStyle = "#6b7a8c"; ctx.font = "9px system-ui"; ctx.fillText(e.id, x + 7, y + 10);
}

function drawBody(ctx, x, y, heading, moving, colour, ours, held, selected) {
  ctx.save(); ctx.translate(x, y);
  if (selected) { ctx.strokeStyle = "#fff"; ctx.lineWidth = 2; ctx.beginPath(); ctx.arc(0, 0, 11, 0, 2 * Math.PI); ctx.stroke(); }
  if (held) { ctx.strokeStyle = "#ffb347"; ctx.lineWidth = 1.5; ctx.setLineDash([2, 2]); ctx.beginPath(); ctx.arc(0, 0, 8.5, 0, 2 * Math.PI); ctx.stroke(); ctx.setLineDash([]); }
  ctx.rotate(moving ? heading : -Math.PI / 2);
  ctx.fillStyle = colour; ctx.strokeStyle = ours ? "#0b0f14" : "#ff6b6b"; ctx.lineWidth = ours ? 1 : 2;
  ctx.beginPath(); ctx.moveTo(8, 0); ctx.lineTo(-6, 5); ctx.lineTo(-3, 0); ctx.lineTo(-6, -5); ctx.closePath();
  ctx.fill(); ctx.stroke();
  ctx.restore();
}

function drawMessages(ctx, v, pos, now) {
  S.msgs = S.msgs.filter((m) => now - m.t0 < MSG_LIFE_MS);
  for (const m of S.msgs) {
    const a = Math.max(0, Math.min(1, 1 - (now - m.t0) / MSG_LIFE_MS));
    const from = pos[m.from];
    if (!from) continue;
    const [x0, y0] = toScreen(v, from);
    ctx.strokeStyle = `rgba(244,227,107,${a.toFixed(2)})`; ctx.lineWidth = 1.5;
    if (m.to === "*") {
      ctx.strokeStyle = `rgba(244,227,107,${(0.45 * a).toFixed(2)})`; ctx.lineWidth = 1;
      const r = (1 - a) * (Number(S.meta.comm_radius_m) || 55) * v.scale;
      ctx.beginPath(); ctx.arc(x0, y0, r, 0, 2 * Math.PI); ctx.stroke();
    } else if (pos[m.to]) {
      const [x1, y1] = toScreen(v, pos[m.to]);
      ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke();
      const ang = Math.atan2(y1 - y0, x1 - x0);
      ctx.beginPath(); ctx.moveTo(x1, y1);
      ctx.lineTo(x1 - 7 * Math.cos(ang - 0.4), y1 - 7 * Math.sin(ang - 0.4));
      ctx.lineTo(x1 - 7 * Math.cos(ang + 0.4), y1 - 7 * Math.sin(ang + 0.4));
      ctx.closePath(); ctx.fillStyle = ctx.strokeStyle; ctx.fill();
    }
  }
}

function series() {
  const ret = [], tok = [];
  let total = 0, tokens = 0, episode = null;
  for (let i = S.base; i <= Math.min(S.cur, lastIndex()); i++) {
    const f = frameAt(i);
    if (!f) continue;
    if (f.episode !== episode) { episode = f.episode; total = 0; }
    total += f.team_reward == null ? 0 : f.team_reward;
    for (const d of Object.values(f.decisions || {})) {
      const t = d.tokens || {};
      tokens += (t.prompt || 0) + (t.completion || 0);
    }
    ret.push(total); tok.push(tokens);
  }
  return { ret, tok };
}

function drawChart(canvas, ys, colour) {
  const ctx = fitCanvas(canvas);
  const w = canvas.clientWidth, h = canvas.clientHeight;
  ctx.clearRect(0, 0, w, h);
  if (ys.length === 0) return;
  let lo = Math.min(0, ...ys), hi = Math.max(0, ...ys);
  if (hi - lo < 1e-9) hi = lo + 1;
  const x = (k) => 4 + (k / Math.max(1, ys.length - 1)) * (w - 8);
  const y = (val) => h - 4 - ((val - lo) / (hi - lo)) * (h - 8);
  ctx.strokeStyle = "#2a3644"; ctx.beginPath(); ctx.moveTo(0, y(0)); ctx.lineTo(w, y(0)); ctx.stroke();
  ctx.strokeStyle = colour; ctx.lineWidth = 1.5; ctx.beginPath();
  ys.forEach((val, k) => (k ? ctx.lineTo(x(k), y(val)) : ctx.moveTo(x(k), y(val))));
  ctx.stroke();
}

function drawCharts() {
  const { ret, tok } = series();
  drawChart($("chart-return"), ret, "#7ddc8a");
  drawChart($("chart-tokens"), tok, "#5cc8ff");
  $("ret").textContent = ret.length ? ret[ret.length - 1].toFixed(3) : "";
  $("tok").textContent = tok.length ? String(tok[tok.length - 1]) : "";
}

function tick(now) {
  if (S.playing && !S.follow && S.cur < lastIndex()) {
    const stepMs = (1000 * (Number(S.meta.round_s) || 0.5)) / Number($("speed").value);
    if (now - S.lastPlay >= stepMs) { S.lastPlay = now; show(S.cur + 1); S.dirtyCharts = true; }
  } else if (S.playing && !S.follow && S.meta.mode === "live") {
    S.follow = true; // caught up with the live run
    updateButtons();
  }
  drawMap(now);
  const f = frameAt(S.cur);
  if (f && S.dirtySide) { S.dirtySide = false; renderSide(f); }
  if (S.dirtyCharts && now - S.chartsAt > 250) { S.dirtyCharts = false; S.chartsAt = now; drawCharts(); }
  if (f && !f._drawn) {
    // the frame's first paint: the latency bench compares this with the world's stamp
    f._drawn = (performance.timeOrigin + performance.now()) / 1000;
    S.drawn.push({ i: f.i, episode: f.episode, round: f.round, stamp: f.stamp, recv: f._recv, drawn: f._drawn, bodies: (f.bodies || []).length });
    if (S.drawn.length > 10000) S.drawn.shift();
  }
  requestAnimationFrame(tick);
}

// -- side panel -------------------------------------------------------------------------
function esc(s) { return String(s == null ? "" : s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]); }

function renderSide(f) {
  $("clock").textContent = `episode ${f.episode} · round ${f.round + 1}${f.done ? ` · ${f.reason}` : ""}`;
  const ours = new Set(f.uavs || []), held = new Set(f.held || []);
  const rows = [];
  for (const b of f.bodies || []) {
    const d = (f.decisions || {})[b.id];
    const role = b.role || (S.meta.roles || {})[b.id] || "";
    if (!ours.has(b.id)) {
      rows.push(`<tr data-uav="${esc(b.id)}" class="opp${b.id === S.selected ? " sel" : ""}"><td>${esc(b.id)}</td><td>${esc(role)}</td><td>(the world's agent)</td><td></td></tr>`);
      continue;
    }
    const hold = held.has(b.id) ? (d && d.hold_cause ? d.hold_cause : "hold") : "";
    rows.push(`<tr data-uav="${esc(b.id)}"${b.id === S.selected ? ' class="sel"' : ""}><td>${esc(b.id)}</td><td>${esc(role)}</td>` +
      `<td title="${esc(d ? d.invocation : "")}">${esc(d ? d.invocation : "…")}</td><td class="hold">${esc(hold)}</td></tr>`);
  }
  $("uavs").tBodies[0].innerHTML = rows.join("");
  renderDecision(f);
  renderLegend(f);
}

function renderLegend(f) {
  const roles = [...new Set((f.bodies || []).map((b) => b.role || "uav"))];
  $("legend").innerHTML = roles.map((r) => `<span><i style="background:${colourOf(r)}"></i>${esc(r)}</span>`).join("") +
    '<span>◌ hold</span><span style="color:#ff6b6b">▭ geofence</span><span style="color:#f4e36b">— message</span>';
}

function renderDecision(f) {
  const box = $("decision");
  if (!S.selected) { box.innerHTML = "<em>Click a UAV to see its last decision.</em>"; return; }
  const uav = S.selected;
  const d = (f.decisions || {})[uav];
  const goal = (S.meta.goals || {})[uav];
  let html = `<h3>${esc(uav)} <span class="kv">round ${f.round + 1}</span></h3>`;
  if (goal) html += `<div class="kv">goal: ${esc(goal)}</div>`;
  if (!(f.uavs || []).includes(uav)) { box.innerHTML = html + "<div class=\"kv\">flown by the world (a scripted opponent)</div>"; return; }
  if (!d) { box.innerHTML = html + '<div class="kv">no report for this round yet</div>'; return; }
  html += `<div>chose <b>${esc(d.invocation)}</b>${d.held ? ` · <span class="hold">held: ${esc(d.hold_cause || "")}${d.hold_reason ? ` (${esc(d.hold_reason)})` : ""}</span>` : ""}</div>`;
  const opts = d.options || [];
  if (opts.length) {
    const beta = Number(d.beta) || 0;
    html += '<table class="options"><thead><tr><th></th><th>option</th><th>base</th><th>A</th><th>z\'</th></tr></thead><tbody>';
    for (const o of opts) {
      const label = o.split(".", 1)[0];
      const text = o.slice(label.length + 2);
      const base = d.base ? d.base[label] : undefined;
      const adv = d.advantage ? d.advantage[label] : undefined;
      const z = base === undefined ? undefined : base + beta * (adv || 0);
      html += `<tr${label === d.chosen ? ' class="chosen"' : ""} data-label="${esc(label)}"><td>${esc(label)}${label === d.chosen ? " ✓" : ""}</td>` +
        `<td title="${esc(text)}">${esc(text)}</td><td class="num">${base === undefined ? "—" : base.toFixed(3)}</td>` +
        `<td class="num">${adv === undefined ? "—" : adv.toFixed(3)}</td><td class="num">${z === undefined ? "—" : z.toFixed(3)}</td></tr>`;
    }
    html += "</tbody></table>";
  }
  const t = d.tokens || {};
  if (!d.llm_calls && !t.prompt && opts.length) html += '<div class="kv">scores from a scripted selector, not an LLM: they say nothing about LLM quality</div>';
  html += `<div class="why">why: ${esc(d.reason || "—")}${d.corrected ? " (the experience correction changed the pick)" : ""}; β=${esc(d.beta)}` +
    `${d.omitted_bound != null ? `; omitted-label bound ${Number(d.omitted_bound).toFixed(3)}` : ""}</div>` +
    `<div class="kv">tokens ${(t.prompt || 0) + (t.completion || 0)} (prompt ${t.prompt || 0}, cached ${t.prompt_cached || 0}) · latency ${Number(d.latency_s || 0).toFixed(3)} s · LLM calls ${d.llm_calls || 0}</div>`;
  box.innerHTML = html;
}

function select(uav) {
  S.selected = uav === S.selected ? null : uav;
  S.dirtySide = true;
}

// -- operator actions -------------------------------------------------------------------
function renderOperator() {
  const box = $("operator");
  const op = S.meta.operator || {};
  let html = "<h3>operator</h3>";
  if (!op.enabled) {
    box.innerHTML = html + `<div class="kv">actions unavailable: ${esc(op.read_only || "read-only")}</div>`;
    return;
  }
  const m = S.meta.mission || {};
  html += m.state === "active" ? '<button id="stop" class="danger">stop the mission…</button>' : `<div class="kv">mission ${esc(m.state || "—")}</div>`;
  const pend = [];
  const recs = [];
  for (const [uav, st] of Object.entries(S.approvals)) {
    for (const p of st.pending || []) pend.push({ uav, ...p, level: st.level });
    for (const r of (st.records || []).slice(-3)) recs.push({ uav, ...r });
  }
  html += `<div class="kv" style="margin-top:6px">vehicle actions waiting for approval: ${pend.length || "none"}</div>`;
  for (const p of pend) {
    html += `<div class="pending"><span>${esc(p.uav)}: <b>${esc(p.action)}</b> <span class="kv">(${esc(p.level)})</span></span>` +
      `<button data-approve="${esc(p.uav)}" data-action="${esc(p.action)}">approve…</button></div>`;
  }
  if (recs.length) {
    html += '<div class="records">' + recs.map((r) => `${esc(r.uav)} ${esc(r.action)} ${esc(r.state)} by ${esc(r.by)}${r.reason ? ` (${esc(r.reason)})` : ""}`).join("<br>") + "</div>";
  }
  box.innerHTML = html;
  if ($("stop")) $("stop").onclick = askStop;
  for (const b of box.querySelectorAll("button[data-approve]")) b.onclick = () => askApprove(b.dataset.approve, b.dataset.action);
}

async function post(url, body) {
  const r = await fetch(url, { method: "POST", headers: { "Content-Type": "application/json", "X-AW-Token": TOKEN }, body: JSON.stringify(body) });
  const data = await r.json().catch(() => ({ error: `HTTP ${r.status}` }));
  if (!r.ok) throw new Error(data.error || `HTTP ${r.status}`);
  return data;
}

function confirmDialog(what, phrase, withTtl, run) {
  const dlg = $("confirm");
  $("confirm-what").textContent = what;
  $("confirm-phrase").textContent = phrase;
  $("confirm-input").value = "";
  $("confirm-error").textContent = "";
  $("ttl-row").style.display = withTtl ? "" : "none";
  $("confirm-ok").onclick = async (ev) => {
    ev.preventDefault();
    if ($("confirm-input").value !== phrase) { $("confirm-error").textContent = "the text does not match"; return; }
    try { await run($("confirm-input").value, Number($("confirm-ttl").value)); dlg.close(); }
    catch (e) { $("confirm-error").textContent = e.message; }
  };
  dlg.showModal();
}

async function askStop() {
  const r = await fetch("/api/operator/stop", { headers: { "X-AW-Token": TOKEN } });
  const plan = await r.json();
  if (!r.ok) { alert(plan.error); return; }
  confirmDialog(`This will ${plan.will}`, plan.confirm, false, (text) => post("/api/operator/stop", { confirm: text, reason: "console" }));
}

function askApprove(uav, action) {
  const phrase = `approve ${uav} ${action}`;  // one spelling: takeoff, land, return_home
  confirmDialog(`Allow ${uav} to ${action.replace("_", " ")} (the UAV checks the approval and records it; it expires).`, phrase, true,
    (text, ttl) => post("/api/operator/approve", { uav, action, ttl_s: ttl, confirm: text }));
}

// -- wiring -----------------------------------------------------------------------------
function updateButtons() {
  $("play").textContent = S.playing ? "pause" : "play";
  $("live").classList.toggle("on", S.follow);
  $("live").style.display = S.meta.mode === "live" ? "" : "none";
}

function applyMeta(meta) {
  S.meta = meta;
  const mode = meta.ended ? "ended" : meta.mode || "live";
  $("mode").textContent = mode; $("mode").className = `badge ${mode}`;
  const m = meta.mission || {};
  $("mission").textContent = [meta.task, m.id, m.text ? `“${m.text}”` : "", m.state && m.state !== "active" ? m.state : ""].filter(Boolean).join(" · ");
  if (meta.mode === "replay" && S.follow) { S.follow = false; S.playing = false; }
  updateButtons();
  renderOperator();
}

function connect() {
  const es = new EventSource(`/api/events?after=${lastIndex()}`);
  S.es = es;
  es.addEventListener("meta", (e) => applyMeta(JSON.parse(e.data)));
  es.addEventListener("approvals", (e) => { S.approvals = JSON.parse(e.data); renderOperator(); });
  es.addEventListener("frame", (e) => {
    const recv = (performance.timeOrigin + performance.now()) / 1000;
    const f = JSON.parse(e.data);
    f._recv = recv;
    addFrames([f]);
    if (S.frames.includes(null)) backfill();
  });
  es.addEventListener("patch", (e) => {
    const p = JSON.parse(e.data);
    const f = frameAt(p.i);
    if (!f) return;
    Object.assign(f.decisions, p.decisions);
    if (p.i === S.cur) S.dirtySide = true;
    S.dirtyCharts = true;
  });
  es.onopen = () => { $("conn").textContent = "connected"; };
  es.onerror = () => { $("conn").textContent = "disconnected: the frames so far stay here"; };
}

async function start() {
  applyMeta(await (await fetch("/api/meta")).json());
  S.approvals = await (await fetch("/api/approvals")).json();
  const data = await (await fetch("/api/frames")).json();
  addFrames(data.frames);
  if (S.meta.mode === "replay") { show(S.base); drawCharts(); }
  else connect();
  renderOperator();
  $("map").addEventListener("click", (ev) => {
    const rect = ev.target.getBoundingClientRect();
    const x = ev.clientX - rect.left, y = ev.clientY - rect.top;
    let best = null, bestD = 14;
    for (const m of S.markers) { const d = Math.hypot(m.x - x, m.y - y); if (d < bestD) { best = m; bestD = d; } }
    if (best) select(best.id);
  });
  $("uavs").addEventListener("click", (ev) => { const tr = ev.target.closest("tr[data-uav]"); if (tr) select(tr.dataset.uav); });
  $("play").onclick = () => {
    S.playing = !S.playing;
    if (!S.playing) S.follow = false;
    else if (S.meta.mode === "replay" && S.cur >= lastIndex()) show(S.base);
    updateButtons();
  };
  $("live").onclick = () => { S.follow = true; S.playing = true; show(lastIndex()); drawCharts(); updateButtons(); };
  $("scrub").oninput = () => { S.follow = false; S.playing = false; show(Number($("scrub").value)); drawCharts(); updateButtons(); };
  requestAnimationFrame(tick);
}

// marker position on the page (for tests): [x, y] in CSS pixels relative to the viewport
S.markerAt = (id) => {
  const m = S.markers.find((k) => k.id === id);
  if (!m) return null;
  const r = $("map").getBoundingClientRect();
  return [r.left + m.x, r.top + m.y];
};

start();
