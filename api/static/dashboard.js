// The spinefarm dashboard: one page over the read-only JSON API (#/, #/run/ID, #/run/ID/trial/N).
"use strict";

const view = document.getElementById("view");
const crumbs = document.getElementById("crumbs");
const liveBadge = document.getElementById("live");
const REFRESH_MS = 2000;
const PAGE_ROWS = 200;
let timer = null;
let generation = 0; // a navigation bumps it; a late refresh of an old page then does nothing

const esc = (s) => String(s ?? "").replace(/[&<>"']/g, (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;",
  "\"": "&quot;", "'": "&#39;"}[c]));
const fmt = (v, d = 4) => (v === null || v === undefined || Number.isNaN(v)) ? "–"
  : (typeof v === "number" ? Number(v.toPrecision(d)).toString() : esc(v));
const enc = encodeURIComponent;

async function api(url) {
  const r = await fetch(url, {cache: "no-store"});
  const body = await r.json().catch(() => null);
  if (!r.ok) throw new Error((body && body.detail && body.detail.message) || `${r.status} ${r.statusText}`);
  return body;
}

function setCrumbs(parts) {
  crumbs.innerHTML = parts.map(([href, label]) => `<a href="${href}">${esc(label)}</a>`).join("");
}

function schedule(fn, live) {
  clearTimeout(timer);
  liveBadge.hidden = !live;
  if (live) timer = setTimeout(fn, REFRESH_MS);
}

const fmtDuration = (s) => (s === null || s === undefined) ? "–" : s < 90 ? `${Math.round(s)} s`
  : s < 5400 ? `${Math.round(s / 60)} min` : `${(s / 3600).toFixed(1)} h`;
const fmtDate = (t) => t ? new Date(t * 1000).toLocaleString(undefined, {dateStyle: "medium", timeStyle: "short"}) : "–";

/** A live page whose server went away (the search ended): keep what it shows, say how to reopen it. */
function serverGone(e, gen, reopen) {
  if (gen !== generation) return;
  clearTimeout(timer);
  liveBadge.hidden = true;
  if (!document.getElementById("cards") && !document.getElementById("runs-table")) { showError(e); return; }
  let box = document.getElementById("ended");
  if (!box) {
    box = document.createElement("div");
    box.id = "ended";
    box.className = "notice";
    view.prepend(box);
  }
  box.innerHTML = `<b>This dashboard's server has stopped</b> (the search ended or was stopped): the page keeps
    what it last showed. Reopen the run with <code id="reopen">${esc(reopen || "spinefarm api runs/RUN.h5")}</code>.`;
  document.querySelectorAll(".state.running").forEach((b) => { b.textContent = "ended"; b.className = "state stopped"; });
  const eta = document.getElementById("eta");
  if (eta) eta.textContent = "–";
}

function card(k, v) { return `<div class="card"><div class="v">${v}</div><div class="k">${esc(k)}</div></div>`; }
function stateBadge(s) { return `<span class="state ${esc(s)}">${esc(s)}</span>`; }

// ---------------------------------------------------------------- runs
const RUN_COLUMNS = [  // [key, label, value of a run for sorting, left-aligned]
  ["run_id", "run", (r) => r.run_id, true], ["morphology", "robot", (r) => r.morphology, true],
  ["state", "state", (r) => r.state, true], ["started", "started", (r) => r.started_at_unix_s, false],
  ["controller", "controller", (r) => r.controller, true], ["engine", "engine", (r) => r.engine, true],
  ["sampler", "sampler", (r) => r.sampler, true], ["objective", "objective", (r) => r.objective, true],
  ["progress", "progress", (r) => r.trials_done / Math.max(1, r.trials_planned), false],
  ["failed", "failed", (r) => r.trials_failed, false], ["eta", "ETA", (r) => r.eta_s, false],
  ["speed", "best speed (cm/s)", (r) => r.best && r.best.scores.speed_cm_s, false],
  ["cot", "best COT", (r) => r.best && r.best.scores.cot, false],
  ["verified", "best verified", (r) => r.best && r.best.verification.verdict, true],
];
const runsSort = {key: "started", dir: -1};

function runCell(key, r) {
  const best = r.best;
  switch (key) {
    case "run_id": return esc(r.run_id);
    case "morphology": return esc(r.morphology);
    case "state": return stateBadge(r.state);
    case "started": return fmtDate(r.started_at_unix_s);
    case "controller": return esc(r.controller || (r.engine ? "default" : "–"));
    case "engine": return esc(r.engine || "–") + (r.rungs_s ? ` <span class="muted">rungs ${r.rungs_s.join(", ")} s</span>` : "");
    case "sampler": return esc(r.sampler || "–");
    case "objective": return esc(r.objective);
    case "progress": {
      const pct = Math.min(100, 100 * r.trials_done / Math.max(1, r.trials_planned));
      return `<span class="bar"><span style="width:${pct}%"></span></span> ${r.trials_done}/${r.trials_planned}`;
    }
    case "failed": return String(r.trials_failed);
    case "eta": return r.state === "running" ? fmtDuration(r.eta_s) : "–";
    case "speed": return best ? fmt(best.scores.speed_cm_s) : "–";
    case "cot": return best ? fmt(best.scores.cot) : "–";
    case "verified": return best ? `<span class="verdict ${esc(best.verification.verdict)}">${esc(best.verification.verdict)}</span>` : "–";
  }
  return "";
}

