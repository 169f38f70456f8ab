"use strict";
// The live view of one e-FSM model: states, a transition matrix, the model's history.
// Loads the states and the history once, then follows the model's server-sent events; never
// polls the snapshot.

const FLAG_COLOURS = { collision: "#d62728", large_distance: "#ff9f1c" };
const NONE_COLOUR = "#7a8794";
const OTHER_COLOUR = "#9467bd";
const SERIES_COLOUR = "#1f77b4";
const KEEP_DECISIONS = 300;
const KEEP_ROWS = 1024;  // history rows on the page; past that every other one is dropped
const KEEP_STATE_POINTS = 4000;
// The car-following observation's units (ReviseRequest.observation); other names show none.
const UNITS = { v_ego: "m/s", v_lead: "m/s", headway: "m" };
const $ = (id) => document.getElementById(id);

const view = {
  model: null, token: "", source: null, config: null, states: [], dims: [0, 0], points: {},
  rows: [], totals: null, stride: 1, stateSteps: [], decisions: [], streams: new Set(), picked: null,
  positions: [], dirty: false, tpmTimer: null, pending: null,
  drawn: {},  // per canvas, what its last drawing showed: points and tick labels (for tests)
};

function authHeaders() { return view.token ? { Authorization: "Bearer " + view.token } : {}; }

async function api(path) {
  const response = await fetch(path, { headers: authHeaders() });
  if (!response.ok) {
    let message = response.statusText;
    try { message = (await response.json()).error.message; } catch (_) { /* not JSON */ }
    throw new Error(response.status + " " + message);
  }
  return response;
}

function setStatus(text) { $("status").textContent = text; }

async function connect() {
  view.token = $("token").value.trim();
  if (view.source) view.source.close();
  try {
    const { models } = await (await api("/models")).json();
    const select = $("model");
    const chosen = select.value || new URLSearchParams(location.search).get("model") || "default";
    select.replaceChildren(...models.map((m) => new Option(m.name, m.name)));
    select.value = models.some((m) => m.name === chosen) ? chosen : models[0].name;
    view.model = select.value;
    await load();
    subscribe();
  } catch (error) {
    setStatus("no data: " + error.message);
  }
}

// A row of the history: the model's totals when an episode ended (GET .../history).
function rowOf(t) {
  return { episodes: t.episodes, steps: t.steps, n_states: t.n_states,
    interventions: { ...t.interventions }, failures: { ...t.failures } };
}

async function load() {
  const [doc, history] = await Promise.all([
    api(`/models/${view.model}?tpm=none&exact=false`).then((r) => r.json()),
    api(`/models/${view.model}/history`).then((r) => r.json())]);
  view.config = doc.config;
  view.states = doc.states;
  view.points = doc.failure_points || {};
  const trial = doc.trial;
  $("trial").textContent = trial ? `trial of itself: ${trial.shielded.episodes} episodes shielded`
    + ` (${trial.shielded.failed} failed), ${trial.audited.episodes} audited (${trial.audited.failed} failed)` : "";
  view.decisions = []; view.streams.clear();
  view.rows = history.episodes.map((episodes, k) => ({
    episodes, steps: history.steps[k], n_states: history.n_states[k],
    interventions: Object.fromEntries(Object.entries(history.interventions).map(([c, v]) => [c, v[k]])),
    failures: Object.fromEntries(Object.entries(history.failures).map(([c, v]) => [c, v[k]])),
  }));
  view.totals = history.totals;
  view.stride = history.stride;
  view.stateSteps = view.rows.map((r) => [r.steps, r.n_states]);
  $("state-count").textContent = String(history.totals.n_states);
  const names = doc.config.observation.names;
  const x = names.indexOf("headway"), y = names.indexOf("v_ego");
  view.dims = x >= 0 && y >= 0 ? [x, y] : [0, Math.min(1, names.length - 1)];
  const bins = Math.round((doc.config.action.high - doc.config.action.low) / doc.config.action.step);
  const action = $("action");
  if (action.options.length !== bins) {
    action.replaceChildren(...Array.from({ length: bins }, (_, b) => new Option(String(b), String(b))));
    action.value = String(Math.floor(bins * 0.75));
  }
  view.dirty = true;
  drawTpm();
}

