// The run page's plots and trials table (loaded before dashboard.js, which routes to them): progress,
// Pareto front, failures, parameters, importance, trials per worker, rungs, filters and the table.
"use strict";

const PAGE_ROWS = 200;
const runState = {sortKey: "trial_id", sortDir: 1, page: 0, param: null, filters: {}, paramCols: [],
  pc: {axes: null, brushes: {}}, brushed: null, onlyBrushed: false, redrawTable: () => {}};

/** A run page starts on page 1 without filters; what was chosen for its plots and columns stays while the same
 * run is shown (a visit to one of its trials and back keeps it). */
function resetRunState(runId) {
  Object.assign(runState, {page: 0, filters: {}});
  if (runState.runId === runId) return;
  Object.assign(runState, {runId, paramCols: [], pc: {axes: null, brushes: {}}, brushed: null, onlyBrushed: false,
    contour: null, rank: null});
}

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
    if (c.status[i] === "complete" && c.objective[i] !== null && !["not_reproduced", "diverged"].includes(c.verification[i])) ok.push(i);
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
  // parameter views take the first rung of a multi-fidelity run: every parameter set once, at one trial length
  // (a promoted row repeats its set at a longer trial, whose distance is not comparable)
  const firstRung = analysis.rungs ? ok.filter((i) => c.rung[i] === 0) : ok;
  const rungNote = document.getElementById("params-rung-note");
  rungNote.hidden = !analysis.rungs;
  rungNote.textContent = analysis.rungs ? `Parameter views (parallel coordinates, the contour, one parameter, ` +
    `importance) show the first rung only (${fmt(analysis.rungs[0].duration_s, 3)} s trials): every parameter ` +
    `set once, at one trial length.` : "";
  drawParamPlots(runId, cols, analysis, firstRung);
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
  // importance: every parameter when few, the 30 strongest when many, and every body constant of a co-designed
  // run however weak (its bars in orange)
  const shown = order.slice(0, 30);
  const top = shown.concat(order.filter((j) => isBody(names[j]) && !shown.includes(j)))
    .sort((a, b) => imp[b] - imp[a]).reverse();
  const nBody = names.filter(isBody).length;
  plot("plot-importance", [{type: "bar", orientation: "h", x: top.map((j) => imp[j]), y: top.map((j) => names[j]),
    marker: {color: top.map((j) => isBody(names[j]) ? "#d35400" : "#3461c1")},
    name: "|rank correlation| with the objective"}],
  {margin: {l: 220, r: 20, t: 10, b: 45}, xaxis: {title: {text: "|Spearman ρ| with the objective"}, range: [0, 1]},
    showlegend: false, height: Math.max(320, 18 * top.length + 60)}, top.length);
  document.getElementById("importance-note").textContent = (names.length > 30
    ? `the 30 strongest of ${names.length} parameters` : `all ${names.length} parameters`)
    + (nBody ? `; the ${nBody} body constants in orange, all shown` : "");
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
  drawEdf(cols, ok, cols.objective);
  drawRank(runId, cols, ok, order);
  runState.redrawTable = () => drawTable(runId, cols);
  drawParallel(runId, cols, analysis, ok, runState.redrawTable);
  drawContour(runId, cols, analysis);
  const c = cols.columns;
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
  if (runState.onlyBrushed && runState.brushed && !runState.brushed.has(i)) return false;
  return true;
}

const PARAM_KEY = "param:";  // sort keys of parameter columns

/** The table's columns: the fixed ones, then the chosen parameters (physical values, unit in the header). */
function tableColumns(cols) {
  const chosen = runState.paramCols.filter((nm) => cols.param_names.includes(nm)).map((nm) => {
    const unit = cols.param_units[cols.param_names.indexOf(nm)];
    return [PARAM_KEY + nm, unit && unit !== "1" ? `${nm} (${unit})` : nm, cols.params[nm]];
  });
  return [...TABLE.map(([key, label]) => [key, label, cols.columns[key]]), ...chosen];
}