function damagedList(bad) {
  if (!bad.length) return "";
  return `<div class="notice warn" id="damaged"><b>${bad.length} file${bad.length > 1 ? "s" : ""} left out</b>
    (damaged or not a run file): <ul>${bad.map((b) => `<li><code>${esc(b.file)}</code>: ${esc(b.reason)}</li>`).join("")}</ul></div>`;
}

async function showRuns(gen) {
  setCrumbs([["#/", "runs"]]);
  const [runs, bad] = await Promise.all([api("/runs"), api("/damaged-files").catch(() => [])]);
  if (gen !== generation) return;
  const col = RUN_COLUMNS.find((c) => c[0] === runsSort.key);
  runs.sort((a, b) => {
    const x = col[2](a), y = col[2](b);
    if (x === y) return a.run_id < b.run_id ? -1 : 1;
    if (x === null || x === undefined) return 1;
    if (y === null || y === undefined) return -1;
    return (x < y ? -1 : 1) * runsSort.dir;
  });
  const rows = runs.map((r) => `<tr class="row" data-run="${esc(r.run_id)}">` + RUN_COLUMNS.map(([key, , , left]) =>
    `<td${left ? " class=\"l\"" : ""}>${runCell(key, r)}</td>`).join("") + "</tr>").join("");
  const head = RUN_COLUMNS.map(([key, label, , left]) => `<th data-key="${key}" class="${left ? "l " : ""}${
    key === runsSort.key ? (runsSort.dir > 0 ? "sorted-asc" : "sorted-desc") : ""}">${label}</th>`).join("");
  view.innerHTML = `<h1>Runs</h1>${damagedList(bad)}${runs.length ? "" : "<p class='muted' id='no-runs'>no run files found</p>"}
    <div class="tablewrap"><table id="runs-table"><thead><tr>${head}</tr></thead><tbody>${rows}</tbody></table></div>`;
  view.querySelectorAll("#runs-table th").forEach((th) => th.addEventListener("click", () => {
    if (runsSort.key === th.dataset.key) runsSort.dir *= -1;
    else { runsSort.key = th.dataset.key; runsSort.dir = th.classList.contains("l") ? 1 : -1; }
    showRuns(gen).catch(showError);
  }));
  view.querySelectorAll("tr.row").forEach((tr) => tr.addEventListener("click", () => {
    location.hash = `#/run/${enc(tr.dataset.run)}`;
  }));
  const reopen = runs.length === 1 ? runs[0].reopen_command : "spinefarm api runs/*.h5";
  schedule(() => showRuns(gen).catch((e) => serverGone(e, gen, reopen)), runs.some((r) => r.state === "running"));
}

// ---------------------------------------------------------------- one run
const runState = {sortKey: "trial_id", sortDir: 1, page: 0, param: null, filters: {}};

function runningMax(xs, ys) {
  const out = []; let best = -Infinity;
  for (let i = 0; i < ys.length; i++) { best = Math.max(best, ys[i]); out.push(best); }
  return {x: xs, y: out};
}

function plot(id, traces, layout, count) {
  const el = document.getElementById(id);
  const base = {margin: {l: 60, r: 20, t: 10, b: 45}, hovermode: "closest", showlegend: true,
    legend: {orientation: "h", y: -0.2}, uirevision: id};
  Plotly.react(el, traces, Object.assign(base, layout), {displaylogo: false, responsive: true});
  el.dataset.points = String(count);
  return el;
}

function onPointClick(el) {
  if (el.dataset.clickBound) return;
  el.dataset.clickBound = "1";
  el.on("plotly_click", (ev) => {
    const p = ev.points && ev.points[0];
    if (p && p.customdata !== undefined) location.hash = `#/run/${enc(el.dataset.run)}/trial/${p.customdata}`;
  });
}