function subscribe() {
  const query = view.token ? "?token=" + encodeURIComponent(view.token) : "";
  view.source = new EventSource(`/models/${view.model}/events${query}`);
  view.source.onopen = () => setStatus("live: " + view.model);
  view.source.onerror = () => setStatus("reconnecting...");
  view.source.onmessage = (message) => {
    const event = JSON.parse(message.data);
    if (event.type === "hello") resync(event).catch((error) => setStatus("no data: " + error.message));
    else if (view.pending) view.pending.push(event);
    else handle(event);
  };
  clearInterval(view.tpmTimer);
  view.tpmTimer = setInterval(drawTpm, 15000);  // one matrix, not the snapshot
}

// The feed starts (or restarts, after a lost connection) at the model's version in its hello;
// steps taken since the page loaded and before that are not in the feed: load again, and
// hold the feed's events meanwhile.
async function resync(hello) {
  if (hello.model_version === view.totals.model_version) return;
  view.pending = [];
  try {
    await load();
  } finally {
    const pending = view.pending;
    view.pending = null;
    pending.forEach(handle);
  }
}

function handle(event) {
  if (event.type !== "step") return;
  const d = event.decision, t = view.totals;
  view.streams.add(d.stream);
  view.decisions.push(d);
  if (view.decisions.length > KEEP_DECISIONS) view.decisions.shift();
  view.dirty = true;
  // a learning step the loaded totals do not hold yet (what-if steps change nothing)
  if (!event.learn || d.model_version <= t.model_version) return;
  if (event.state) view.states[event.state.index] = event.state;  // as of after this step
  else if (d.state !== null && view.states[d.state]) view.states[d.state].visits += 1;
  t.steps += 1; t.model_version = d.model_version;
  if (event.event) t.failures[event.event] = (t.failures[event.event] || 0) + 1;
  if (d.revised && !d.shadow) t.interventions[d.verdict] = (t.interventions[d.verdict] || 0) + 1;
  if (d.n_states !== t.n_states) view.stateSteps.push([t.steps, d.n_states]);
  t.n_states = d.n_states;
  if (d.reason === "done") {
    t.episodes = d.episode;
    view.rows.push(rowOf(t));
  }
  if (view.rows.length > KEEP_ROWS) view.rows = thinned(view.rows);
  if (view.stateSteps.length > KEEP_STATE_POINTS) view.stateSteps = thinned(view.stateSteps);
  $("state-count").textContent = String(d.n_states);
}

// Every other element, the last kept: rows hold totals, so fewer of them still tell the rates.
function thinned(items) {
  return items.filter((_, k) => (items.length - 1 - k) % 2 === 0);
}

function colourOf(flag) {
  if (flag === null || flag === undefined) return NONE_COLOUR;
  return FLAG_COLOURS[flag] || OTHER_COLOUR;
}

// --- axes ------------------------------------------------------------------------------------

// Round tick values over [lo, hi]: steps of 1, 2 or 5 times a power of ten, about `count` of
// them (whole numbers only where `integer`).
function ticks(lo, hi, count, integer = false) {
  if (!(hi > lo)) hi = lo + 1;
  const rough = (hi - lo) / count, power = 10 ** Math.floor(Math.log10(rough));
  const nice = [1, 2, 5, 10].map((m) => m * power).find((s) => s >= rough);
  const step = integer ? Math.max(1, nice) : nice;
  const values = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) {
    values.push(Math.abs(v) < step * 1e-9 ? 0 : v);
  }
  return { values, step };
}

// A tick's label: as many decimals as its step needs; thousands as "k", millions as "M".
function tickLabel(v, step) {
  for (const [scale, suffix] of [[1e6, "M"], [1e3, "k"]]) {
    if (step >= scale / 10 && Math.abs(v) >= scale) {
      return +(v / scale).toFixed(Math.max(0, Math.ceil(-Math.log10(step / scale)))) + suffix;
    }
  }
  return v.toFixed(Math.max(0, Math.ceil(-Math.log10(step))));
}

function withUnit(name) { return UNITS[name] ? `${name} [${UNITS[name]}]` : name; }

