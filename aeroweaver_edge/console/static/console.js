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
  drawn: [], markers: [], labels: [], lastPlay: 0, es: null, backfilling: false,
  dirtyMap: true, mapSize: "", fitHalf: 20, ended: false, stopped: false, endedAt: -1, endedWhy: "", serverGone: false, legendSig: "", scaleBar: null,
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
    growFit(f);
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
  S.dirtySide = true; S.dirtyMap = true;
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
const PAD = { left: 44, right: 14, top: 14, bottom: 34 }; // room for the metre axes
const TRAIL = 12;        // frames of trail behind each body
const COVER_M = 3;       // a target is covered with one of our UAVs this close (coverage task)
const STALE_S = 3;       // a field UAV not heard for this long is drawn grey
const COVERABLE = new Set(["landmark", "slot", "goal", "target"]);

function niceStep(raw) {
  const p = 10 ** Math.floor(Math.log10(Math.max(raw, 1e-6)));
  for (const k of [1, 2, 5, 10]) if (k * p >= raw) return k * p;
  return 10 * p;
}

function halfExtent() {
  const h = Number(S.meta.arena_half_m);
  return h > 0 ? h : S.fitHalf;
}

function growFit(f) {
  // field frames have no arena: fit everything seen so far (it only grows, no jitter)
  let m = 0;
  for (const b of f.bodies || []) m = Math.max(m, Math.abs(b.pos[0]), Math.abs(b.pos[1]));
  for (const e of f.entities || []) m = Math.max(m, Math.abs(e.pos[0]), Math.abs(e.pos[1]));
  const want = Math.max(20, Math.ceil((m * 1.25) / 10) * 10);
  if (want > S.fitHalf) { S.fitHalf = want; S.dirtyMap = true; } // a shown frame rescales too
}

function view(canvas) {
  const half = halfExtent();
  const w = canvas.clientWidth, h = canvas.clientHeight;
  const scale = Math.min(w - PAD.left - PAD.right, h - PAD.top - PAD.bottom) / (2 * half);
  return { half, scale, cx: PAD.left + (w - PAD.left - PAD.right) / 2, cy: PAD.top + (h - PAD.top - PAD.bottom) / 2, w, h };
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

function drawGrid(ctx, v) {
  // grid and metre axes: a step that keeps labels about 60 px apart
  const step = niceStep(60 / v.scale);
  v.step = step;
  const lo = -Math.floor(v.half / step) * step;
  ctx.lineWidth = 1; ctx.font = "10px system-ui"; ctx.fillStyle = "#8897a8";
  const [left, top] = toScreen(v, [v.half, -v.half]), [right, bottom] = toScreen(v, [-v.half, v.half]);
  for (let m = lo; m <= v.half + 1e-6; m += step) {
    const [x] = toScreen(v, [0, m]), [, y] = toScreen(v, [m, 0]);
    ctx.strokeStyle = m === 0 ? "#2a3a4c" : "#1c2733";
    ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, bottom); ctx.stroke();
    ctx.beginPath(); ctx.moveTo(left, y); ctx.lineTo(right, y); ctx.stroke();
    ctx.textAlign = "center"; ctx.textBaseline = "top"; ctx.fillText(String(m), x, bottom + 3);
    ctx.textAlign = "right"; ctx.textBaseline = "middle"; ctx.fillText(String(m), left - 4, y);
  }
  ctx.textAlign = "center"; ctx.textBaseline = "top";
  ctx.fillText("east (m) →", (left + right) / 2, bottom + 16);
  ctx.save(); ctx.translate(left - 32, (top + bottom) / 2); ctx.rotate(-Math.PI / 2);
  ctx.fillText("north (m) →", 0, 0); ctx.restore();
  ctx.textAlign = "left"; ctx.textBaseline = "alphabetic";
  if (Number(S.meta.arena_half_m) > 0) { // the simulated arena is the geofence
    ctx.setLineDash([6, 4]); ctx.strokeStyle = "#ff6b6b"; ctx.lineWidth = 1.5;
    ctx.strokeRect(left, top, right - left, bottom - top);
    ctx.setLineDash([]);
  }
}