function drawRunPlots(runId, cols, analysis, meta) {
  const c = cols.columns;
  const n = cols.n_trials;
  const ok = [];  // trials that count: complete, finite objective, not refuted by re-simulation
  for (let i = 0; i < n; i++) {
    if (c.status[i] === "complete" && c.objective[i] !== null && c.verification[i] !== "not_reproduced") ok.push(i);
  }
  const objName = meta.objective;
  // best so far against trials
  const byTrial = runningMax(ok.map((i) => c.trial_id[i]), ok.map((i) => c.objective[i]));
  let el = plot("plot-progress", [
    {x: ok.map((i) => c.trial_id[i]), y: ok.map((i) => c.objective[i]), customdata: ok.map((i) => c.trial_id[i]),
      mode: "markers", type: "scatter", name: "trial", marker: {size: 4, color: "#9aa7bd"}},
    {x: byTrial.x, y: byTrial.y, mode: "lines", type: "scatter", name: "best so far", line: {color: "#3461c1", shape: "hv"}},
  ], {xaxis: {title: {text: "trial"}}, yaxis: {title: {text: objName}}}, ok.length);
  el.dataset.run = runId; onPointClick(el);
  // best so far against time
  const timed = ok.filter((i) => c.finished_at_unix_s[i] !== null)
    .sort((a, b) => c.finished_at_unix_s[a] - c.finished_at_unix_s[b]);
  const t0 = timed.length ? Math.min(...timed.map((i) => c.finished_at_unix_s[i])) : 0;
  const byTime = runningMax(timed.map((i) => c.finished_at_unix_s[i] - t0), timed.map((i) => c.objective[i]));
  plot("plot-time", [{x: byTime.x, y: byTime.y, mode: "lines+markers", type: "scatter", name: "best so far",
    line: {color: "#3461c1", shape: "hv"}, marker: {size: 3}}],
  {xaxis: {title: {text: "time since first result (s)"}}, yaxis: {title: {text: objName}}}, timed.length);
  // speed against COT with the Pareto front (stored with the run: faster and cheaper)
  const sc = [];
  for (let i = 0; i < n; i++) if (c.status[i] === "complete" && c.speed_cm_s[i] !== null && c.cot[i] !== null) sc.push(i);
  const front = analysis.pareto_front.slice().sort((a, b) => c.speed_cm_s[a] - c.speed_cm_s[b]);
  const positive = sc.every((i) => c.cot[i] > 0);
  el = plot("plot-pareto", [
    {x: sc.map((i) => c.speed_cm_s[i]), y: sc.map((i) => c.cot[i]), customdata: sc.map((i) => c.trial_id[i]),
      mode: "markers", type: "scatter", name: "trial", marker: {size: 5, color: "#9aa7bd"},
      hovertemplate: "trial %{customdata}<br>%{x:.4g} cm/s, COT %{y:.4g}<extra></extra>"},
    {x: front.map((i) => c.speed_cm_s[i]), y: front.map((i) => c.cot[i]), customdata: front.map((i) => c.trial_id[i]),
      mode: "lines+markers", type: "scatter", name: "Pareto front", line: {color: "#c0392b"}, marker: {size: 7}},
  ], {xaxis: {title: {text: "speed (cm/s)"}}, yaxis: {title: {text: "cost of transport"}, type: positive && sc.length ? "log" : "linear"}},
  sc.length);
  el.dataset.run = runId; el.dataset.front = String(front.length); onPointClick(el);
  const complete = c.status.filter((s) => s === "complete").length;
  document.getElementById("pareto-note").textContent = complete > sc.length
    ? `${complete - sc.length} without a finite COT not shown` : "";
  drawParamPlots(runId, cols, analysis, ok);
  drawTimeline(cols);
  if (analysis.rungs) drawRungs(runId, cols, analysis.rungs);
  // failures by reason
  const reasons = Object.entries(analysis.failed_by_reason);
  el = plot("plot-failed", [{type: "bar", x: reasons.map((r) => r[0]), y: reasons.map((r) => r[1]),
    marker: {color: "#c0392b"}, name: "failed trials"}],
  {xaxis: {title: {text: "reason"}, visible: reasons.length > 0}, yaxis: {title: {text: "trials"}, visible: reasons.length > 0},
    showlegend: false, annotations: reasons.length ? [] : [{text: "no failed trials", showarrow: false,
      xref: "paper", yref: "paper", x: 0.5, y: 0.5, font: {size: 16, color: "#6b7385"}}]},
  reasons.reduce((s, r) => s + r[1], 0));
}

function drawParamPlots(runId, cols, analysis, ok) {
  const names = cols.param_names;
  const imp = names.map((nm) => analysis.importance[nm] || 0);
  const order = names.map((_, j) => j).sort((a, b) => imp[b] - imp[a]);
  // importance: every parameter when few, the 30 strongest when many
  const top = order.slice(0, 30).reverse();
  plot("plot-importance", [{type: "bar", orientation: "h", x: top.map((j) => imp[j]), y: top.map((j) => names[j]),
    marker: {color: "#3461c1"}, name: "|rank correlation| with the objective"}],
  {margin: {l: 220, r: 20, t: 10, b: 45}, xaxis: {title: {text: "|Spearman ρ| with the objective"}, range: [0, 1]},
    showlegend: false, height: Math.max(320, 18 * top.length + 60)}, top.length);
  document.getElementById("importance-note").textContent = names.length > 30
    ? `the 30 strongest of ${names.length} parameters` : `all ${names.length} parameters`;
  const warn = document.getElementById("importance-warning");
  const nUsed = analysis.importance_trials;
  warn.hidden = nUsed >= analysis.importance_min_trials;
  warn.innerHTML = warn.hidden ? "" : `<b>Read with care:</b> ranked from ${nUsed} finished trial${nUsed === 1 ? "" : "s"}
    of ${names.length} parameters; below ${analysis.importance_min_trials} the ranking is mostly noise${
    analysis.importance_noise ? ` (a parameter unrelated to the objective reaches |ρ| ≈ ${fmt(analysis.importance_noise, 2)}
    by chance: the dashed line)` : ""}.`;
  const impEl = document.getElementById("plot-importance");
  if (analysis.importance_noise && analysis.importance_noise < 1) {
    Plotly.relayout(impEl, {shapes: [{type: "line", x0: analysis.importance_noise, x1: analysis.importance_noise,
      yref: "paper", y0: 0, y1: 1, line: {dash: "dash", color: "#c27b12", width: 1.5}}]});
  }
  // parallel coordinates of the strongest parameters, lines coloured by objective quantile
  const axes = order.slice(0, Math.min(12, names.length));
  const c = cols.columns;
  const objs = ok.map((i) => c.objective[i]).sort((a, b) => a - b);
  const q = (f) => objs.length ? objs[Math.min(objs.length - 1, Math.floor(f * objs.length))] : 0;
  const bands = [["lower half", -Infinity, q(0.5), "#c9d1de", 0.35], ["50–80 %", q(0.5), q(0.8), "#8fa6cf", 0.5],
    ["80–95 %", q(0.8), q(0.95), "#4c74c9", 0.7], ["top 5 %", q(0.95), Infinity, "#c0392b", 0.9]];
  const traces = bands.map(([label, lo, hi, color, opacity]) => {
    const x = [], y = [];
    for (const i of ok) {
      const o = c.objective[i];
      if (!(o >= lo && (o < hi || hi === Infinity))) continue;
      axes.forEach((j, k) => {
        const v = cols.params[names[j]][i];
        const span = cols.param_highs[j] - cols.param_lows[j];
        x.push(k); y.push(span > 0 ? (v - cols.param_lows[j]) / span : 0.5);
      });
      x.push(null); y.push(null);
    }
    return {x, y, mode: "lines", type: "scatter", name: label, line: {color, width: 1}, opacity, hoverinfo: "skip"};
  });
  plot("plot-parallel", traces, {xaxis: {tickvals: axes.map((_, k) => k), ticktext: axes.map((j) => names[j]),
    tickangle: -30, automargin: true}, yaxis: {title: {text: "position in range"}, range: [-0.02, 1.02]}}, ok.length);
  // one parameter against the objective
  const sel = document.getElementById("param-select");
  if (!runState.param || !names.includes(runState.param)) runState.param = names[order[0]];
  if (sel.options.length !== names.length) {
    sel.innerHTML = order.map((j) => `<option value="${esc(names[j])}">${esc(names[j])}` +
      `${cols.param_units[j] && cols.param_units[j] !== "1" ? " (" + esc(cols.param_units[j]) + ")" : ""}</option>`).join("");
    sel.onchange = () => { runState.param = sel.value; drawParamPlots(runId, cols, analysis, ok); };
  }
  sel.value = runState.param;
  const pv = cols.params[runState.param];
  const el = plot("plot-param", [{x: ok.map((i) => pv[i]), y: ok.map((i) => c.objective[i]),
    customdata: ok.map((i) => c.trial_id[i]), mode: "markers", type: "scatter", name: "trial",
    marker: {size: 5, color: "#3461c1", opacity: 0.7}}],
  {xaxis: {title: {text: runState.param}}, yaxis: {title: {text: cols.objective}}, showlegend: false}, ok.length);
  el.dataset.run = runId; onPointClick(el);
}

