// The operator's console: reads the coordinator's status stream (GET /events, server-sent
// events; the document is described in docs/console.md) and sends actions (POST /api/action).
// It keeps no state of its own beyond the last document and the token the operator typed
// (sessionStorage, this tab only).
"use strict";

const STATES = ["discovered", "calibrating", "verified", "calibrated", "blending", "stalled",
                "failed", "lost"];
const SVG = "http://www.w3.org/2000/svg";
const $ = (id) => document.getElementById(id);

let doc = null;          // the last status document
let selected = null;     // the unit the operator picked (node id) or null
let token = sessionStorage.getItem("sandtable-token") || "";
let streamAbort = null;

function headers(extra) {
  const h = Object.assign({}, extra || {});
  if (token) h["Authorization"] = "Bearer " + token;
  return h;
}

function setLink(state, text) {
  const link = $("link");
  link.dataset.state = state;
  link.textContent = text;
}

function banner(text) {
  const b = $("banner");
  b.hidden = !text;
  b.textContent = text || "";
}

// The stream: fetch (so the token can travel in a header) read as server-sent events.
async function stream() {
  if (streamAbort) streamAbort.abort();
  const abort = new AbortController();
  streamAbort = abort;
  try {
    const response = await fetch("/events", {headers: headers(), signal: abort.signal});
    if (response.status === 401) {
      setLink("lost", "sign in needed");
      banner("This console is not on the coordinator's host: sign in with the site's operator token.");
      return;
    }
    if (!response.ok) throw new Error("HTTP " + response.status);
    setLink("live", "live");
    const reader = response.body.getReader();
    const decoder = new TextDecoder();
    let buffer = "";
    for (;;) {
      const {value, done} = await reader.read();
      if (done) break;
      buffer += decoder.decode(value, {stream: true});
      let end;
      while ((end = buffer.indexOf("\n\n")) >= 0) {
        const event = buffer.slice(0, end);
        buffer = buffer.slice(end + 2);
        const data = event.split("\n").filter((l) => l.startsWith("data: "))
                          .map((l) => l.slice(6)).join("\n");
        if (data) {
          try {
            doc = JSON.parse(data);
            render();
          } catch (e) {
            console.warn("status document not JSON", e);
          }
        }
      }
    }
    throw new Error("the stream ended");
  } catch (e) {
    if (abort.signal.aborted) return;
    setLink("lost", "coordinator unreachable, retrying");
  }
  setTimeout(stream, 1000);
}

function fmt(value, digits, unit) {
  if (value === null || value === undefined || Number.isNaN(value)) return "-";
  return Number(value).toFixed(digits) + (unit ? " " + unit : "");
}

function ago(seconds) {
  if (seconds === null || seconds === undefined) return "-";
  if (seconds < 60) return seconds.toFixed(seconds < 10 ? 1 : 0) + " s";
  if (seconds < 3600) return (seconds / 60).toFixed(0) + " min";
  return (seconds / 3600).toFixed(1) + " h";
}

function bytes(n) {
  if (n < 1024) return n + " B";
  if (n < 1024 * 1024) return (n / 1024).toFixed(1) + " kB";
  return (n / (1024 * 1024)).toFixed(1) + " MB";
}

// The unit's link as the coordinator sees it: its last heartbeat, what came from it.
function linkText(u) {
  const heard = u.heartbeat_age_s === null ? "-" : ago(u.heartbeat_age_s) + " ago";
  if (!u.link) return heard;
  return heard + " · " + u.link.messages_in + " msgs, " + bytes(u.link.bytes_in) + " in";
}

function member(id) {
  return (doc.members || []).find((m) => m.node_id === id);
}

function render() {
  const units = doc.units || [];
  const counts = {};
  for (const u of units) counts[u.state] = (counts[u.state] || 0) + 1;
  $("summary").textContent = units.length + " unit" + (units.length === 1 ? "" : "s") + ": " +
      STATES.filter((s) => counts[s]).map((s) => counts[s] + " " + s).join(", ");
  renderTop(units);
  renderTable(units);
  renderActions(units);
}

function el(name, attrs, parent) {
  const node = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs || {})) node.setAttribute(k, v);
  if (parent) parent.appendChild(node);
  return node;
}