function drawScaleBar(ctx, v) {
  const metres = niceStep(80 / v.scale), px = metres * v.scale;
  const x1 = v.w - 12, x0 = x1 - px, y = 24; // top right, over the map
  ctx.fillStyle = "rgba(16,21,28,.75)"; ctx.fillRect(x0 - 6, y - 16, px + 12, 24);
  ctx.strokeStyle = "#d8e0ea"; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(x0, y - 4); ctx.lineTo(x0, y); ctx.lineTo(x1, y); ctx.lineTo(x1, y - 4); ctx.stroke();
  ctx.fillStyle = "#d8e0ea"; ctx.font = "10px system-ui"; ctx.textAlign = "center";
  ctx.fillText(`${metres} m`, (x0 + x1) / 2, y - 6); ctx.textAlign = "left";
  S.scaleBar = { metres, px };
}

function trailOf(id, episode) {
  const pts = [];
  for (let i = Math.max(S.base, S.cur - TRAIL); i <= S.cur; i++) {
    const f = frameAt(i);
    if (!f || f.episode !== episode) continue;
    const b = (f.bodies || []).find((k) => k.id === id);
    if (b) pts.push(b.pos);
  }
  return pts;
}

function drawTrail(ctx, v, pts, colour) {
  if (pts.length < 2) return;
  ctx.strokeStyle = colour; ctx.lineWidth = 1.5;
  for (let k = 1; k < pts.length; k++) {
    ctx.globalAlpha = 0.1 + 0.45 * (k / pts.length);
    const [x0, y0] = toScreen(v, pts[k - 1]), [x1, y1] = toScreen(v, pts[k]);
    ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke();
  }
  ctx.globalAlpha = 1;
}

// Per-task status: which targets are covered (one of our UAVs within COVER_M) and which UAV
// heads for what (its current skill invocation names the target).
function taskStatus(f) {
  const ours = (f.bodies || []).filter((b) => (f.uavs || []).includes(b.id));
  const decisions = f.decisions || {};
  const rows = [];
  for (const e of f.entities || []) {
    const coverable = COVERABLE.has(e.kind);
    const by = coverable ? ours.filter((b) => Math.hypot(b.pos[0] - e.pos[0], b.pos[1] - e.pos[1]) <= COVER_M).map((b) => b.id) : [];
    const word = new RegExp(`\\b${e.id.replace(/[.*+?^${}()|[\]\\]/g, "\\$&")}\\b`);
    const claimed = Object.keys(decisions).sort().filter((u) => word.test(String(decisions[u].invocation || "")));
    if (coverable || claimed.length) rows.push({ id: e.id, kind: e.kind, role: e.role || "", coverable, covered: by, claimed });
  }
  return rows;
}

// Deterministic label placement: labels in a fixed order (our UAVs, other bodies, then
// targets, each by id); each takes the first candidate position, ring by ring around its
// anchor, whose box stays on the canvas and overlaps no placed label and no glyph.
function placeLabels(ctx, items, glyphs, w, h) {
  const placed = [];
  const hit = (a, b) => a.x < b.x + b.w && b.x < a.x + a.w && a.y < b.y + b.h && b.y < a.y + a.h;
  const dirs = [[1, -1], [1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1]];
  for (const it of items) {
    const tw = Math.ceil(ctx.measureText(it.text).width) + 2, th = 11;
    let best = null, bestCost = Infinity;
    search: for (let ring = 0; ring < 14; ring++) {
      const d = it.r + 2 + ring * 11;
      for (const [dx, dy] of dirs) {
        const x = it.x + dx * d - (dx < 0 ? tw : dx === 0 ? tw / 2 : 0);
        const y = it.y + dy * d - (dy < 0 ? th : dy === 0 ? th / 2 : 0);
        const box = { x, y, w: tw, h: th };
        let cost = 0;
        if (x < 0 || y < 0 || x + tw > w || y + th > h) cost += 1e6;
        for (const o of placed) if (hit(box, o)) cost += 1000;
        for (const g of glyphs) if (g.id !== it.key && hit(box, g)) cost += 10;
        if (cost < bestCost) { bestCost = cost; best = box; }
        if (cost === 0) break search;
      }
    }
    const box = { id: it.id, kind: it.kind, x: best.x, y: best.y, w: best.w, h: best.h, ax: it.x, ay: it.y };
    placed.push(box);
  }
  return placed;
}

