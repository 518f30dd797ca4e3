// BITE Studio: the editor (command sidebar, diagnostics as you type, the
// behavior graph) and the team monitor (live run, Zenoh team, replay).
// Plain JavaScript, no build step; CodeMirror 5 is loaded before this module.
/* global CodeMirror */

const $ = (sel) => document.querySelector(sel);
// Robot names, a dozen at most (a 100-robot subteam in one line).
const names = (list) => {
  const a = [...list];
  return a.length > 12 ? `${a.slice(0, 10).join(", ")}, … (${a.length} in all)` : a.join(", ");
};
const esc = (s) => String(s ?? "").replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);

// What tests and curious users can read: snapshots received, frames drawn.
const stats = { snapshots: 0, frames: 0, bytes: 0, applyMs: 0, drawMs: {}, since: performance.now() };
window.studio = { stats };

// ---------------------------------------------------------------- editor

CodeMirror.defineSimpleMode("rtcl", {
  start: [
    { regex: /#.*/, token: "comment" },
    { regex: /^\s*[A-Za-z_][\w-]*/, token: "keyword", sol: true },
    { regex: /=>/, token: "operator" },
    { regex: /:/, token: "operator" },
    { regex: /[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?/, token: "number" },
    { regex: /[A-Za-z_][\w-]*/, token: "variable-2" },
  ],
  meta: { lineComment: "#" },
});

let kind = "rtcl";
let fileName = null;
let lastAnalysis = null;
// Only the latest analysis is shown (answers may come back out of order).
let analyzing = 0;

function lintAsync(text, update, _opts, cm) {
  analyze(text).then((a) => {
    const marks = (a.diagnostics || [])
      .filter((d) => d.line > 0)
      .map((d) => {
        const line = Math.min(d.line - 1, cm.lineCount() - 1);
        const ch = Math.max(0, d.col - 1);
        const len = cm.getLine(line)?.length ?? 0;
        return {
          from: CodeMirror.Pos(line, Math.min(ch, len)),
          to: CodeMirror.Pos(line, ch < len ? len : Math.min(ch + 1, len)),
          message: d.message + (d.hint ? `\nhint: ${d.hint}` : ""),
          severity: d.severity,
        };
      });
    update(marks);
  });
}

const cm = CodeMirror($("#editor-host"), {
  mode: "rtcl",
  lineNumbers: true,
  gutters: ["CodeMirror-lint-markers"],
  lint: { getAnnotations: lintAsync, async: true, delay: 250 },
  dragDrop: true,
});
window.studio.cm = cm;

async function analyze(text) {
  const my = ++analyzing;
  const res = await fetch("/api/analyze", {
    method: "POST",
    headers: { "content-type": "application/json" },
    body: JSON.stringify({ kind, file: fileName, text }),
  });
  const a = await res.json();
  if (my === analyzing) {
    lastAnalysis = a;
    showDiagnostics(a.diagnostics || []);
    showGraph(a.graph);
  }
  return a;
}

function showDiagnostics(list) {
  const ul = $("#diagnostics");
  ul.innerHTML = "";
  const errors = list.filter((d) => d.severity === "error").length;
  $("#diag-count").textContent = list.length ? `${errors} error(s), ${list.length - errors} warning(s)` : "";
  if (!list.length) {
    ul.innerHTML = `<li class="ok">no problems: the mission compiles and its graph checks</li>`;
    return;
  }
  for (const d of list) {
    const li = document.createElement("li");
    li.className = `diagnostic ${d.severity}`;
    li.dataset.line = d.line;
    li.dataset.code = d.code;
    const at = d.line > 0 ? `${d.line}:${d.col}` : "";
    li.innerHTML = `<b>${esc(at)}</b> ${esc(d.severity)}[${esc(d.code)}]: ${esc(d.message)}` +
      (d.hint ? `\n<span class="hint">hint: ${esc(d.hint)}</span>` : "");
    li.onclick = () => {
      if (d.line > 0) {
        cm.focus();
        cm.setCursor({ line: d.line - 1, ch: Math.max(0, d.col - 1) });
      }
    };
    ul.appendChild(li);
  }
}

function showGraph(g) {
  const box = $("#graph");
  const tbody = $("#points tbody");
  if (!g) {
    $("#graph-info").textContent = "(fix the errors to see it)";
    return;
  }
  $("#graph-info").textContent = `${g.name}: ${g.behaviors} behaviors, ${g.robots} robots, ${g.points.length} points`;
  box.innerHTML = g.svg;
  tbody.innerHTML = g.points
    .map((p) => `<tr><td>${esc(p.name)}</td><td>${esc(p.kind)}</td><td>${esc(p.protocol)}</td></tr>`)
    .join("");
  markActive();
}

// The template goes on its own line: `line` if that line is empty, else
// a new line there (what was on it moves down).
function insertTemplate(template, line) {
  line = Math.max(0, Math.min(line, cm.lineCount()));
  if (line < cm.lineCount() && cm.getLine(line).trim() === "") {
    cm.replaceRange(template, { line, ch: 0 }, { line, ch: cm.getLine(line).length });
  } else if (line >= cm.lineCount()) {
    const last = cm.lineCount() - 1;
    cm.replaceRange("\n" + template, { line: last, ch: cm.getLine(last).length });
    line = last + 1;
  } else {
    cm.replaceRange(template + "\n", { line, ch: 0 });
  }
  cm.focus();
  cm.setCursor({ line, ch: template.length });
}

cm.on("drop", (_cm, e) => {
  const template = e.dataTransfer?.getData("application/x-bite-command");
  if (!template) return; // an ordinary text drop
  e.preventDefault();
  const pos = cm.coordsChar({ left: e.clientX, top: e.clientY }, "window");
  insertTemplate(template, pos.line);
});
cm.on("dragover", (_cm, e) => {
  if (e.dataTransfer?.types?.includes("application/x-bite-command")) e.preventDefault();
});

function showLibrary(commands) {
  const ul = $("#commands");
  ul.innerHTML = "";
  for (const c of commands) {
    const li = document.createElement("li");
    li.className = "command";
    li.draggable = true;
    li.dataset.name = c.name;
    li.dataset.template = c.template;
    li.title = `${c.summary || ""}\n\nDrag into the mission, or click to insert:\n${c.template}`;
    const params = c.params
      .map((p) => `<li><b>${esc(p.name)}</b>${p.optional ? " (optional)" : ""}: ${esc(p.type)}${p.doc ? ` — ${esc(p.doc)}` : ""}</li>`)
      .join("");
    li.innerHTML = `<b>${esc(c.name)}</b><code>${esc(c.usage)}</code><p>${esc(c.summary || "")}</p>` +
      (params ? `<ul>${params}</ul>` : "") +
      (c.min_robots > 1 ? `<p class="muted">needs ${c.min_robots} robots or more</p>` : "");
    li.addEventListener("dragstart", (e) => {
      e.dataTransfer.setData("application/x-bite-command", c.template);
      e.dataTransfer.setData("text/plain", c.template);
      e.dataTransfer.effectAllowed = "copy";
    });
    li.addEventListener("click", () => {
      const cur = cm.getCursor();
      const here = cm.getLine(cur.line) ?? "";
      insertTemplate(c.template, here.trim() === "" ? cur.line : cur.line + 1);
    });
    ul.appendChild(li);
  }
}

$("#kind").onchange = () => {
  kind = $("#kind").value;
  cm.setOption("mode", kind === "rtcl" ? "rtcl" : "yaml");
  $("#sidebar").style.opacity = kind === "rtcl" ? 1 : 0.45;
  cm.performLint();
};

// ---------------------------------------------------------------- run, replay

$("#run").onclick = async () => {
  const res = await fetch("/api/run", {
    method: "POST",
    headers: { "content-type": "application/json" },
    body: JSON.stringify({ kind, file: fileName, text: cm.getValue(), pace: Number($("#pace").value) }),
  });
  const a = await res.json().catch(async () => ({ error: `${res.status} ${res.statusText}` }));
  if (!res.ok) {
    showDiagnostics(a.diagnostics || []);
    if (a.error) $("#outcome").title = a.error;
    $("#outcome").textContent = "the mission has errors: not run";
    $("#outcome").className = "failed";
    return;
  }
  follow();
};
$("#graph").onclick = () => $("#graph").classList.toggle("full");
$("#stop").onclick = () => fetch("/api/stop", { method: "POST" });
$("#live").onclick = () => fetch("/api/live", { method: "POST" });
$("#open-log").onchange = async (e) => {
  const f = e.target.files[0];
  if (!f) return;
  const res = await fetch(`/api/replay?name=${encodeURIComponent(f.name)}`, { method: "POST", body: await f.arrayBuffer() });
  if (!res.ok) {
    const why = res.status === 413 ? "the log is larger than the studio takes (512 MiB)"
      : (await res.json().catch(() => ({ error: `${res.status} ${res.statusText}` }))).error;
    $("#outcome").textContent = why;
    $("#outcome").className = "failed";
  }
  e.target.value = "";
};

// ---------------------------------------------------------------- monitor

const M = {
  generation: null, robots: [], layout: null, objects: {}, trails: [],
  decisions: new Map(), inFlight: [], t: 0, end: 0, following: true, live: false,
};
// Where each robot is drawn (x, y, heading), by name.
window.studio.hasLayout = () => !!M.layout;
window.studio.positions = () => Object.fromEntries(M.robots.map((r) => [r.name, r.pose]));
const palette = new Map();

// A colour from a record, only if it is one (`#rrggbb`).
const hex = (c) => (/^#[0-9a-f]{6}$/i.test(c ?? "") ? c : "#dddddd");
function colourOf(behavior) {
  return hex(palette.get(behavior));
}
// Black or white text, whichever reads on `bg` (#rrggbb).
function inkOn(bg) {
  const m = /^#?([0-9a-f]{2})([0-9a-f]{2})([0-9a-f]{2})$/i.exec(bg || "");
  if (!m) return "#111";
  const [r, g, b] = m.slice(1).map((h) => parseInt(h, 16) / 255);
  return 0.2126 * r + 0.7152 * g + 0.0722 * b > 0.5 ? "#111" : "#fff";
}

let ws;
let seekTo = null;
function connect() {
  ws = new WebSocket(`ws://${location.host}/api/monitor`);
  ws.onmessage = (e) => {
    const t0 = performance.now();
    stats.bytes += e.data.length;
    onSnapshot(JSON.parse(e.data));
    stats.applyMs += performance.now() - t0;
  };
  ws.onclose = () => {
    seekInFlight = false;
    setTimeout(connect, 1000);
  };
}
// One seek in flight at a time: the next goes when the studio has
// answered the last (a drag sends far more than it can rebuild).
let seekInFlight = false;
let seekSent = null;
let seekQueued;
function seek(t) {
  M.following = t === null;
  if (seekInFlight) {
    seekQueued = t;
    return;
  }
  if (ws?.readyState === 1) {
    seekInFlight = true;
    seekSent = t;
    ws.send(JSON.stringify({ seek: t }));
  }
}
function follow() {
  seekTo = null;
  seek(null);
}
$("#follow").onclick = follow;
// Scrubbing sends at most one seek a frame.
$("#scrubber").oninput = (e) => {
  const first = seekTo === null;
  seekTo = Number(e.target.value);
  if (first) {
    requestAnimationFrame(() => {
      seek(seekTo);
      seekTo = null;
    });
  }
};

function onSnapshot(s) {
  stats.snapshots++;
  // The studio has moved to the time asked for: the next seek may go.
  if (seekInFlight && (s.at ?? null) === seekSent) {
    seekInFlight = false;
    if (seekQueued !== undefined) {
      const t = seekQueued;
      seekQueued = undefined;
      seek(t);
    }
  }
  if (s.generation !== M.generation || s.reset) {
    if (s.generation !== M.generation) {
      M.layout = null;
      palette.clear();
      M.following = true;
      // A new source starts at its live end: seeks of the old one are moot.
      seekInFlight = false;
      seekQueued = undefined;
    }
    M.generation = s.generation;
    M.trails = [];
    M.decisions = new Map();
  }
  if (s.layout) {
    M.layout = s.layout;
    const bs = s.layout.behaviors || [], pal = s.layout.palette || [];
    bs.forEach((b, i) => pal.length && palette.set(b, pal[i % pal.length]));
  }
  M.robots = s.robots;
  M.objects = s.objects || {};
  M.inFlight = s.in_flight || [];
  M.t = s.t;
  M.end = s.end;
  M.live = s.live;
  M.records = s.records;
  for (const [i, pts] of s.trails) {
    (M.trails[i] ||= []).push(...pts);
  }
  for (const d of s.decisions) M.decisions.set(d.key, d);
  $("#source").textContent = `${s.source}: ${s.label}${s.live ? " (live)" : ""} — ${s.records} records`;
  $("#live").hidden = !window.studio.zenoh || s.source === "zenoh";
  const sc = $("#scrubber");
  sc.max = Math.max(s.end, 0.05).toFixed(2);
  if (document.activeElement !== sc) sc.value = s.t.toFixed(2);
  $("#clock").textContent = `t = ${s.t.toFixed(1)} s / ${s.end.toFixed(1)} s`;
  const out = $("#outcome");
  if (s.ended) {
    const ok = s.ended.outcome === "completed" && !(s.ended.violations || []).length;
    out.textContent = `${s.ended.outcome}${s.ended.violations?.length ? `, ${s.ended.violations.length} violation(s)` : ""} — log ${s.ended.log || ""}`;
    out.className = ok ? "completed" : "failed";
    out.title = s.ended.summary || s.ended.error || "";
  } else if (s.summary) {
    out.textContent = s.summary.outcome;
    out.className = s.summary.outcome === "completed" ? "completed" : "failed";
  } else {
    out.textContent = s.live ? "running" : "";
    out.className = "";
  }
  const dropped = Object.entries(s.dropped || {}).filter(([, n]) => n > 0);
  const droppedLine = dropped.length
    ? [`dropped records: ${dropped.map(([why, n]) => `${n} ${why.replaceAll("_", " ")}`).join(", ")}`]
    : [];
  $("#problems").innerHTML = droppedLine.concat(s.problems || []).map((p) => `<li>${esc(p)}</li>`).join("");
  scheduleDraw();
}

let drawPending = false;
function scheduleDraw() {
  if (drawPending) return;
  drawPending = true;
  requestAnimationFrame(() => {
    drawPending = false;
    stats.frames++;
    for (const f of [drawArena, drawRobots, drawOrg, drawInFlight, drawTimeline, markActive]) {
      const t0 = performance.now();
      try {
        f();
      } catch (e) {
        // One panel's trouble (a malformed record) must not stop the others.
        console.error(e);
      }
      stats.drawMs[f.name] = (stats.drawMs[f.name] || 0) + performance.now() - t0;
    }
  });
}

function drawArena() {
  const canvas = $("#arena");
  const L = M.layout;
  const posed = M.robots.some((r) => r.pose);
  $("#no-arena").hidden = !!(L || posed) || M.generation === 0 || M.records === 0;
  canvas.hidden = !(L || posed);
  if (canvas.hidden) return;
  let [w, h] = L?.arena || [0, 0];
  if (!L) {
    for (const r of M.robots) if (r.pose) { w = Math.max(w, r.pose[0] + 1); h = Math.max(h, r.pose[1] + 1); }
  }
  const cssW = canvas.clientWidth || 640;
  const scale = cssW / Math.max(w, 0.1);
  const cssH = Math.max(80, Math.min(h * scale, 420));
  const k = Math.min(scale, cssH / Math.max(h, 0.1));
  const dpr = window.devicePixelRatio || 1;
  if (canvas.width !== Math.round(cssW * dpr) || canvas.height !== Math.round(cssH * dpr)) {
    canvas.width = Math.round(cssW * dpr);
    canvas.height = Math.round(cssH * dpr);
    canvas.style.height = `${cssH}px`;
  }
  const g = canvas.getContext("2d");
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  g.clearRect(0, 0, cssW, cssH);
  // World → canvas: y up.
  const X = (x) => x * k, Y = (y) => cssH - y * k;
  g.strokeStyle = "#333"; g.lineWidth = 1;
  g.strokeRect(X(0), Y(h), w * k, h * k);
  for (const [name, z] of Object.entries(L?.zones || {})) {
    g.fillStyle = "rgba(46, 160, 67, 0.12)";
    g.fillRect(X(z[0]), Y(z[3]), (z[2] - z[0]) * k, (z[3] - z[1]) * k);
    g.fillStyle = "#2a7a3f"; g.font = "10px sans-serif";
    g.fillText(name, X(z[0]) + 3, Y(z[3]) + 11);
  }
  const shape = (o, at, fill) => {
    g.save();
    g.translate(X(at[0]), Y(at[1]));
    g.rotate(-(o.angle || 0));
    g.fillStyle = fill;
    if (o.shape === "disc") {
      g.beginPath(); g.arc(0, 0, o.size[0] * k, 0, 2 * Math.PI); g.fill();
    } else {
      const [sw, sh] = o.size;
      g.fillRect(-sw * k / 2, -sh * k / 2, sw * k, sh * k);
    }
    g.restore();
  };
  for (const o of L?.obstacles || []) shape(o, o.at, o.colour || "#8a8f99");
  for (const o of L?.objects || []) {
    shape(o, M.objects[o.name] || o.at, o.colour || "#c59d00");
    const at = M.objects[o.name] || o.at;
    g.fillStyle = "#333"; g.font = "10px sans-serif";
    g.fillText(o.name, X(at[0]) + 6, Y(at[1]) - 6);
  }
  // Trajectories, coloured by the behavior run there.
  g.lineWidth = 1.5;
  for (const pts of M.trails) {
    if (!pts) continue;
    for (let i = 1; i < pts.length; i++) {
      g.strokeStyle = hex(pts[i][2]); g.globalAlpha = 0.55;
      g.beginPath(); g.moveTo(X(pts[i - 1][0]), Y(pts[i - 1][1])); g.lineTo(X(pts[i][0]), Y(pts[i][1])); g.stroke();
    }
  }
  g.globalAlpha = 1;
  // Formation links: to the robot whose slot it keeps or whom it follows.
  g.setLineDash([4, 3]); g.strokeStyle = "#555"; g.lineWidth = 1;
  for (const r of M.robots) {
    const o = r.link != null ? M.robots[r.link] : null;
    if (r.pose && o?.pose) {
      g.beginPath(); g.moveTo(X(r.pose[0]), Y(r.pose[1])); g.lineTo(X(o.pose[0]), Y(o.pose[1])); g.stroke();
    }
  }
  g.setLineDash([]);
  const rr = Math.max((L?.robot_radius || 0.12) * k, 3);
  const labels = M.robots.length <= 30;
  for (const r of M.robots) {
    if (!r.pose) continue;
    const [x, y, th] = r.pose;
    g.fillStyle = hex(r.colour); g.strokeStyle = r.crashed ? "#c0392b" : "#222"; g.lineWidth = r.crashed ? 2 : 1;
    g.beginPath(); g.arc(X(x), Y(y), rr, 0, 2 * Math.PI); g.fill(); g.stroke();
    g.beginPath(); g.moveTo(X(x), Y(y)); g.lineTo(X(x) + Math.cos(th) * rr * 1.6, Y(y) - Math.sin(th) * rr * 1.6); g.stroke();
    if (labels) { g.fillStyle = "#111"; g.font = "10px sans-serif"; g.fillText(r.name, X(x) + rr + 2, Y(y) + 3); }
  }
}

const rowCache = new Map();
function drawRobots() {
  const tbody = $("#robots tbody");
  const rows = M.robots.map((r) => {
    const stack = r.stack.map(([b, team]) => `<span class="chip" style="background:${colourOf(b)};color:${inkOn(colourOf(b))}" title="subteam ${esc(team)}">${esc(b)}</span>`).join("›");
    const state = [
      r.completed ? `<span class="flag-done">completed</span>` : "",
      r.crashed ? `<span class="flag-lost">crashed</span>` : "",
      r.phase ? esc(r.phase) : "",
      r.lost.length ? `<span class="flag-lost">lost: ${esc(names(r.lost))}</span>` : "",
      r.informs ? `${r.informs} informs` : "",
    ].filter(Boolean).join("<br>");
    const beliefs = Object.entries(r.beliefs || {}).slice(0, 6)
      .map(([k, v]) => `${esc(k)}=${esc(typeof v === "number" ? +v.toFixed(2) : JSON.stringify(v))}`).join("<br>");
    const auth = r.auth ? `${esc(r.auth.accepted ?? 0)} ok` + Object.entries(r.auth.rejected || {}).map(([k, v]) => `<br>${esc(k)}: ${esc(v)}`).join("") : "";
    return `<tr data-robot="${esc(r.name)}"><td>${esc(r.name)}</td><td class="stack">${stack || "<span class=muted>idle</span>"}</td><td>${state}</td><td>${beliefs}</td><td>${auth}</td></tr>`;
  });
  const html = rows.join("");
  if (rowCache.get("robots") !== html) {
    tbody.innerHTML = html;
    rowCache.set("robots", html);
  }
}

// Subteams as a tree, from the robots' stacks: a frame's subteam is a
// child of the subteam of the frame above it.
function drawOrg() {
  const nodes = new Map();
  const roots = [];
  for (const r of M.robots) {
    let parent = null;
    for (const [b, team] of r.stack) {
      let n = nodes.get(team);
      if (!n) {
        n = { team, behaviors: new Set(), members: new Set(), kids: [] };
        nodes.set(team, n);
        if (parent && parent !== n) parent.kids.push(n); else if (!parent) roots.push(n);
      }
      n.behaviors.add(b);
      n.members.add(r.name);
      parent = n;
    }
  }
  const render = (n) => `<li><b>${esc(n.team)}</b> ${esc([...n.behaviors].join(", "))} <span class="muted">[${esc(names(n.members))}]</span>` +
    (n.kids.length ? `<ul>${n.kids.map(render).join("")}</ul>` : "") + `</li>`;
  const html = roots.length ? `<ul>${roots.map(render).join("")}</ul>` : `<span class="muted">no team behavior running</span>`;
  if (rowCache.get("org") !== html) { $("#org").innerHTML = html; rowCache.set("org", html); }
}

function drawInFlight() {
  const html = M.inFlight.slice(0, 40).map((i) =>
    `<li><b>${esc(i.point)}</b> ${esc(i.protocol)} <span class="muted">subteam ${esc(i.team)}, since ${i.started.toFixed(1)} s; waiting: ${esc(names(i.waiting))}; decided: ${i.decided}; messages ${i.sent} sent, ${i.received} received</span></li>`).join("")
    || `<li class="muted">none</li>`;
  if (rowCache.get("flight") !== html) { $("#in-flight").innerHTML = html; rowCache.set("flight", html); }
}

// One row per point; a mark per joint decision (red: participants
// disagreed, orange: decided on a deadline).
function drawTimeline() {
  const ds = [...M.decisions.values()];
  const points = [...new Set(ds.map((d) => d.point))];
  const W = 600, rowH = 16, left = 170, H = Math.max(1, points.length) * rowH + 22;
  const end = Math.max(M.end, M.t, 1);
  const x = (t) => left + (t / end) * (W - left - 10);
  let s = `<svg viewBox="0 0 ${W} ${H}" height="${H}" font-size="10" font-family="sans-serif">`;
  points.forEach((p, i) => {
    s += `<text x="4" y="${i * rowH + 12}">${esc(p)}</text><line x1="${left}" x2="${W - 10}" y1="${i * rowH + 8}" y2="${i * rowH + 8}" stroke="#eee"/>`;
  });
  for (const d of ds) {
    const i = points.indexOf(d.point);
    const fill = !d.agree ? "#c0392b" : d.timed_out ? "#e67e22" : "#1f5fbf";
    s += `<circle class="decision" cx="${x(d.t).toFixed(1)}" cy="${i * rowH + 8}" r="3.5" fill="${fill}"><title>${esc(d.point)} at ${d.t.toFixed(2)} s (${esc(d.protocol)}, subteam ${esc(d.team)}): ${esc(JSON.stringify(d.outcome))}${d.timed_out ? " — on a deadline" : ""}${d.agree ? "" : " — PARTICIPANTS DISAGREE"}</title></circle>`;
  }
  const ty = points.length * rowH + 16;
  s += `<line x1="${x(M.t)}" x2="${x(M.t)}" y1="0" y2="${ty - 8}" stroke="#d35400"/>`;
  s += `<text x="${left}" y="${ty}">0 s</text><text x="${W - 10}" y="${ty}" text-anchor="end">${end.toFixed(1)} s</text></svg>`;
  if (!ds.length) s = `<p class="muted">no decisions yet</p>`;
  if (rowCache.get("timeline") !== s) { $("#timeline").innerHTML = s; rowCache.set("timeline", s); }
}

// The behaviors some robot runs, marked in the graph.
function markActive() {
  const active = new Set(M.robots.flatMap((r) => r.stack.map(([b]) => b)));
  for (const g of document.querySelectorAll("#graph g.behavior")) {
    g.classList.toggle("active", active.has(g.dataset.behavior));
  }
}

// ---------------------------------------------------------------- start

async function start() {
  const info = await (await fetch("/api/info")).json();
  window.studio.info = info;
  window.studio.zenoh = !!info.zenoh;
  showLibrary(info.library);
  const sc = info.scenario;
  $("#scenario").textContent = `world: ${sc.name}${sc.physical ? ` (${sc.robots} robots)` : " (timed)"}`;
  if (info.file) {
    fileName = info.file.name;
    kind = info.file.kind;
    $("#file-name").textContent = fileName;
    $("#kind").value = kind;
    cm.setOption("mode", kind === "rtcl" ? "rtcl" : "yaml");
    cm.setValue(info.file.text);
  } else {
    cm.setValue("# A mission in the robot team command language: one command per line.\n# Drag commands from the left, or click one to insert it.\n");
  }
  $("#pace").value = String(info.pace);
  connect();
}
start();