// trials per worker over time: a bar from each trial's start (finish − wall time) to its finish
function drawTimeline(cols) {
  const c = cols.columns;
  const rows = [];
  for (let i = 0; i < cols.n_trials; i++) {
    if (c.finished_at_unix_s[i] !== null && c.wall_time_s[i] !== null) rows.push(i);
  }
  const t0 = rows.length ? Math.min(...rows.map((i) => c.finished_at_unix_s[i] - c.wall_time_s[i])) : 0;
  const workers = [...new Set(rows.map((i) => c.worker_id[i] || "unknown"))].sort();
  const colours = ["#3461c1", "#2e9e5b", "#c27b12", "#8e44ad", "#c0392b", "#16a085"];
  const traces = workers.map((w, k) => {
    const x = [], y = [], ids = [];
    for (const i of rows) {
      if ((c.worker_id[i] || "unknown") !== w) continue;
      const end = c.finished_at_unix_s[i] - t0;
      x.push(end - c.wall_time_s[i], end, null); y.push(w, w, null); ids.push(c.trial_id[i], c.trial_id[i], null);
    }
    return {x, y, customdata: ids, mode: "lines", type: "scatter", name: w, line: {width: 10, color: colours[k % colours.length]},
      hovertemplate: "trial %{customdata}<extra>%{y}</extra>"};
  });
  const el = plot("plot-timeline", traces, {xaxis: {title: {text: "time since the first trial started (s)"}},
    yaxis: {type: "category", automargin: true}, showlegend: false,
    margin: {l: 20, r: 20, t: 10, b: 45}}, rows.length);
  el.dataset.workers = String(workers.length);
}

// a multi-fidelity run: each parameter set's distance per rung, promotions as lines, and the rung table
function drawRungs(runId, cols, rungs) {
  const c = cols.columns;
  const dur = (i) => c.duration_s[i] !== null ? c.duration_s[i] : rungs[c.rung[i]].duration_s;
  const done = [];
  for (let i = 0; i < cols.n_trials; i++) if (c.status[i] === "complete" && c.distance_m[i] !== null) done.push(i);
  const lx = [], ly = [];
  for (const i of done) {
    const p = c.parent[i];
    if (c.rung[i] > 0 && p !== null && p >= 0 && c.distance_m[p] !== null) {
      lx.push(dur(p), dur(i), null); ly.push(c.distance_m[p], c.distance_m[i], null);
    }
  }
  const el = plot("plot-rungs", [
    {x: lx, y: ly, mode: "lines", type: "scatter", name: "promoted", line: {color: "#c0392b", width: 1}, hoverinfo: "skip"},
    {x: done.map(dur), y: done.map((i) => c.distance_m[i]), customdata: done.map((i) => c.trial_id[i]), mode: "markers",
      type: "scatter", name: "trial", marker: {size: 5, color: "#3461c1", opacity: 0.7},
      hovertemplate: "trial %{customdata}<br>%{x} s: %{y:.4g} m<extra></extra>"},
  ], {xaxis: {title: {text: "trial length (s), one rung each"}, tickvals: rungs.map((r) => r.duration_s)},
    yaxis: {title: {text: "distance (m)"}}}, done.length);
  el.dataset.run = runId; el.dataset.promotions = String(lx.length / 3); onPointClick(el);
  document.getElementById("rungs-table").innerHTML = `<thead><tr><th class="l">rung</th><th>length (s)</th>
    <th>trials</th><th>complete</th><th>promoted</th><th>best (m)</th><th>median (m)</th><th>judged</th>
    <th>judge / screen distance</th></tr></thead><tbody>${rungs.map((r) => `<tr><td class="l">${r.rung}</td>
    <td>${fmt(r.duration_s)}</td><td>${r.trials}</td><td>${r.complete}</td><td>${r.promoted}</td>
    <td>${fmt(r.best_distance_m)}</td><td>${fmt(r.median_distance_m)}</td><td>${r.judged}</td>
    <td>${fmt(r.judge_ratio_median, 3)}</td></tr>`).join("")}</tbody>`;
}