function drawLabels(ctx, labels, items) {
  const style = Object.fromEntries(items.map((it) => [it.id, it]));
  for (const l of labels) {
    const it = style[l.id];
    const cx = Math.max(l.x, Math.min(l.ax, l.x + l.w)), cy = Math.max(l.y, Math.min(l.ay, l.y + l.h));
    if (Math.hypot(cx - l.ax, cy - l.ay) > it.r + 8) { // far from its glyph: a leader line
      ctx.strokeStyle = "rgba(136,151,168,.6)"; ctx.lineWidth = 1;
      ctx.beginPath(); ctx.moveTo(l.ax, l.ay); ctx.lineTo(cx, cy); ctx.stroke();
    }
    ctx.fillStyle = "rgba(16,21,28,.7)"; ctx.fillRect(l.x, l.y, l.w, l.h);
    ctx.fillStyle = it.colour; ctx.fillText(it.text, l.x + 1, l.y + 9);
  }
}

function drawMap(now) {
  const canvas = $("map");
  const ctx = fitCanvas(canvas);
  const v = view(canvas);
  ctx.clearRect(0, 0, v.w, v.h);
  drawGrid(ctx, v);
  drawScaleBar(ctx, v);
  const f = frameAt(S.cur);
  if (!f) {
    ctx.fillStyle = "#8897a8"; ctx.font = "14px system-ui"; ctx.textAlign = "center";
    // who is up says what the page is waiting for (alive/uav/<id> tokens; the world's token)
    const alive = S.meta.alive || [];
    const up = alive.filter((a) => /^uav/.test(a));
    const lines = !up.length ? ["waiting for the first round… (no UAV daemon is up yet)"]
      : alive.includes("world") ? [`${up.length} daemon(s) up; waiting for the world's first round…`]
      : [`${up.length} daemon(s) up (${up.slice(0, 6).join(", ")}${up.length > 6 ? ", …" : ""}), no round report yet:`,
        "field daemons report every round; daemons on the sim backend wait for a simulated world",
        "(aeroweaver mission start --sim-world)"];
    lines.forEach((t, k) => ctx.fillText(t, v.cx, v.cy + 18 * (k - (lines.length - 1) / 2)));
    ctx.textAlign = "left";
    S.markers = []; S.labels = [];
    return;
  }
  const ours = new Set(f.uavs || []), held = new Set(f.held || []), absent = new Set(f.absent || []);
  const vehicles = f.vehicles || {};
  const stale = (id) => absent.has(id) || (vehicles[id] && vehicles[id].heard_s > STALE_S);
  const covered = new Set(taskStatus(f).filter((r) => r.covered.length).map((r) => r.id));
  for (const e of f.entities || []) drawEntity(ctx, v, e, covered.has(e.id));
  const alpha = S.anim ? Math.max(0, Math.min(1, (now - S.anim.t0) / S.anim.ms)) : 1;
  if (S.anim && alpha >= 1) S.anim.done = true; // the motion's last draw is at the frame itself
  const pos = {};
  for (const b of f.bodies || []) {
    const from = S.anim && S.anim.from && S.anim.from[b.id];
    pos[b.id] = from ? [from[0] + (b.pos[0] - from[0]) * alpha, from[1] + (b.pos[1] - from[1]) * alpha] : b.pos;
  }
  for (const b of f.bodies || []) {
    const pts = trailOf(b.id, f.episode);
    if (pts.length) pts[pts.length - 1] = pos[b.id];
    drawTrail(ctx, v, pts, colourOf(b.role || "uav"));
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
  S.markers = [];
  const glyphs = [], items = [];
  for (const b of f.bodies || []) {
    const [x, y] = toScreen(v, pos[b.id]);
    const heading = Math.atan2(-(b.vel ? b.vel[0] : 0), b.vel ? b.vel[1] : 0);
    const moving = b.vel && Math.hypot(b.vel[0], b.vel[1]) > 0.05;
    const colour = stale(b.id) ? "#5a6675" : colourOf(b.role || "uav");
    drawBody(ctx, x, y, heading, moving, colour, ours.has(b.id), held.has(b.id), b.id === S.selected);
    S.markers.push({ id: b.id, x, y, ours: ours.has(b.id) });
    glyphs.push({ id: `b:${b.id}`, x: x - 9, y: y - 9, w: 18, h: 18 });
    items.push({ id: `b:${b.id}`, key: `b:${b.id}`, kind: "body", text: b.id, x, y, r: 9, colour: ours.has(b.id) ? "#d8e0ea" : "#ffb0b0", order: ours.has(b.id) ? 0 : 1 });
  }
  for (const e of f.entities || []) {
    const [x, y] = toScreen(v, e.pos);
    glyphs.push({ id: `e:${e.id}`, x: x - 7, y: y - 7, w: 14, h: 14 });
    if (e.kind !== "forest") items.push({ id: `e:${e.id}`, key: `e:${e.id}`, kind: "entity", text: e.id, x, y, r: 7, colour: covered.has(e.id) ? "#7ddc8a" : "#8897a8", order: 2 });
  }
  items.sort((a, b) => a.order - b.order || (a.text < b.text ? -1 : a.text > b.text ? 1 : 0));
  ctx.font = "10px system-ui";
  S.labels = placeLabels(ctx, items, glyphs, v.w, v.h);
  drawLabels(ctx, S.labels, items);
}

function drawEntity(ctx, v, e, covered) {
  const [x, y] = toScreen(v, e.pos);
  glyphEntity(ctx, x, y, e.kind, e.role, covered, v.scale);
}

function glyphEntity(ctx, x, y, kind, role, covered, scale) {
  ctx.lineWidth = 1.5;
  if (kind === "forest") {
    ctx.fillStyle = "rgba(60,140,70,.25)"; ctx.beginPath(); ctx.arc(x, y, Math.max(6, 10 * scale), 0, 2 * Math.PI); ctx.fill();
  } else if (kind === "food") {
    ctx.fillStyle = "#7ddc8a"; ctx.beginPath(); ctx.arc(x, y, 4, 0, 2 * Math.PI); ctx.fill();
  } else if (kind === "treasure") {
    ctx.fillStyle = colourOf(`treasure:${role || ""}`);
    ctx.beginPath(); ctx.moveTo(x, y - 6); ctx.lineTo(x + 6, y); ctx.lineTo(x, y + 6); ctx.lineTo(x - 6, y); ctx.closePath(); ctx.fill();
  } else if (kind === "slot") {
    ctx.strokeStyle = covered ? "#7ddc8a" : "#6b7a8c"; ctx.strokeRect(x - 4, y - 4, 8, 8);
  } else {
    ctx.strokeStyle = covered ? "#7ddc8a" : "#9aa8b8"; ctx.beginPath(); ctx.arc(x, y, 6, 0, 2 * Math.PI); ctx.stroke();
    ctx.beginPath(); ctx.arc(x, y, covered ? 3.5 : 1.5, 0, 2 * Math.PI); ctx.fillStyle = covered ? "#7ddc8a" : "#9aa8b8"; ctx.fill();
  }
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
    if (m.to === "*") {
      const r = (1 - a) * (Number(S.meta.comm_radius_m) || 55) * v.scale;
      glyphBroadcast(ctx, x0, y0, r, a);
    } else if (pos[m.to]) {
      const [x1, y1] = toScreen(v, pos[m.to]);
      glyphArrow(ctx, x0, y0, x1, y1, a);
    }
  }
}