// Top view: x to the right, the table's y up (the SVG's y flipped).
function renderTop(units) {
  const svg = $("top");
  svg.replaceChildren();
  const points = units.flatMap((u) => u.footprint_m || []);
  let [x0, x1, y0, y1] = [-1, 1, -1, 1];
  if (points.length) {
    x0 = Math.min(...points.map((p) => p[0])); x1 = Math.max(...points.map((p) => p[0]));
    y0 = Math.min(...points.map((p) => p[1])); y1 = Math.max(...points.map((p) => p[1]));
  }
  const span = Math.max(x1 - x0, y1 - y0, 0.2);
  const pad = 0.08 * span;
  svg.setAttribute("viewBox",
      [x0 - pad, -y1 - pad, x1 - x0 + 2 * pad, y1 - y0 + 2 * pad].join(" "));
  const grid = el("g", {}, svg);
  const step = span > 4 ? 1 : span > 1.5 ? 0.5 : 0.25;
  for (let x = Math.ceil((x0 - pad) / step) * step; x <= x1 + pad; x += step) {
    el("line", {class: Math.abs(x) < 1e-9 ? "axis" : "grid", x1: x, x2: x, y1: -y1 - pad,
                y2: -y0 + pad}, grid);
  }
  for (let y = Math.ceil((y0 - pad) / step) * step; y <= y1 + pad; y += step) {
    el("line", {class: Math.abs(y) < 1e-9 ? "axis" : "grid", y1: -y, y2: -y, x1: x0 - pad,
                x2: x1 + pad}, grid);
  }
  const font = 0.035 * span;
  // Scale bar: one grid step, bottom left.
  const sx = x0 - pad * 0.6, sy = -y0 + pad * 0.6;
  el("line", {class: "scale", x1: sx, x2: sx + step, y1: sy, y2: sy}, svg);
  const label = el("text", {class: "scale-text", x: sx, y: sy - font * 0.4,
                            "font-size": font}, svg);
  label.textContent = step + " m";
  if (!points.length) {
    const t = el("text", {class: "empty", x: 0, y: 0, "font-size": font}, svg);
    t.textContent = units.length ? "no unit holds a calibration yet" : "no units";
  }
  for (const u of units) {
    const fp = u.footprint_m || [];
    if (fp.length < 3) continue;
    const poly = el("polygon", {
      class: "footprint" + (u.node_id === selected ? " selected" : ""),
      points: fp.map((p) => p[0] + "," + (-p[1])).join(" "),
      fill: `var(--${u.state})`, stroke: `var(--${u.state})`,
      "data-unit-id": u.node_id, "data-state": u.state,
    }, svg);
    poly.addEventListener("click", () => {
      if ($("annotation-tool").value === "view") select(u.node_id);
    });
    const title = el("title", {}, poly);
    title.textContent = "unit " + u.node_id + ": " + u.state;
    const cx = fp.reduce((a, p) => a + p[0], 0) / fp.length;
    const cy = fp.reduce((a, p) => a + p[1], 0) / fp.length;
    const text = el("text", {class: "label", x: cx, y: -cy, "font-size": font * 1.3,
                             "stroke-width": font * 0.15}, svg);
    text.textContent = u.node_id;
  }
  drawPending(svg);
  const legend = $("legend");
  legend.replaceChildren(...STATES.map((s) => {
    const li = document.createElement("li");
    li.textContent = s;
    li.style.setProperty("--swatch", `var(--${s})`);
    return li;
  }));
}

function renderTable(units) {
  const body = $("units").tBodies[0];
  body.replaceChildren(...units.map((u) => {
    const m = member(u.node_id);
    const tr = document.createElement("tr");
    tr.dataset.unitId = u.node_id;
    tr.dataset.state = u.state;
    if (u.node_id === selected) tr.className = "selected";
    const cells = [
      String(u.node_id),
      null,
      ago(u.since_s),
      (u.host_name || "-") + (m ? " " + m.peer_router : ""),
      u.predicted_rms_mm > 0 ? fmt(u.predicted_rms_mm, 2, "mm") : "-",
      u.frame_ms_p50 > 0 ? fmt(u.frame_ms_p50, 1) + " / " + fmt(u.frame_ms_p99, 1, "ms") : "-",
      u.pattern && u.pattern !== "none" ? u.pattern : "show",
      linkText(u),
      u.last_error || "",
    ];
    cells.forEach((text, i) => {
      const td = document.createElement("td");
      if (i === 1) {
        const badge = document.createElement("span");
        badge.className = "state";
        badge.style.setProperty("--swatch", `var(--${u.state})`);
        badge.textContent = u.state;
        td.appendChild(badge);
      } else {
        td.textContent = text;
      }
      if (i === 8) td.className = "error";
      tr.appendChild(td);
    });
    tr.addEventListener("click", () => select(u.node_id));
    return tr;
  }));
}