function paramColumnPicker(cols) {
  const left = cols.param_names.filter((nm) => !runState.paramCols.includes(nm));
  return `<label>parameter columns <select id="add-param-col"><option value="">add…</option>${left.map((nm) =>
    `<option value="${esc(nm)}">${esc(nm)}</option>`).join("")}</select></label>${runState.paramCols.length
    ? `<button type="button" id="clear-param-cols">remove all</button>` : ""}`;
}

function drawTable(runId, cols) {
  const c = cols.columns;
  const idx = [...Array(cols.n_trials).keys()].filter((i) => passes(c, i));
  const count = document.getElementById("filter-count");
  if (count) count.textContent = idx.length < cols.n_trials ? `${idx.length} of ${cols.n_trials} trials` : "";
  const columns = tableColumns(cols);
  if (!columns.some(([key]) => key === runState.sortKey)) { runState.sortKey = "trial_id"; runState.sortDir = 1; }
  const k = runState.sortKey, d = runState.sortDir;
  const sortCol = columns.find(([key]) => key === k)[2];
  idx.sort((a, b) => {
    const x = sortCol[a], y = sortCol[b];
    if (x === y) return a - b;
    if (x === null) return 1;
    if (y === null) return -1;
    return (x < y ? -1 : 1) * d;
  });
  const pages = Math.max(1, Math.ceil(idx.length / PAGE_ROWS));
  runState.page = Math.min(runState.page, pages - 1);
  const rows = idx.slice(runState.page * PAGE_ROWS, (runState.page + 1) * PAGE_ROWS).map((i) =>
    `<tr class="row" data-trial="${c.trial_id[i]}">` + columns.map(([key, , values]) => {
      const v = values[i];
      const cls = typeof v === "number" ? "" : ` class="l${key === "verification" ? " verdict " + esc(v) : ""}"`;
      return `<td${cls}>${key === "verification" && !v ? "–" : fmt(v)}</td>`;
    }).join("") + "</tr>").join("");
  const head = columns.map(([key, label]) => `<th data-key="${esc(key)}" class="${["status", "phase", "verification",
    "worker_id", "reason"].includes(key) ? "l " : ""}${key.startsWith(PARAM_KEY) ? "param " : ""}${
    key === k ? (d > 0 ? "sorted-asc" : "sorted-desc") : ""}">${esc(label)}${key.startsWith(PARAM_KEY)
    ? ` <span class="drop" title="remove this column" data-drop="${esc(key.slice(PARAM_KEY.length))}">×</span>` : ""}</th>`).join("");
  const box = document.getElementById("trials");
  box.dataset.rows = String(idx.length);
  box.innerHTML = `<div class="pager"><button id="prev" ${runState.page ? "" : "disabled"}>‹</button>
    <span>page ${runState.page + 1} of ${pages} · ${idx.length} trials</span>
    <button id="next" ${runState.page < pages - 1 ? "" : "disabled"}>›</button>${paramColumnPicker(cols)}</div>
    <div class="tablewrap"><table id="trial-table"><thead><tr>${head}</tr></thead><tbody>${rows}</tbody></table></div>`;
  bindTable(runId, cols, box);
}

function bindTable(runId, cols, box) {
  const redraw = () => drawTable(runId, cols);
  box.querySelectorAll("th").forEach((th) => th.addEventListener("click", (ev) => {
    const drop = ev.target.dataset && ev.target.dataset.drop;
    if (drop) {
      runState.paramCols = runState.paramCols.filter((nm) => nm !== drop);
    } else if (runState.sortKey === th.dataset.key) runState.sortDir *= -1;
    else { runState.sortKey = th.dataset.key; runState.sortDir = th.dataset.key === "trial_id" ? 1 : -1; }
    redraw();
  }));
  box.querySelectorAll("tr.row").forEach((tr) => tr.addEventListener("click", () => {
    location.hash = `#/run/${enc(runId)}/trial/${tr.dataset.trial}`;
  }));
  document.getElementById("prev").onclick = () => { runState.page--; redraw(); };
  document.getElementById("next").onclick = () => { runState.page++; redraw(); };
  document.getElementById("add-param-col").onchange = (ev) => {
    if (ev.target.value) runState.paramCols.push(ev.target.value);
    redraw();
  };
  const clear = document.getElementById("clear-param-cols");
  if (clear) clear.onclick = () => { runState.paramCols = []; redraw(); };
}