function glyphBroadcast(ctx, x, y, r, a) {
  ctx.strokeStyle = `rgba(244,227,107,${(0.45 * a).toFixed(2)})`; ctx.lineWidth = 1;
  ctx.beginPath(); ctx.arc(x, y, r, 0, 2 * Math.PI); ctx.stroke();
}

function glyphArrow(ctx, x0, y0, x1, y1, a) {
  ctx.strokeStyle = `rgba(244,227,107,${a.toFixed(2)})`; ctx.lineWidth = 1.5;
  ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke();
  const ang = Math.atan2(y1 - y0, x1 - x0);
  ctx.beginPath(); ctx.moveTo(x1, y1);
  ctx.lineTo(x1 - 7 * Math.cos(ang - 0.4), y1 - 7 * Math.sin(ang - 0.4));
  ctx.lineTo(x1 - 7 * Math.cos(ang + 0.4), y1 - 7 * Math.sin(ang + 0.4));
  ctx.closePath(); ctx.fillStyle = ctx.strokeStyle; ctx.fill();
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
  } else if (S.playing && !S.follow && S.meta.mode === "live" && !S.stopped) {
    S.follow = true; // caught up with the live run
    updateButtons();
  }
  // the map is redrawn only when something on it can change: a new frame or selection,
  // the motion between two frames, fading messages, or a resize (an idle page costs nothing)
  const map = $("map");
  const size = `${map.clientWidth}x${map.clientHeight}`;
  // until one draw at the frame's own positions, however late the animation frames come
  // (a busy or throttled page); bounded, so a frame gone meanwhile does not redraw forever
  const animating = S.anim && !S.anim.done && now - S.anim.t0 < S.anim.ms + 2000;
  if (S.dirtyMap || animating || S.msgs.length || size !== S.mapSize) {
    S.dirtyMap = false; S.mapSize = size;
    drawMap(now);
  }
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