const TABLE = [["trial_id", "trial"], ["status", "status"], ["phase", "phase"], ["objective", "objective"],
  ["distance_m", "distance (m)"], ["speed_cm_s", "speed (cm/s)"], ["cot", "COT"], ["work_j", "work (J)"],
  ["verification", "verified"], ["wall_time_s", "wall (s)"], ["worker_id", "worker"], ["reason", "reason"]];

const FILTERS = [["status", "status"], ["phase", "phase"], ["worker_id", "worker"], ["rung", "rung"],
  ["verification", "verified"]];

/** The filter bar over the trials table: a choice per categorical column, a minimum objective, a reason text. */
function drawFilters(runId, cols) {
  const c = cols.columns;
  const bar = document.getElementById("trial-filters");
  const f = runState.filters;
  const choices = FILTERS.map(([key, label]) => {
    const values = [...new Set(c[key].map((v) => (v === null || v === "" ? "" : String(v))))].sort();
    if (values.length < 2 && !f[key]) return "";
    return `<label>${label} <select data-filter="${key}"><option value="">all</option>${values.map((v) =>
      `<option value="${esc(v)}"${f[key] === v ? " selected" : ""}>${esc(v || "–")}</option>`).join("")}</select></label>`;
  }).join("");
  const sig = choices;
  if (bar.dataset.sig === sig) return;  // a live refresh with the same choices keeps what is typed
  bar.dataset.sig = sig;
  bar.innerHTML = `${choices}<label>objective ≥ <input data-filter="min_objective" type="number" step="any"
    value="${esc(f.min_objective ?? "")}" style="width:7em"></label><label>reason contains <input data-filter="reason"
    type="text" value="${esc(f.reason ?? "")}" style="width:10em"></label><span class="muted" id="filter-count"></span>`;
  bar.querySelectorAll("[data-filter]").forEach((el) => {
    el.addEventListener(el.tagName === "SELECT" ? "change" : "input", () => {
      f[el.dataset.filter] = el.value;
      runState.page = 0;
      drawTable(runId, cols);
    });
  });
}

function passes(c, i) {
  const f = runState.filters;
  for (const [key] of FILTERS) {
    if (f[key] && String(c[key][i] ?? "") !== f[key]) return false;
  }
  if (f.min_objective !== undefined && f.min_objective !== "" && !(c.objective[i] >= Number(f.min_objective))) return false;
  if (f.reason && !String(c.reason[i] || "").toLowerCase().includes(f.reason.toLowerCase())) return false;
  return true;
}

function drawTable(runId, cols) {
  const c = cols.columns;
  const idx = [...Array(cols.n_trials).keys()].filter((i) => passes(c, i));
  const count = document.getElementById("filter-count");
  if (count) count.textContent = idx.length < cols.n_trials ? `${idx.length} of ${cols.n_trials} trials` : "";
  const k = runState.sortKey, d = runState.sortDir;
  idx.sort((a, b) => {
    const x = c[k][a], y = c[k][b];
    if (x === y) return a - b;
    if (x === null) return 1;
    if (y === null) return -1;
    return (x < y ? -1 : 1) * d;
  });
  const pages = Math.max(1, Math.ceil(idx.length / PAGE_ROWS));
  runState.page = Math.min(runState.page, pages - 1);
  const rows = idx.slice(runState.page * PAGE_ROWS, (runState.page + 1) * PAGE_ROWS).map((i) =>
    `<tr class="row" data-trial="${c.trial_id[i]}">` + TABLE.map(([key]) => {
      const v = c[key][i];
      const cls = typeof v === "number" ? "" : ` class="l${key === "verification" ? " verdict " + esc(v) : ""}"`;
      return `<td${cls}>${key === "verification" && !v ? "–" : fmt(v)}</td>`;
    }).join("") + "</tr>").join("");
  const head = TABLE.map(([key, label]) => `<th data-key="${key}" class="${["status", "phase", "verification",
    "worker_id", "reason"].includes(key) ? "l " : ""}${key === k ? (d > 0 ? "sorted-asc" : "sorted-desc") : ""}">${label}</th>`).join("");
  const box = document.getElementById("trials");
  box.dataset.rows = String(idx.length);
  box.innerHTML = `<div class="pager"><button id="prev" ${runState.page ? "" : "disabled"}>‹</button>
    <span>page ${runState.page + 1} of ${pages} · ${idx.length} trials</span>
    <button id="next" ${runState.page < pages - 1 ? "" : "disabled"}>›</button></div>
    <div class="tablewrap"><table id="trial-table"><thead><tr>${head}</tr></thead><tbody>${rows}</tbody></table></div>`;
  box.querySelectorAll("th").forEach((th) => th.addEventListener("click", () => {
    if (runState.sortKey === th.dataset.key) runState.sortDir *= -1;
    else { runState.sortKey = th.dataset.key; runState.sortDir = th.dataset.key === "trial_id" ? 1 : -1; }
    drawTable(runId, cols);
  }));
  box.querySelectorAll("tr.row").forEach((tr) => tr.addEventListener("click", () => {
    location.hash = `#/run/${enc(runId)}/trial/${tr.dataset.trial}`;
  }));
  document.getElementById("prev").onclick = () => { runState.page--; drawTable(runId, cols); };
  document.getElementById("next").onclick = () => { runState.page++; drawTable(runId, cols); };
}