// A frame with tick values and titles around the box `box` ({left, top, width, height}) for
// data in [x0, x1] x [y0, y1] (y0 at the bottom; reversed when y0 > y1), with grid lines unless
// over an image (`grid` false: tick marks outside); returns the scales and records the ticks.
function axes(ctx, id, box, [x0, x1], [y0, y1], xTitle, yTitle,
  { xCount = 6, yCount = 4, grid = true, integer = false } = {}) {
  const sx = (v) => box.left + (v - x0) / (x1 - x0) * box.width;
  const sy = (v) => box.top + box.height - (v - y0) / (y1 - y0) * box.height;
  const xt = ticks(Math.min(x0, x1), Math.max(x0, x1), xCount, integer);
  const yt = ticks(Math.min(y0, y1), Math.max(y0, y1), yCount, integer);
  const bottom = box.top + box.height, outside = grid ? 0 : 4;
  ctx.font = "11px sans-serif"; ctx.lineWidth = 1;
  ctx.strokeStyle = grid ? "#eceef1" : "#aab"; ctx.fillStyle = "#555";
  ctx.textAlign = "center"; ctx.textBaseline = "top";
  for (const v of xt.values) {
    const x = Math.round(sx(v)) + 0.5;
    ctx.beginPath(); ctx.moveTo(x, grid ? box.top : bottom); ctx.lineTo(x, bottom + outside);
    ctx.stroke();
    ctx.fillText(tickLabel(v, xt.step), x, bottom + 4 + outside);
  }
  ctx.textAlign = "right"; ctx.textBaseline = "middle";
  for (const v of yt.values) {
    const y = Math.round(sy(v)) + 0.5;
    ctx.beginPath(); ctx.moveTo(grid ? box.left + box.width : box.left, y);
    ctx.lineTo(box.left - outside, y); ctx.stroke();
    ctx.fillText(tickLabel(v, yt.step), box.left - 4 - outside, y);
  }
  ctx.strokeStyle = "#aab"; ctx.strokeRect(box.left + 0.5, box.top + 0.5, box.width, box.height);
  ctx.fillStyle = "#333"; ctx.font = "12px sans-serif";
  ctx.textAlign = "center"; ctx.textBaseline = "bottom";
  ctx.fillText(xTitle, box.left + box.width / 2, ctx.canvas.height - 2);
  ctx.save(); ctx.translate(2, box.top + box.height / 2); ctx.rotate(-Math.PI / 2);
  ctx.textBaseline = "top"; ctx.fillText(yTitle, 0, 0); ctx.restore();
  view.drawn[id] = { points: 0, xTicks: xt.values.map((v) => tickLabel(v, xt.step)),
    yTicks: yt.values.map((v) => tickLabel(v, yt.step)), xTitle, yTitle };
  return { sx, sy };
}

function drawStates() {
  const canvas = $("states"), ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!view.config) return;
  const [dx, dy] = view.dims, obs = view.config.observation;
  // the axes span the normalisation bounds and every state beyond them (a headway above its
  // bound normalises above 1 and is still a state)
  const span = (d) => {
    const centres = view.states.filter(Boolean).map((s) => s.centre[d])
      .concat(...Object.values(view.points).map((ps) => ps.map((p) => p[d])));
    return [Math.min(obs.low[d], ...centres), Math.max(obs.high[d], ...centres)];
  };
  const box = { left: 56, top: 12, width: canvas.width - 70, height: canvas.height - 56 };
  const { sx, sy } = axes(ctx, "states", box, span(dx), span(dy), withUnit(obs.names[dx]),
    withUnit(obs.names[dy]), { xCount: 10, yCount: 6 });
  view.positions = [];
  for (const s of view.states) {
    if (!s) continue;
    const x = sx(s.centre[dx]), y = sy(s.centre[dy]);
    const r = 3 + Math.min(12, Math.sqrt(s.visits) / 2);
    ctx.beginPath(); ctx.arc(x, y, r, 0, 2 * Math.PI);
    ctx.fillStyle = colourOf(s.flag); ctx.globalAlpha = 0.75; ctx.fill(); ctx.globalAlpha = 1;
    if (s.index === view.picked) { ctx.lineWidth = 2; ctx.strokeStyle = "#000"; ctx.stroke(); }
    view.positions.push([s.index, x, y]);
  }
  view.drawn.states.points = view.positions.length;
  ctx.lineWidth = 1.5;  // where the reach keeps each criterion's failures, as of the last load
  for (const [name, points] of Object.entries(view.points)) {
    ctx.strokeStyle = colourOf(name);
    for (const p of points) {
      const x = sx(p[dx]), y = sy(p[dy]);
      ctx.beginPath(); ctx.moveTo(x - 4, y - 4); ctx.lineTo(x + 4, y + 4);
      ctx.moveTo(x + 4, y - 4); ctx.lineTo(x - 4, y + 4); ctx.stroke();
    }
  }
}