function fmt(x, unit, nd) { return x == null ? "—" : `${Number(x).toFixed(nd)}${unit}`; }

function renderSide(f) {
  const when = f.source === "field" ? `field view · sample ${f.round + 1}` : `episode ${f.episode} · round ${f.round + 1}`;
  $("clock").textContent = `${when}${f.done ? ` · ${f.reason}` : ""}`;
  const ours = new Set(f.uavs || []), held = new Set(f.held || []), absent = new Set(f.absent || []);
  const veh = f.vehicles || {};
  const withLink = Object.keys(veh).length > 0;
  // with a vehicle link the row is wide: the role moves into the UAV cell's tooltip
  $("uavs").tHead.innerHTML = `<tr><th>UAV</th>${withLink ? "" : "<th>role</th>"}` +
    (withLink ? '<th title="flight mode the autopilot reports">mode</th><th title="armed">arm</th><th title="altitude above the origin">alt</th><th title="battery remaining">batt</th><th title="age of the vehicle\'s last heartbeat when the UAV reported (+ the report\'s own age when stale)">hb</th><th title="the daemon\'s flight phase">phase</th>' : "") +
    "<th>skill</th><th>hold</th></tr>";
  const rows = [];
  for (const b of f.bodies || []) {
    const d = (f.decisions || {})[b.id];
    const role = b.role || (S.meta.roles || {})[b.id] || "";
    const sel = b.id === S.selected ? " sel" : "";
    if (!ours.has(b.id)) {
      rows.push(`<tr data-uav="${esc(b.id)}" class="opp${sel}"><td title="${esc(role)}">${esc(b.id)}</td>${withLink ? '<td colspan="6"></td>' : `<td>${esc(role)}</td>`}<td>(the world's agent)</td><td></td></tr>`);
      continue;
    }
    const hold = held.has(b.id) ? (d && d.hold_cause ? d.hold_cause : "hold") : "";
    let link = "";
    if (withLink) {
      const x = veh[b.id] || {};
      const late = x.heard_s > STALE_S;
      const hb = x.heartbeat_age_s == null ? null : x.heartbeat_age_s + (late ? x.heard_s : 0);
      link = `<td class="mode" title="${esc(x.mode || "")}">${esc(x.mode || "—")}</td><td class="armed">${x.armed == null ? "—" : x.armed ? "armed" : "safe"}</td>` +
        `<td class="alt num">${fmt(x.alt_m, " m", 1)}</td><td class="batt num">${fmt(x.battery_pct, " %", 0)}</td>` +
        `<td class="hb num${late ? " hold" : ""}" title="last report ${fmt(x.heard_s, " s", 1)} ago">${fmt(hb, " s", 1)}</td><td class="phase">${esc(x.phase || "—")}</td>`;
    }
    const cls = `${absent.has(b.id) || (veh[b.id] && veh[b.id].heard_s > STALE_S) ? "stale" : ""}${sel}`.trim();
    rows.push(`<tr data-uav="${esc(b.id)}"${cls ? ` class="${cls}"` : ""}><td title="role ${esc(role)}">${esc(b.id)}</td>${withLink ? link : `<td>${esc(role)}</td>`}` +
      `<td class="skill" title="${esc(d ? d.invocation : "")}">${esc(d ? d.invocation : "…")}</td><td class="hold">${esc(hold)}</td></tr>`);
  }
  $("uavs").tBodies[0].innerHTML = rows.join("");
  renderTasks(f);
  renderDecision(f);
  renderLegend(f);
}