function runNotice(status, r) {
  const best = status.best;
  if (status.state === "stopped") {
    return `<div class="notice" id="stopped">This run stopped before its budget (${status.trials_done} of
      ${status.trials_planned} trials). Continue it with <code>${esc(status.resume_command)}</code>.</div>`;
  }
  if (status.state === "stalled") {
    return `<div class="notice warn">Its coordinator holds the file but has not reported for
      ${fmtDuration(status.status_age_s)}.</div>`;
  }
  if (status.state === "done" && best) {
    return `<div class="notice" id="finished">Finished. <a href="#/run/${r}/trial/${best.trial_id}">Watch the best gait
      (trial ${best.trial_id})</a>, or as a video: <code>spinefarm render --run ${esc(status.reopen_command.replace(/^spinefarm api /, ""))}
      --video best.mp4</code>.</div>`;
  }
  return "";
}

function runSkeleton(runId) {
  const r = enc(runId);
  view.innerHTML = `<h1 id="run-title"></h1><div class="cards" id="cards"></div><div id="run-notice"></div>
    <div class="notice" id="empty" hidden></div><div id="run-body">
    <div class="buttons"><a class="button" id="dl-file" href="/runs/${r}/file">download run file (.h5)</a>
    <a class="button" id="dl-csv" href="/runs/${r}/trials.csv">download CSV</a></div>
    <div class="grid">
      <div class="panel"><h2>Best so far against trials</h2><div class="plot" id="plot-progress"></div></div>
      <div class="panel"><h2>Best so far against time</h2><div class="plot" id="plot-time"></div></div>
      <div class="panel"><h2>Speed against cost of transport <span class="muted" id="pareto-note"></span></h2><div class="plot" id="plot-pareto"></div></div>
      <div class="panel"><h2>Failed trials by reason</h2><div class="plot" id="plot-failed"></div></div>
      <div class="panel"><h2>Parallel coordinates <span class="muted">(the 12 most important parameters)</span></h2>
        <div class="plot" id="plot-parallel"></div></div>
      <div class="panel"><h2>One parameter against the objective <select id="param-select"></select></h2>
        <div class="plot" id="plot-param"></div></div>
      <div class="panel"><h2>Parameter importance <span class="muted" id="importance-note"></span></h2>
        <div class="notice warn" id="importance-warning" hidden></div><div id="plot-importance"></div></div>
      <div class="panel"><h2>Trials per worker over time</h2><div class="plot" id="plot-timeline"></div></div>
      <div class="panel" id="rungs-panel" hidden><h2>Rungs <span class="muted">(multi-fidelity: each parameter set
        per trial length)</span></h2><div class="plot" id="plot-rungs"></div>
        <div class="tablewrap"><table id="rungs-table"></table></div></div>
    </div>
    <h2 style="margin-top:1em">Trials</h2><div class="filters" id="trial-filters"></div><div id="trials"></div></div>`;
}

async function showRun(runId, gen, first) {
  setCrumbs([["#/", "runs"], [`#/run/${enc(runId)}`, runId]]);
  const r = enc(runId);
  const [status, cols, analysis, meta] = await Promise.all([api(`/runs/${r}`), api(`/runs/${r}/columns`),
    api(`/runs/${r}/analysis`), api(`/runs/${r}/meta`)]);
  if (gen !== generation) return;
  if (first) runSkeleton(runId);
  document.getElementById("run-title").innerHTML = `${esc(runId)} ${stateBadge(status.state)}`;
  const best = status.best;
  const alive = status.workers.filter((w) => w.alive).length;
  const step = status.step_s || meta.trial_config.dt_s;
  document.getElementById("cards").innerHTML = [
    card("robot", esc(status.morphology)), card("state", stateBadge(status.state)),
    card("trials done", `${status.trials_done} / ${status.trials_planned}`),
    ...(status.trials_planned > status.trials_budget
      ? [card("parameter sets", `${status.parameter_sets_sampled} / ${status.trials_budget}`)] : []),
    ...(status.state === "running" ? [card("ETA", `<span id="eta">${fmtDuration(status.eta_s)}</span>`)] : []),
    card("failed", status.trials_failed), card("trials per second", fmt(status.rate_trials_s, 3)),
    ...(status.state === "running" || status.workers.length ? [card("workers", `${alive}${status.workers.length > alive
      ? " (+" + (status.workers.length - alive) + " gone)" : ""}`)] : []),
    card("best " + esc(meta.objective), best ? `<a href="#/run/${r}/trial/${best.trial_id}">${fmt(best.objective)}</a>` : "–"),
    card("best speed (cm/s)", best ? fmt(best.scores.speed_cm_s) : "–"), card("best COT", best ? fmt(best.scores.cot) : "–"),
    card("best verified", best ? `<span class="verdict ${esc(best.verification.verdict)}">${esc(best.verification.verdict)}</span>` : "–"),
    meta.physical ? card("engine, step", `${esc(status.engine || "bullet")}, ${step ? fmt(step * 1000) + " ms" : "not run yet"}`) : "",
    card("sampler", esc(status.sampler || "–")), card("started", fmtDate(status.started_at_unix_s)),
  ].join("");
  document.getElementById("run-notice").innerHTML = runNotice(status, r);
  const empty = !cols.columns.status.some((x) => x === "complete" || x === "failed");
  document.getElementById("run-body").hidden = empty;
  document.getElementById("empty").hidden = !empty;
  if (empty) {
    document.getElementById("empty").innerHTML = `<b>No finished trial yet.</b> ${cols.n_trials
      ? `${cols.n_trials} trial(s) sampled, none has come back.` : "This run file holds no trial."} ${
      status.state === "running" ? "This page fills in as results arrive." : status.resume_command
        ? `Continue it, with workers, by <code>${esc(status.resume_command)}</code>.` : ""}`;
    schedule(() => showRun(runId, gen, false).catch((e) => serverGone(e, gen, status.reopen_command)),
      status.state === "running");
    return;
  }
  document.getElementById("rungs-panel").hidden = !analysis.rungs;
  drawRunPlots(runId, cols, analysis, meta);
  drawFilters(runId, cols);
  drawTable(runId, cols);
  document.body.dataset.trialsShown = String(cols.n_trials);
  schedule(() => showRun(runId, gen, false).catch((e) => serverGone(e, gen, status.reopen_command)),
    status.state === "running");
}