async function pickState(event) {
  const canvas = $("states"), box = canvas.getBoundingClientRect();
  const x = (event.clientX - box.left) * canvas.width / box.width;
  const y = (event.clientY - box.top) * canvas.height / box.height;
  let best = null, bestDistance = 15 * 15;
  for (const [index, px, py] of view.positions) {
    const distance = (px - x) ** 2 + (py - y) ** 2;
    if (distance < bestDistance) { best = index; bestDistance = distance; }
  }
  if (best === null) return;
  view.picked = best; view.dirty = true;
  const detail = await (await api(`/models/${view.model}/states/${best}?top=3`)).json();
  const failures = Object.entries(detail.failures).filter(([, n]) => n > 0)
    .map(([name, n]) => `${n} ${name.replace("_", " ")}`).join(", ") || "no failures";
  const record = detail.record;
  const watched = record.revised + record.passed === 0 ? "" : `; the shield's revisions here: `
    + `${record.revised} steps, ${record.revised_failed} followed by a failure, against `
    + `${record.passed_failed} of ${record.passed} passed`
    + (detail.backed_off ? " (backed off: it passes the proposals here)" : "");
  $("picked").textContent =
    `#${best} (${detail.flag || "favourable"}, ${detail.visits} visits, ${failures}${watched})`;
  const rows = detail.next.map((a) => `<tr><td>${a.bin}</td><td>${a.states.map(
    (s) => `#${s.state} ${(100 * s.prob).toFixed(1)}%`).join(", ")}</td></tr>`).join("");
  $("state-detail").innerHTML = `<p>centre ${detail.centre.map((v) => v.toFixed(1)).join(", ")}</p>`
    + `<table id="next-states"><thead><tr><th>action bin</th><th>most likely next states</th></tr></thead>`
    + `<tbody>${rows}</tbody></table>`;
}

// A probability's colour: white to dark blue over its square root, so that small ones show.
function heat(p) {
  const v = Math.sqrt(p);
  return [255 - 200 * v, 255 - 140 * v, 255 - 60 * v];
}

async function drawTpm() {
  if (!view.model) return;
  const action = $("action").value;
  let doc;
  try {
    doc = await (await api(`/models/${view.model}?tpm=sparse&action=${action}&exact=false&min_prob=0.001`)).json();
  } catch (error) { setStatus("no data: " + error.message); return; }
  const canvas = $("tpm"), ctx = canvas.getContext("2d"), n = doc.n_states;
  const side = Math.min(canvas.width - 130, canvas.height - 56);
  const box = { left: 56, top: 12, width: side, height: side };
  const bins = Math.max(1, Math.min(n, side));  // at most one cell per pixel
  const cells = new Float32Array(bins * bins);
  const [m] = doc.tpm.matrices;
  for (let k = 0; k < m.rows.length; k += 1) {  // bin the sparse entries, keeping maxima
    const cell = Math.floor(m.rows[k] * bins / n) * bins + Math.floor(m.cols[k] * bins / n);
    if (m.probs[k] > cells[cell]) cells[cell] = m.probs[k];
  }
  const small = document.createElement("canvas");
  small.width = bins; small.height = bins;
  const smallCtx = small.getContext("2d"), image = smallCtx.createImageData(bins, bins);
  for (let p = 0; p < cells.length; p += 1) image.data.set([...heat(cells[p]), 255], 4 * p);
  smallCtx.putImageData(image, 0, 0);
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.imageSmoothingEnabled = false;
  ctx.drawImage(small, box.left, box.top, box.width, box.height);
  // state k's row and column span [k - 1/2, k + 1/2]: a tick names the state at its centre;
  // row 0 at the top
  const end = Math.max(n, 1) - 0.5;
  axes(ctx, "tpm", box, [-0.5, end], [end, -0.5], "to state (column)",
    "from state (row)", { xCount: 6, yCount: 6, grid: false, integer: true });
  view.drawn.tpm.points = m.rows.length;
  colourScale(ctx, { left: box.left + box.width + 18, top: box.top, width: 14,
    height: box.height });
  $("tpm-note").textContent = `action bin ${action}: ${n} x ${n}, ${m.rows.length} entries >= 0.001`
    + (bins < n ? `; one cell per ${(n / bins).toFixed(1)} states, showing their largest` : "");
}

// The colour bar of the matrix: probability 0 (bottom) to 1 (top), on the square-root scale
// the cells use, with its tick values.
function colourScale(ctx, box) {
  const y = (p) => box.top + box.height * (1 - Math.sqrt(p));
  for (let py = 0; py < box.height; py += 1) {
    const v = 1 - py / box.height;
    ctx.fillStyle = `rgb(${heat(v * v).join(",")})`;
    ctx.fillRect(box.left, box.top + py, box.width, 1);
  }
  ctx.strokeStyle = "#aab"; ctx.strokeRect(box.left + 0.5, box.top + 0.5, box.width, box.height);
  ctx.fillStyle = "#555"; ctx.font = "11px sans-serif";
  ctx.textAlign = "left"; ctx.textBaseline = "middle";
  const labels = [0, 0.01, 0.05, 0.1, 0.25, 0.5, 1];
  for (const p of labels) {
    ctx.fillRect(box.left + box.width, Math.round(y(p)), 4, 1);
    ctx.fillText(String(p), box.left + box.width + 6, y(p));
  }
  ctx.save(); ctx.translate(ctx.canvas.width - 2, box.top + box.height / 2);
  ctx.rotate(Math.PI / 2); ctx.textAlign = "center"; ctx.textBaseline = "top";
  ctx.fillStyle = "#333"; ctx.font = "12px sans-serif";
  ctx.fillText("transition probability", 0, 0); ctx.restore();
  view.drawn.tpm.scale = labels.map(String);
}

// Lines with dots (`step`: a staircase, for a count that holds between changes) over labelled
// axes; a legend when there are several series.
function chart(id, series, xTitle, yTitle, { yMin = 0, step = false } = {}) {
  const canvas = $(id), ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  const points = series.flatMap((s) => s.points);
  const xs = points.map((p) => p[0]), ys = points.map((p) => p[1]);
  const x0 = xs.length ? Math.min(...xs) : 0, x1 = Math.max(...xs, x0 + 1);
  const top = Math.max(...ys, yMin), y1 = top > yMin ? top : yMin + 1;
  const box = { left: 56, top: 10, width: canvas.width - 70, height: canvas.height - 54 };
  const { sx, sy } = axes(ctx, id, box, [x0, x1], [yMin, y1 * 1.05], xTitle, yTitle);
  ctx.lineWidth = 1.5;
  for (const s of series) {
    ctx.strokeStyle = ctx.fillStyle = s.colour;
    ctx.beginPath();
    s.points.forEach(([x, y], k) => {
      if (k === 0) ctx.moveTo(sx(x), sy(y));
      else if (step) ctx.lineTo(sx(x), sy(s.points[k - 1][1]));
      ctx.lineTo(sx(x), sy(y));
    });
    ctx.stroke();
    if (s.points.length <= 120) {
      for (const [x, y] of s.points) { ctx.beginPath(); ctx.arc(sx(x), sy(y), 2, 0, 2 * Math.PI); ctx.fill(); }
    }
  }
  if (series.length > 1) {
    ctx.font = "11px sans-serif"; ctx.textAlign = "left"; ctx.textBaseline = "middle";
    series.forEach((s, k) => {
      const y = box.top + 10 + 14 * k;
      ctx.fillStyle = s.colour; ctx.fillRect(box.left + 8, y - 1, 12, 3);
      ctx.fillStyle = "#333"; ctx.fillText(s.name, box.left + 24, y);
    });
  }
  view.drawn[id].points = points.length;
}

// Per window between two history rows (an episode, or `stride` of them): what happened in it,
// from the difference of the totals; the first window starts at the model's start.
function windows() {
  const zero = { episodes: 0, steps: 0, interventions: {}, failures: {} };
  return view.rows.map((row, k) => {
    const before = k ? view.rows[k - 1] : zero;
    return { episode: row.episodes, episodes: row.episodes - before.episodes,
      actions: (row.steps - before.steps) - (row.episodes - before.episodes),
      revised: (c) => row.interventions[c] - (before.interventions[c] || 0) };
  });
}

function drawCharts() {
  const criteria = view.config ? view.config.criteria.map((c) => c.name) : [];
  const spans = windows();
  const episodes = view.totals ? view.totals.episodes : 0;
  $("history-note").textContent = `since the model's start: ${episodes} episodes, `
    + `${view.rows.length} points (` + (view.stride > 1
    ? `one every ${view.stride} episodes as loaded, then one per episode)` : "one per episode)");
  chart("chart-revisions", criteria.map((name) => ({ name, colour: colourOf(name),
    points: spans.map((w) => [w.episode, w.revised(name) / w.episodes]) })),
  "episode", "revisions per episode");
  chart("chart-share", [{ name: "revised", colour: SERIES_COLOUR,
    points: spans.filter((w) => w.actions > 0).map((w) => [w.episode,
      100 * criteria.reduce((sum, c) => sum + w.revised(c), 0) / w.actions]) }],
  "episode", "revised actions [%]");
  const states = [...view.stateSteps];
  if (view.totals) states.push([view.totals.steps, view.totals.n_states]);
  chart("chart-states", [{ name: "states", colour: "#2ca02c", points: states }],
    "learning steps", "states", { step: true });
  const start = [[0, 0]];
  chart("chart-failures", criteria.map((name) => ({ name, colour: colourOf(name),
    points: start.concat(view.rows.map((r) => [r.episodes, r.failures[name] || 0])) })),
  "episode", "failures so far");
}

function drawDecisions() {
  const select = $("stream");
  const streams = [...view.streams].sort();
  if (select.options.length !== streams.length) {
    const chosen = select.value;
    select.replaceChildren(...streams.map((s) => new Option(s, s)));
    if (streams.includes(chosen)) select.value = chosen;
  }
  const rows = view.decisions.filter((d) => d.stream === select.value).slice(-12).reverse();
  const number = (v) => (v === null || v === undefined ? "-" : Number(v).toFixed(3));
  $("decisions").tBodies[0].innerHTML = rows.map((d) => `<tr><td>${d.episode}:${d.step}</td>`
    + `<td>${number(d.proposed)}</td><td class="${d.revised ? "revised" : ""}">${number(d.action)}</td>`
    + `<td>${d.reason}</td><td>${Object.entries(d.risk).map(([k, v]) => `${k} ${number(v)}`).join(", ")}</td>`
    + `<td>${number(d.threshold)}</td><td>${d.candidates.map((c) => `${c.bin}:${c.verdict}${c.risk ? ` (${number(Object.values(c.risk).reduce((a, b) => a + b, 0))})` : ""}`).join(" ")}</td></tr>`).join("");
}

function renderConfig() {
  $("config").textContent = JSON.stringify({ totals: view.totals, config: view.config }, null, 1);
}

async function download(format) {
  const path = `/models/${view.model}` + (format === "npz" ? "?format=npz" : "");
  const blob = await (await api(path)).blob();
  const link = document.createElement("a");
  link.href = URL.createObjectURL(blob);
  link.download = `${view.model}.${format}`;
  link.click();
  URL.revokeObjectURL(link.href);
}

function frame() {
  if (view.dirty) {
    view.dirty = false;
    $("version").textContent = String(view.totals ? view.totals.model_version : 0);
    $("episodes").textContent = String(view.totals ? view.totals.episodes : 0);
    drawStates(); drawCharts(); drawDecisions(); renderConfig();
  }
  requestAnimationFrame(frame);
}

$("connect").addEventListener("click", connect);
$("model").addEventListener("change", connect);
$("action").addEventListener("change", drawTpm);
$("stream").addEventListener("change", () => { view.dirty = true; });
$("states").addEventListener("click", (event) => { pickState(event).catch((e) => setStatus(e.message)); });
$("download-json").addEventListener("click", () => download("json"));
$("download-npz").addEventListener("click", () => download("npz"));
const fromHash = new URLSearchParams(location.hash.slice(1)).get("token");
if (fromHash) $("token").value = fromHash;
requestAnimationFrame(frame);
connect();