function renderTasks(f) {
  const rows = taskStatus(f);
  const box = $("tasks");
  if (!rows.length) { box.style.display = "none"; box.innerHTML = ""; return; }
  box.style.display = "";
  const cov = rows.filter((r) => r.coverable);
  const done = cov.filter((r) => r.covered.length).length;
  let html = `<h3>targets${cov.length ? ` <span class="kv">${done} of ${cov.length} covered</span>` : ""}</h3>`;
  html += '<table id="targets"><thead><tr><th>target</th><th>kind</th><th title="one of our UAVs within 3 m">covered by</th><th title="UAVs whose current skill names it">heading for it</th></tr></thead><tbody>';
  for (const r of rows) {
    html += `<tr data-target="${esc(r.id)}"${r.covered.length ? ' class="covered"' : ""}><td>${esc(r.id)}</td><td>${esc(r.kind)}${r.role ? ` (${esc(r.role)})` : ""}</td>` +
      `<td class="by">${r.coverable ? esc(r.covered.join(", ") || "—") : ""}</td><td class="claimed">${esc(r.claimed.join(", ") || "—")}</td></tr>`;
  }
  box.innerHTML = html + "</tbody></table>";
}

// The legend: every glyph the map can show for this frame, drawn by the map's own code.
function legendItems(f) {
  const items = [];
  const ours = new Set(f.uavs || []);
  const roles = [...new Set((f.bodies || []).filter((b) => ours.has(b.id)).map((b) => b.role || "uav"))];
  for (const r of roles) items.push({ key: `role:${r}`, text: `our UAV, role ${r} (points along its velocity)`, draw: (c) => drawBody(c, 8, 8, 0, true, colourOf(r), true, false, false) });
  const opp = [...new Set((f.bodies || []).filter((b) => !ours.has(b.id)).map((b) => b.role || "agent"))];
  for (const r of opp) items.push({ key: `opp:${r}`, text: `the world's ${r} (red outline)`, draw: (c) => drawBody(c, 8, 8, 0, true, colourOf(r), false, false, false) });
  items.push({ key: "held", text: "held this round", draw: (c) => drawBody(c, 8, 8, 0, false, "#5cc8ff", true, true, false) });
  if (f.source === "field" || f.vehicles) items.push({ key: "stale", text: `no report for ${STALE_S} s`, draw: (c) => drawBody(c, 8, 8, 0, false, "#5a6675", true, false, false) });
  items.push({ key: "trail", text: `trail (last ${TRAIL} frames)`, draw: (c) => { c.strokeStyle = "#5cc8ff"; c.globalAlpha = 0.5; c.lineWidth = 1.5; c.beginPath(); c.moveTo(1, 14); c.quadraticCurveTo(4, 3, 15, 3); c.stroke(); c.globalAlpha = 1; } });
  items.push({ key: "selected", text: "selected: comm radius (ring), sensing radius (dashed)", draw: (c) => { c.strokeStyle = "rgba(92,200,255,.7)"; c.lineWidth = 1; c.beginPath(); c.arc(8, 8, 7, 0, 2 * Math.PI); c.stroke(); c.setLineDash([2, 2]); c.beginPath(); c.arc(8, 8, 4, 0, 2 * Math.PI); c.stroke(); c.setLineDash([]); } });
  const kinds = [...new Set((f.entities || []).map((e) => e.kind))].sort();
  for (const k of kinds) {
    if (COVERABLE.has(k)) {
      items.push({ key: `k:${k}`, text: `${k}, not covered`, draw: (c) => glyphEntity(c, 8, 8, k, "", false, 1) });
      items.push({ key: `k:${k}:c`, text: `${k}, covered (a UAV within ${COVER_M} m)`, draw: (c) => glyphEntity(c, 8, 8, k, "", true, 1) });
    } else if (k === "treasure") {
      const colours = [...new Set((f.entities || []).filter((e) => e.kind === k).map((e) => e.role || ""))].sort();
      for (const r of colours) items.push({ key: `k:${k}:${r}`, text: `treasure${r ? ` (${r})` : ""}`, draw: (c) => glyphEntity(c, 8, 8, k, r, false, 1) });
    } else {
      items.push({ key: `k:${k}`, text: k, draw: (c) => glyphEntity(c, 8, 8, k, "", false, 0.6) });
    }
  }
  if (Number(S.meta.arena_half_m) > 0) items.push({ key: "fence", text: "geofence (the arena)", draw: (c) => { c.setLineDash([3, 2]); c.strokeStyle = "#ff6b6b"; c.lineWidth = 1.5; c.strokeRect(2, 2, 12, 12); c.setLineDash([]); } });
  if (f.source !== "field") {
    items.push({ key: "msg", text: "directed message", draw: (c) => glyphArrow(c, 1, 13, 15, 3, 1) });
    items.push({ key: "bcast", text: "broadcast", draw: (c) => glyphBroadcast(c, 8, 8, 6, 1) });
  }
  items.push({ key: "scale", text: `scale bar; grid and axes in metres, north up`, draw: (c) => { c.strokeStyle = "#d8e0ea"; c.lineWidth = 2; c.beginPath(); c.moveTo(1, 8); c.lineTo(1, 12); c.lineTo(15, 12); c.lineTo(15, 8); c.stroke(); } });
  return items;
}