// ---------------------------------------------------------------- one trial
async function showTrial(runId, trialId, gen) {
  const r = enc(runId);
  setCrumbs([["#/", "runs"], [`#/run/${r}`, runId], [`#/run/${r}/trial/${trialId}`, `trial ${trialId}`]]);
  const [t, meta] = await Promise.all([api(`/runs/${r}/trials/${trialId}`), api(`/runs/${r}/meta`)]);
  if (gen !== generation) return;
  const units = Object.fromEntries(meta.param_names.map((n, j) => [n, meta.param_units[j]]));
  const scoreRows = Object.entries(t.scores).map(([k, v]) => `<tr><td class="l">${esc(k)}</td><td>${fmt(v, 6)}</td></tr>`).join("");
  const paramRows = Object.entries(t.params).map(([k, v]) => `<tr><td class="l">${esc(k)}</td><td>${fmt(v, 6)}</td>
    <td class="l">${esc(units[k] === "1" ? "" : units[k])}</td><td>${fmt(t.params_unit[k], 4)}</td></tr>`).join("");
  const v = t.verification;
  const tc = meta.trial_config;
  view.innerHTML = `<h1 id="trial-title">Trial ${t.trial_id} <span class="state ${esc(t.status)}">${esc(t.status)}</span></h1>
    <div class="cards">${card("objective (" + esc(meta.objective) + ")", fmt(t.objective, 6))}
      ${card("phase", esc(t.phase))}${card("parent", t.parent ?? "–")}${card("seed", t.seed)}
      ${meta.physical ? card("engine", esc(t.engine || tc.engine || "bullet")) +
        card("step", (t.dt_s || tc.dt_s) ? fmt((t.dt_s || tc.dt_s) * 1000) + " ms" : "–") +
        card("duration", (t.duration_s || tc.duration_s) ? fmt(t.duration_s || tc.duration_s) + " s" : "–") : ""}
      ${t.rung ? card("rung", t.rung) : ""}${card("worker", esc(t.worker_id || "–"))}</div>
    ${t.reason ? `<p class="error">${esc(t.reason)}</p>` : ""}
    <div class="buttons"><a class="button" id="dl-params" href="/runs/${r}/trials/${t.trial_id}/params.json"
      download>download --params file</a></div>
    <div class="grid">
      <div class="panel"><h2>Verification</h2><table id="verification"><tbody>
        <tr><td class="l">verdict</td><td class="l verdict ${esc(v.verdict)}">${esc(v.verdict)}</td></tr>
        <tr><td class="l">distance at the search's step (m)</td><td>${fmt(t.scores.distance_m, 6)}</td></tr>
        <tr><td class="l">distance re-simulated in ${esc(v.judge || "a finer step")} (m)</td><td>${fmt(v.fine_step_distance_m, 6)}</td></tr>
        ${v.reason ? `<tr><td class="l">reason</td><td class="l">${esc(v.reason)}</td></tr>` : ""}</tbody></table>
        <h2 style="margin-top:1em">Score parts</h2><table id="scores"><tbody>${scoreRows}</tbody></table></div>
      <div class="panel"><h2>Parameters</h2><div class="tablewrap"><table id="params"><thead><tr><th class="l">name</th>
        <th>value</th><th class="l">unit</th><th>in range (0–1)</th></tr></thead><tbody>${paramRows}</tbody></table></div></div>
    </div>
    <div class="panel" style="margin-top:1em"><h2>The gait, moving</h2><div id="motion-area"></div></div>
    <div class="panel picture" style="margin-top:1em"><h2>The gait in six frames</h2><div id="picture"></div></div>`;
  const pic = document.getElementById("picture");
  const area = document.getElementById("motion-area");
  if (!meta.physical) {
    pic.innerHTML = area.innerHTML = "<p class='muted'>a test objective: there is no robot to draw</p>";
    return;
  }
  if (t.status === "waiting") { pic.innerHTML = area.innerHTML = "<p class='muted'>not run yet</p>"; return; }
  pic.innerHTML = "<p class='muted'>drawn after the motion</p>";
  await showMotion(area, runId, [t.trial_id], gen);
  if (gen !== generation) return;
  pic.innerHTML = "<p class='muted' id='picture-wait'>drawing the gait (the trial is simulated again; this can take a while)…</p>";
  const url = `/runs/${r}/trials/${t.trial_id}/picture.png`;
  const resp = await fetch(url);
  if (gen !== generation) return;
  if (!resp.ok) {
    const body = await resp.json().catch(() => null);
    pic.innerHTML = `<p class="error" id="picture-error">${esc((body && body.detail && body.detail.message) || resp.statusText)}</p>`;
    return;
  }
  const img = new Image();
  img.id = "gait";
  img.alt = `gait of trial ${t.trial_id}`;
  img.src = URL.createObjectURL(await resp.blob());
  await img.decode().catch(() => null);
  if (gen !== generation) return;
  pic.replaceChildren(img);
}

