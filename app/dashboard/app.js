"use strict";
// The live view of one e-FSM model: states, a transition matrix, decisions over time.
// Loads the states once, then follows the model's server-sent events; never polls the snapshot.

const FLAG_COLOURS = { collision: "#d62728", large_distance: "#ff9f1c" };
const NONE_COLOUR = "#7a8794";
const OTHER_COLOUR = "#9467bd";
const KEEP_DECISIONS = 300;
const $ = (id) => document.getElementById(id);

const view = {
  model: null, token: "", source: null, config: null, states: [], dims: [0, 0], points: {},
  version: 0, episodes: 0, failures: [], history: [], current: null, decisions: [],
  streams: new Set(), statesOverSteps: [], picked: null, positions: [], dirty: false,
  tpmTimer: null, counters: null,
};

function newEpisode() { return { steps: 0, revised: 0, byCriterion: {} }; }

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

async function load() {
  const doc = await (await api(`/models/${view.model}?tpm=none&exact=false`)).json();
  view.config = doc.config;
  view.states = doc.states;
  view.points = doc.failure_points || {};
  view.version = doc.model_version;
  view.episodes = doc.episodes;
  view.history = []; view.current = newEpisode(); view.decisions = []; view.streams.clear();
  view.statesOverSteps = [[doc.model_version, doc.n_states]];
  view.failures = [];
  $("state-count").textContent = String(doc.n_states);
  const names = doc.config.observation.names;
  const x = names.indexOf("headway"), y = names.indexOf("v_ego");
  view.dims = x >= 0 && y >= 0 ? [x, y] : [0, Math.min(1, names.length - 1)];
  const bins = Math.round((doc.config.action.high - doc.config.action.low) / doc.config.action.step);
  const action = $("action");
  if (action.options.length !== bins) {
    action.replaceChildren(...Array.from({ length: bins }, (_, b) => new Option(String(b), String(b))));
    action.value = String(Math.floor(bins * 0.75));
  }
  view.counters = { n_states: doc.n_states, steps: doc.steps, episodes: doc.episodes,
    model_version: doc.model_version, interventions: { ...doc.interventions } };
  view.dirty = true;
  drawTpm();
}

function subscribe() {
  const query = view.token ? "?token=" + encodeURIComponent(view.token) : "";
  view.source = new EventSource(`/models/${view.model}/events${query}`);
  view.source.onopen = () => setStatus("live: " + view.model);
  view.source.onerror = () => setStatus("reconnecting...");
  view.source.onmessage = (message) => handle(JSON.parse(message.data));
  clearInterval(view.tpmTimer);
  view.tpmTimer = setInterval(drawTpm, 15000);  // one matrix, not the snapshot
}

function handle(event) {
  if (event.type !== "step") return;
  const d = event.decision;
  if (event.state) view.states[event.state.index] = event.state;
  if (event.learn && d.state !== null && view.states[d.state]) view.states[d.state].visits += 1;
  view.version = d.model_version;
  view.episodes = d.episode;
  const c = view.counters;
  c.n_states = d.n_states; c.model_version = d.model_version; c.episodes = d.episode;
  if (event.learn) c.steps += 1;
  if (d.revised && !d.shadow) c.interventions[d.verdict] = (c.interventions[d.verdict] || 0) + 1;
  view.streams.add(d.stream);
  view.decisions.push(d);
  if (view.decisions.length > KEEP_DECISIONS) view.decisions.shift();
  if (d.reason === "done") {
    view.history.push(view.current);
    view.failures.push(event.event ? 1 : 0);
    view.current = newEpisode();
  } else {
    view.current.steps += 1;
    if (d.revised && !d.shadow) {
      view.current.revised += 1;
      view.current.byCriterion[d.verdict] = (view.current.byCriterion[d.verdict] || 0) + 1;
    }
  }
  view.statesOverSteps.push([d.model_version, d.n_states]);
  if (view.statesOverSteps.length > 4000) view.statesOverSteps.splice(0, 2000);
  $("state-count").textContent = String(d.n_states);
  view.dirty = true;
}

function colourOf(flag) {
  if (flag === null || flag === undefined) return NONE_COLOUR;
  return FLAG_COLOURS[flag] || OTHER_COLOUR;
}