function renderLegend(f) {
  const items = legendItems(f);
  const sig = items.map((i) => `${i.key}|${i.text}`).join("\n");
  if (sig === S.legendSig) return;
  S.legendSig = sig;
  const box = $("legend");
  box.innerHTML = items.map((i) => `<span data-glyph="${esc(i.key)}"><canvas width="16" height="16"></canvas>${esc(i.text)}</span>`).join("");
  box.querySelectorAll("canvas").forEach((cv, k) => { const c = cv.getContext("2d"); items[k].draw(c); });
}

function renderDecision(f) {
  const box = $("decision");
  if (!S.selected) { box.innerHTML = "<em>Click a UAV to see its last decision.</em>"; return; }
  const uav = S.selected;
  const d = (f.decisions || {})[uav];
  const goal = (S.meta.goals || {})[uav];
  const vr = (f.vehicles || {})[uav];
  const when = f.source === "field" ? `its round ${vr ? vr.round + 1 : "?"}` : `round ${f.round + 1}`;
  const role = (S.meta.roles || {})[uav];
  let html = `<h3>${esc(uav)} <span class="kv">${esc(when)}${role ? ` · ${esc(role)}` : ""}</span></h3>`;
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
  S.dirtySide = true; S.dirtyMap = true;
}

// -- operator actions -------------------------------------------------------------------
function renderOperator() {
  const box = $("operator");
  const op = S.meta.operator || {};
  let html = "<h3>operator</h3>";
  if (S.ended) {
    box.innerHTML = html + `<button id="stop" class="danger" disabled title="${esc(S.endedWhy)}">stop the mission…</button>` +
      `<div class="kv">${esc(S.endedWhy)}: play or scrub to replay what this page saw</div>`;
    return;
  }
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
  $("live").style.display = S.meta.mode === "live" && !S.stopped ? "" : "none";
  $("replay").style.display = S.ended ? "" : "none";
}