// A unit picker: `all` (labelled `allLabel`) and every unit not lost; keeps the choice while
// it is still offered (or takes `preferred` when it is), else `all`.
function fillUnitSelect(select, allLabel, units, preferred = null) {
  const keep = select.value;
  select.replaceChildren(new Option(allLabel, "all"),
      ...units.filter((u) => u.state !== "lost").map((u) => new Option("unit " + u.node_id,
                                                                       String(u.node_id))));
  const offered = (value) => [...select.options].some((o) => o.value === value);
  select.value = preferred !== null && offered(String(preferred)) ? String(preferred)
      : (offered(keep) ? keep : "all");
}

function renderActions(units) {
  fillUnitSelect($("pattern-target"), "every unit", units, selected);
  fillUnitSelect($("recalibrate-target"), "the whole site", units);
  const r = doc.recalibration;
  $("recalibration-state").textContent = !r ? "-"
      : r.ask_id === 0 ? "not asked since the coordinator started"
      : `ask ${r.ask_id}: ${r.all_units ? "the whole site" : "unit " + r.node_id}`;
  const t = doc.timeline;
  $("timeline-state").textContent = t
      ? `${t.playing ? "playing" : "paused"} at ${t.media_time_s.toFixed(1)} of ` +
        `${t.duration_s.toFixed(0)} s, rate ${t.rate}`
      : "no timeline loaded";
  const a = doc.annotations;
  $("annotations-state").textContent = a ? a.strokes + (a.strokes === 1 ? " stroke" : " strokes") : "-";
  const list = $("enrollment");
  const asking = (doc.enrollment && doc.enrollment.units) || [];
  $("enrollment-row").hidden = !(doc.enrollment && doc.enrollment.on);
  list.replaceChildren(...asking.map((e) => {
    const li = document.createElement("li");
    li.textContent = `${e.fingerprint} ${e.host_name || "?"} (${e.address}, id ${e.node_id}) ` +
                     `${e.state} `;
    if (e.state === "pending") {
      for (const verb of ["accept", "refuse"]) {
        const b = document.createElement("button");
        b.textContent = verb === "accept" ? "Accept" : "Refuse";
        b.dataset.action = "";
        b.addEventListener("click", () => act({action: "enrollment", [verb]: e.fingerprint}));
        li.appendChild(b);
      }
    }
    return li;
  }));
  const canAct = !!token;
  for (const b of document.querySelectorAll("[data-action]")) b.disabled = !canAct;
  $("actions-note").textContent = canAct ? "" : "(read-only: sign in with the operator token)";
}

function select(id) {
  selected = selected === id ? null : id;
  if (doc) render();
}

// The stroke being drawn on the top view (table metres), shown until it is sent.
let pending = null;

function drawPending(svg) {
  if (!pending || pending.points.length < 1) return;
  el("polyline", {class: "pending", id: "pending",
                  points: pending.points.map((p) => p[0] + "," + (-p[1])).join(" "),
                  stroke: pending.colour, "stroke-width": pending.width_m}, svg);
}

// A pointer event's place on the table (metres, table frame; the table top is z = 0).
function tablePoint(e) {
  const svg = $("top");
  const pt = svg.createSVGPoint();
  pt.x = e.clientX;
  pt.y = e.clientY;
  const p = pt.matrixTransform(svg.getScreenCTM().inverse());
  return [p.x, -p.y, 0];
}

function rgb01(hex) {
  return [1, 3, 5].map((i) => Number.parseInt(hex.slice(i, i + 2), 16) / 255);
}