function drawStates() {
  const canvas = $("states"), ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!view.config) return;
  const [dx, dy] = view.dims, obs = view.config.observation, pad = 30;
  // the axes span the normalisation bounds and every state beyond them (a headway above its
  // bound normalises above 1 and is still a state)
  const span = (d) => {
    const centres = view.states.filter(Boolean).map((s) => s.centre[d])
      .concat(...Object.values(view.points).map((ps) => ps.map((p) => p[d])));
    return [Math.min(obs.low[d], ...centres), Math.max(obs.high[d], ...centres)];
  };
  const [x0, x1] = span(dx), [y0, y1] = span(dy);
  const sx = (v) => pad + (v - x0) / (x1 - x0) * (canvas.width - 2 * pad);
  const sy = (v) => canvas.height - pad - (v - y0) / (y1 - y0) * (canvas.height - 2 * pad);
  ctx.strokeStyle = "#ccd"; ctx.strokeRect(pad, pad, canvas.width - 2 * pad, canvas.height - 2 * pad);
  ctx.fillStyle = "#555"; ctx.font = "12px sans-serif";
  ctx.fillText(obs.names[dx], canvas.width / 2, canvas.height - 8);
  ctx.save(); ctx.translate(12, canvas.height / 2); ctx.rotate(-Math.PI / 2);
  ctx.fillText(obs.names[dy], 0, 0); ctx.restore();
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
  $("picked").textContent =
    `#${best} (${detail.flag || "favourable"}, ${detail.visits} visits, ${failures})`;
  const rows = detail.next.map((a) => `<tr><td>${a.bin}</td><td>${a.states.map(
    (s) => `#${s.state} ${(100 * s.prob).toFixed(1)}%`).join(", ")}</td></tr>`).join("");
  $("state-detail").innerHTML = `<p>centre ${detail.centre.map((v) => v.toFixed(1)).join(", ")}</p>`
    + `<table id="next-states"><thead><tr><th>action bin</th><th>most likely next states</th></tr></thead>`
    + `<tbody>${rows}</tbody></table>`;
}

async function drawTpm() {
  if (!view.model) return;
  const action = $("action").value;
  let doc;
  try {
    doc = await (await api(`/models/${view.model}?tpm=sparse&action=${action}&exact=false&min_prob=0.001`)).json();
  } catch (error) { setStatus("no data: " + error.message); return; }
  const canvas = $("tpm"), ctx = canvas.getContext("2d"), n = doc.n_states;
  const bins = Math.max(1, Math.min(n, canvas.width));  // at most one cell per pixel
  const cells = new Float32Array(bins * bins);
  const [m] = doc.tpm.matrices;
  for (let k = 0; k < m.rows.length; k += 1) {  // bin the sparse entries, keeping maxima
    const cell = Math.floor(m.rows[k] * bins / n) * bins + Math.floor(m.cols[k] * bins / n);
    if (m.probs[k] > cells[cell]) cells[cell] = m.probs[k];
  }
  const small = document.createElement("canvas");
  small.width = bins; small.height = bins;
  const smallCtx = small.getContext("2d"), image = smallCtx.createImageData(bins, bins);
  for (let p = 0; p < cells.length; p += 1) {
    const v = Math.sqrt(cells[p]);
    image.data.set([255 - 200 * v, 255 - 140 * v, 255 - 60 * v, 255], 4 * p);
  }
  smallCtx.putImageData(image, 0, 0);
  ctx.imageSmoothingEnabled = false;
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.drawImage(small, 0, 0, canvas.width, canvas.height);
  $("tpm-note").textContent = `action bin ${action}: ${n} x ${n}, ${m.rows.length} entries >= 0.001 `
    + "(row: from, column: to; darker: likelier)";
}

function line(canvasId, series) {
  const canvas = $(canvasId), ctx = canvas.getContext("2d"), pad = 22;
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  const points = series.flatMap((s) => s.points);
  if (points.length < 2) return;
  const xs = points.map((p) => p[0]), ys = points.map((p) => p[1]);
  const x0 = Math.min(...xs), x1 = Math.max(...xs, x0 + 1), y1 = Math.max(...ys, 1e-9);
  ctx.strokeStyle = "#ccd"; ctx.strokeRect(pad, 4, canvas.width - pad - 4, canvas.height - pad - 4);
  ctx.fillStyle = "#555"; ctx.font = "10px sans-serif"; ctx.fillText(y1.toPrecision(3), 0, 12);
  for (const s of series) {
    ctx.beginPath(); ctx.strokeStyle = s.colour;
    s.points.forEach(([x, y], k) => {
      const px = pad + (x - x0) / (x1 - x0) * (canvas.width - pad - 6);
      const py = canvas.height - pad - y / y1 * (canvas.height - pad - 8);
      if (k === 0) ctx.moveTo(px, py); else ctx.lineTo(px, py);
    });
    ctx.stroke();
  }
}

function drawCharts() {
  const episodes = view.history;
  const criteria = view.config ? view.config.criteria.map((c) => c.name) : [];
  line("chart-revisions", criteria.map((name) => ({
    colour: colourOf(name), points: episodes.map((e, k) => [k + 1, e.byCriterion[name] || 0]) })));
  line("chart-share", [{ colour: "#1f77b4",
    points: episodes.map((e, k) => [k + 1, e.steps ? e.revised / e.steps : 0]) }]);
  line("chart-states", [{ colour: "#2ca02c", points: view.statesOverSteps }]);
  let failed = 0;
  line("chart-failures", [
    { colour: "#1f77b4", points: episodes.map((_, k) => [k + 1, k + 1]) },
    { colour: "#d62728", points: view.failures.map((f, k) => [k + 1, (failed += f)]) },
  ]);
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
  $("config").textContent = JSON.stringify({ counters: view.counters, config: view.config }, null, 1);
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
    $("version").textContent = String(view.version);
    $("episodes").textContent = String(view.episodes);
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