// ---------------------------------------------------------------- the gait, moving (3D, gait3d.js)
let motionViews = [];

async function fetchMotion(runId, trialId) {
  const resp = await fetch(`/runs/${enc(runId)}/trials/${trialId}/motion.json`);
  const body = await resp.json().catch(() => null);
  if (!resp.ok) throw new Error((body && body.detail && body.detail.message) || resp.statusText);
  return body;
}

function motionCaption(trialId, m) {
  const r = m.result;
  return `trial ${trialId}: ${fmt(r.distance_m)} m, ${fmt(r.speed_cm_s)} cm/s, COT ${fmt(r.cot)}` +
    (r.reason ? ` (${esc(r.reason)})` : "");
}

/** Play the motions of trials of one run side by side, in step (one clock). */
async function showMotion(area, runId, trialIds, gen) {
  area.innerHTML = `<p class="muted" id="motion-wait">re-simulating ${trialIds.length > 1 ? "the trials" : "the trial"}
    to record its motion (the first time can take a while)…</p>`;
  let motions;
  try {
    motions = await Promise.all(trialIds.map((id) => fetchMotion(runId, id)));
  } catch (e) {
    if (gen === generation) area.innerHTML = `<p class="error" id="motion-error">${esc(e.message || e)}</p>`;
    return;
  }
  if (gen !== generation) return;
  const {MotionView, Player} = await import("/static/gait3d.js");
  if (gen !== generation) return;
  motionViews.forEach((v) => v.dispose());
  const r = enc(runId);
  area.innerHTML = `<div class="motion-row">${trialIds.map((id, k) => `<figure class="motion-fig">
      <div class="motion" id="motion-${k}" data-trial="${id}"></div>
      <figcaption>${motionCaption(id, motions[k])}</figcaption></figure>`).join("")}</div>
    <div class="motion-bar" id="motion-bar"></div>
    <p class="muted small">drag to orbit, scroll to zoom; strings coloured by tension (blue none, red
    ${fmt(Math.max(...motions.map((m) => m.tension_max_n)))} N), green: the path of the centre of mass ·
    <label>beside trial <input id="compare-id" type="number" min="0" style="width:6em"></label>
    <button id="compare-go" type="button">watch both</button></p>`;
  motionViews = trialIds.map((_, k) => new MotionView(document.getElementById(`motion-${k}`), motions[k]));
  window.spinefarmPlayer = new Player(motionViews, document.getElementById("motion-bar"));
  document.getElementById("compare-go").onclick = () => {
    const other = document.getElementById("compare-id").value;
    if (other !== "") location.hash = `#/run/${r}/watch/${trialIds[0]},${Number(other)}`;
  };
  area.dataset.ready = "1";
}

async function showWatch(runId, ids, gen) {
  const r = enc(runId);
  setCrumbs([["#/", "runs"], [`#/run/${r}`, runId], [`#/run/${r}/watch/${ids.join(",")}`,
    `trials ${ids.join(" and ")}, moving`]]);
  view.innerHTML = `<h1>Trials ${ids.map((id) => `<a href="#/run/${r}/trial/${id}">${id}</a>`).join(" and ")}
    in step</h1><div class="panel"><div id="motion-area"></div></div>`;
  await showMotion(document.getElementById("motion-area"), runId, ids, gen);
}

// ---------------------------------------------------------------- routing
function showError(e) {
  view.innerHTML = `<p class="error" id="page-error">${esc(e.message || e)}</p>`;
}

function route() {
  generation++;
  clearTimeout(timer);
  if (window.spinefarmPlayer) window.spinefarmPlayer.pause();
  motionViews.forEach((v) => v.dispose());
  motionViews = [];
  liveBadge.hidden = true;
  const gen = generation;
  const parts = location.hash.replace(/^#\/?/, "").split("/").map(decodeURIComponent);
  let p;
  if (parts[0] === "run" && parts[1] && parts[2] === "watch" && parts[3]) {
    p = showWatch(parts[1], parts[3].split(",").map(Number).filter((x) => Number.isInteger(x) && x >= 0), gen);
  } else if (parts[0] === "run" && parts[1] && parts[2] === "trial" && parts[3] !== undefined) {
    p = showTrial(parts[1], Number(parts[3]), gen);
  } else if (parts[0] === "run" && parts[1]) {
    runState.page = 0;
    runState.filters = {};
    p = showRun(parts[1], gen, true);
  } else {
    p = showRuns(gen);
  }
  p.catch(showError);
}

window.addEventListener("hashchange", route);
route();