function wireDrawing() {
  const svg = $("top");
  const tool = () => (token ? $("annotation-tool").value : "view");
  $("annotation-tool").addEventListener("change", () => { svg.classList.value = tool(); });
  svg.addEventListener("pointerdown", (e) => {
    if (tool() === "erase") {
      act({action: "annotation_erase", center_in_table_m: tablePoint(e),
           radius_m: Number($("erase-radius").value) / 1000});
      return;
    }
    if (tool() !== "draw") return;
    e.preventDefault();
    svg.setPointerCapture(e.pointerId);
    pending = {points: [tablePoint(e)], colour: $("annotation-colour").value,
               width_m: Number($("annotation-width").value) / 1000};
    drawPending(svg);
  });
  svg.addEventListener("pointermove", (e) => {
    if (!pending) return;
    const p = tablePoint(e), last = pending.points[pending.points.length - 1];
    if (Math.hypot(p[0] - last[0], p[1] - last[1]) < 0.002) return;  // 2 mm apart at least
    pending.points.push(p);
    const old = $("pending");
    if (old) old.remove();
    drawPending(svg);
  });
  const finish = async () => {
    if (!pending) return;
    const stroke = pending;
    await act({action: "annotation_stroke", color_rgb: rgb01(stroke.colour),
               width_m: stroke.width_m, points_in_table_m: stroke.points});
    if (pending === stroke) pending = null;
    const old = $("pending");
    if (old) old.remove();
  };
  svg.addEventListener("pointerup", finish);
  svg.addEventListener("pointercancel", finish);
}

async function act(body) {
  const result = $("result");
  result.className = "result";
  result.textContent = "sending " + body.action + " ...";
  try {
    const response = await fetch("/api/action", {
      method: "POST", headers: headers({"Content-Type": "application/json"}),
      body: JSON.stringify(body)});
    let answer = {};
    try { answer = await response.json(); } catch (e) { answer = {message: await response.text()}; }
    result.className = response.ok ? "result" : "result bad";
    result.textContent = (response.ok ? "done: " : "refused (" + response.status + "): ") +
                         (answer.message || "");
    return response.ok ? answer : null;
  } catch (e) {
    result.className = "result bad";
    result.textContent = "not sent: " + e.message;
    return null;
  }
}

function wire() {
  $("login").addEventListener("submit", (e) => {
    e.preventDefault();
    token = $("token").value.trim();
    sessionStorage.setItem("sandtable-token", token);
    $("token").value = "";
    $("logout").hidden = !token;
    banner("");
    stream();
  });
  $("logout").hidden = !token;
  $("logout").addEventListener("click", () => {
    token = "";
    sessionStorage.removeItem("sandtable-token");
    $("logout").hidden = true;
    stream();
  });
  $("pattern-apply").addEventListener("click", () => {
    const target = $("pattern-target").value;
    const body = {action: "test_pattern", pattern: $("pattern").value};
    if (target !== "all") body.node_id = Number(target);
    act(body);
  });
  $("recalibrate-apply").addEventListener("click", () => {
    const target = $("recalibrate-target").value;
    const what = target === "all" ? "every unit of the site" : "unit " + target;
    if (!confirm(`Calibrate ${what} again? Its projectors show structured light meanwhile.`)) {
      return;
    }
    const body = {action: "recalibrate"};
    if (target !== "all") body.node_id = Number(target);
    act(body);
  });
  $("play").addEventListener("click", () => act({action: "timeline", op: "play"}));
  $("pause").addEventListener("click", () => act({action: "timeline", op: "pause"}));
  $("seek-apply").addEventListener("click",
      () => act({action: "timeline", op: "seek", value: Number($("seek").value)}));
  $("rate-apply").addEventListener("click",
      () => act({action: "timeline", op: "rate", value: Number($("rate").value)}));
  $("export").addEventListener("click", async () => {
    const answer = await act({action: "annotations_export"});
    if (!answer || typeof answer.session !== "string") return;
    const stamp = new Date().toISOString().replace(/[:.]/g, "-").slice(0, 19);
    const a = document.createElement("a");
    a.href = URL.createObjectURL(new Blob([answer.session], {type: "application/x-ndjson"}));
    a.download = "annotations-" + stamp + ".jsonl";
    document.body.appendChild(a);
    a.click();
    a.remove();
  });
  $("import").addEventListener("change", async () => {
    const file = $("import").files[0];
    if (!file) return;
    const text = await file.text();
    $("import").value = "";
    if (!confirm(`Replace every stroke on the table with those of ${file.name}?`)) return;
    act({action: "annotations_import", session: text});
  });
  $("clear").addEventListener("click", () => {
    if (confirm("Clear every annotation stroke on the table? This cannot be undone.")) {
      act({action: "annotations_clear"});
    }
  });
}

wire();
wireDrawing();
stream();