function endedWhy(meta) {
  if (S.serverGone) return "the console server stopped";
  if (meta.ended) return "the run has ended";
  if ((meta.mission || {}).state === "ended") return "the mission has ended";
  return "";
}

function applyMeta(meta) {
  S.meta = meta; S.dirtyMap = true;
  const why = endedWhy(meta);
  // The run or the console is over: no more frames, hold the last one (play replays).
  // Only the mission ended: frames still come (the UAVs land), so keep following them.
  const stopped = Boolean(meta.ended || S.serverGone);
  if (stopped && !S.stopped) { S.follow = false; S.playing = false; S.endedAt = lastIndex(); }
  if (!why && S.ended && meta.mode === "live") { S.follow = true; S.playing = true; } // a new mission
  S.ended = Boolean(why); S.endedWhy = why; S.stopped = stopped;
  const mode = why ? "ended" : meta.mode || "live";
  $("mode").textContent = mode; $("mode").className = `badge ${mode}`;
  $("mode").title = why;
  const m = meta.mission || {};
  $("mission").textContent = [meta.task, m.id, m.text ? `“${m.text}”` : "", m.state && m.state !== "active" ? m.state : ""].filter(Boolean).join(" · ");
  if (meta.mode === "replay" && S.follow) { S.follow = false; S.playing = false; }
  updateButtons();
  renderOperator();
}

async function serverGone() {
  // the stream broke: is the server still there? If not, the run is over for this page
  try {
    const r = await fetch("/api/meta", { cache: "no-store" });
    if (r.ok) return;
  } catch (e) { /* gone */ }
  S.serverGone = true;
  if (S.es) S.es.close();
  $("conn").textContent = "the console server stopped: the frames this page saw stay here";
  applyMeta({ ...S.meta, operator: { enabled: false, read_only: "the console server stopped" } });
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
    if (p.i === S.cur) { S.dirtySide = true; S.dirtyMap = true; }
    S.dirtyCharts = true;
  });
  es.onopen = () => { $("conn").textContent = "connected"; };
  es.onerror = () => { $("conn").textContent = "disconnected: the frames so far stay here"; serverGone(); };
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
    else if ((S.meta.mode === "replay" && S.cur >= lastIndex()) || (S.stopped && S.cur >= S.endedAt)) show(S.base);
    updateButtons();
  };
  $("replay").onclick = () => { S.follow = false; S.playing = true; S.lastPlay = 0; show(S.base); drawCharts(); updateButtons(); };
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
