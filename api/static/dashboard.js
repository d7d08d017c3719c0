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

function card(k, v) { return `<div class="card"><div class="v">${v}</div><div class="k">${esc(k)}</div></div>`; }
function stateBadge(s) { return `<span class="state ${esc(s)}">${esc(s)}</span>`; }

// ---------------------------------------------------------------- runs
async function showRuns(gen) {
  setCrumbs([["#/", "runs"]]);
  const runs = await api("/runs");
  if (gen !== generation) return;
  const rows = runs.map((r) => {
    const pct = Math.min(100, 100 * r.trials_done / Math.max(1, r.trials_planned));
    const best = r.best;
    const alive = r.workers.filter((w) => w.alive).length;
    return `<tr class="row" data-run="${esc(r.run_id)}"><td class="l">${esc(r.run_id)}</td>
      <td class="l">${esc(r.morphology)}</td><td class="l">${stateBadge(r.state)}</td>
      <td><span class="bar"><span style="width:${pct}%"></span></span> ${r.trials_done}/${r.trials_planned}</td>
      <td>${r.trials_failed}</td><td>${fmt(r.rate_trials_s, 3)}</td><td>${alive}</td>
      <td>${best ? fmt(best.scores.speed_cm_s) : "–"}</td><td>${best ? fmt(best.scores.cot) : "–"}</td>
      <td class="l verdict ${best ? esc(best.verification.verdict) : ""}">${best ? esc(best.verification.verdict) : "–"}</td>
    </tr>`;
  }).join("");
  view.innerHTML = `<h1>Runs</h1>${runs.length ? "" : "<p class='muted'>no run files found</p>"}
    <div class="tablewrap"><table id="runs-table"><thead><tr><th class="l">run</th><th class="l">robot</th>
    <th class="l">state</th><th>progress</th><th>failed</th><th>trials/s</th><th>workers</th>
    <th>best speed (cm/s)</th><th>best COT</th><th class="l">best verified</th></tr></thead>
    <tbody>${rows}</tbody></table></div>`;
  view.querySelectorAll("tr.row").forEach((tr) => tr.addEventListener("click", () => {
    location.hash = `#/run/${enc(tr.dataset.run)}`;
  }));
  schedule(() => showRuns(gen).catch(showError), runs.some((r) => r.state === "running"));
}

// ---------------------------------------------------------------- one run
const runState = {sortKey: "trial_id", sortDir: 1, page: 0, param: null};

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

const TABLE = [["trial_id", "trial"], ["status", "status"], ["phase", "phase"], ["objective", "objective"],
  ["distance_m", "distance (m)"], ["speed_cm_s", "speed (cm/s)"], ["cot", "COT"], ["work_j", "work (J)"],
  ["verification", "verified"], ["wall_time_s", "wall (s)"], ["worker_id", "worker"], ["reason", "reason"]];

function drawTable(runId, cols) {
  const c = cols.columns;
  const idx = [...Array(cols.n_trials).keys()];
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

function runSkeleton(runId) {
  const r = enc(runId);
  view.innerHTML = `<h1 id="run-title"></h1><div class="cards" id="cards"></div>
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
        <div id="plot-importance"></div></div>
    </div>
    <h2 style="margin-top:1em">Trials</h2><div id="trials"></div>`;
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
  document.getElementById("cards").innerHTML = [
    card("robot", esc(status.morphology)), card("trials done", `${status.trials_done} / ${status.trials_planned}`),
    ...(status.trials_planned > status.trials_budget
      ? [card("parameter sets", `${status.parameter_sets_sampled} / ${status.trials_budget}`)] : []),
    card("failed", status.trials_failed), card("trials per second", fmt(status.rate_trials_s, 3)),
    card("workers", `${alive}${status.workers.length > alive ? " (+" + (status.workers.length - alive) + " gone)" : ""}`),
    card("best " + esc(meta.objective), best ? `<a href="#/run/${r}/trial/${best.trial_id}">${fmt(best.objective)}</a>` : "–"),
    card("best speed (cm/s)", best ? fmt(best.scores.speed_cm_s) : "–"), card("best COT", best ? fmt(best.scores.cot) : "–"),
    card("best verified", best ? `<span class="verdict ${esc(best.verification.verdict)}">${esc(best.verification.label || best.verification.verdict)}</span>` : "–"),
    ...(status.audit && status.audit.fraction > 0 ? [card("audits agree / disagree",
      `${status.audit.audits_agrees} / ${status.audit.audits_disagrees}`)] : []),
    meta.physical ? card("engine, step", `${esc(meta.trial_config.engine || "bullet")}, ${meta.trial_config.dt_s ? fmt(meta.trial_config.dt_s * 1000) + " ms" : "–"}`) : "",
    meta.engine_choice ? engineChoiceCard(meta.engine_choice) : "",
  ].join("");
  drawRunPlots(runId, cols, analysis, meta);
  drawTable(runId, cols);
  document.body.dataset.trialsShown = String(cols.n_trials);
  schedule(() => showRun(runId, gen, false).catch(showError), status.state === "running");
}

// how `search --engine auto` chose the tier: the calibration's figures, its reason on hover
function engineChoiceCard(c) {
  const text = `${esc(c.engine)}: ρ ${fmt(c.spearman, 3)}, top-${c.top_k} ${c.top_overlap}, ratio ${fmt(c.median_distance_ratio, 3)}`;
  return `<div class="card" title="${esc(c.reason || "")}" data-engine-choice="${esc(c.engine)}"><div class="v">${text}</div>`
    + `<div class="k">engine auto${c.cached ? " (cached calibration)" : ""}</div></div>`;
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
        <tr><td class="l">verdict</td><td class="l verdict ${esc(v.verdict)}" id="verdict-label">${esc(v.label || v.verdict)}</td></tr>
        <tr><td class="l">distance at the search's step (m)</td><td>${fmt(t.scores.distance_m, 6)}</td></tr>
        <tr><td class="l">distance re-simulated in ${esc(v.judge || "a finer step")} (m)</td><td>${fmt(v.fine_step_distance_m, 6)}</td></tr>
        ${v.verdict === "judged" && v.screen_to_judge_ratio != null ? `<tr><td class="l">screen / judge ratio</td><td>${fmt(v.screen_to_judge_ratio, 4)}</td></tr>` : ""}
        ${t.audit && t.audit.state !== "not_audited" ? `<tr><td class="l">audit by ${esc(t.audit.worker_id || "another worker")}</td>
          <td class="l">${esc(t.audit.state)} (${fmt(t.audit.distance_m, 6)} m)</td></tr>` : ""}
        ${v.reason ? `<tr><td class="l">reason</td><td class="l">${esc(v.reason)}</td></tr>` : ""}</tbody></table>
        <h2 style="margin-top:1em">Score parts</h2><table id="scores"><tbody>${scoreRows}</tbody></table></div>
      <div class="panel"><h2>Parameters</h2><div class="tablewrap"><table id="params"><thead><tr><th class="l">name</th>
        <th>value</th><th class="l">unit</th><th>in range (0–1)</th></tr></thead><tbody>${paramRows}</tbody></table></div></div>
    </div>
    <div id="episodes"></div>
    <div class="panel picture" style="margin-top:1em"><h2>The gait</h2><div id="picture"></div></div>`;
  if (meta.robust && meta.robust.episodes) showEpisodes(r, t.trial_id, gen);
  const pic = document.getElementById("picture");
  if (!meta.physical) { pic.innerHTML = "<p class='muted'>a test objective: there is no robot to draw</p>"; return; }
  if (t.status === "waiting") { pic.innerHTML = "<p class='muted'>not run yet</p>"; return; }
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

// a robust trial's episodes: each its own randomised world, and their spread
async function showEpisodes(r, trialId, gen) {
  const e = await api(`/runs/${r}/trials/${trialId}/episodes`);
  if (gen !== generation || !e.episodes.length) return;
  const s = e.spread.speed_cm_s;
  const draws = Object.entries(e.robust.randomize || {}).map(([k, v]) => `${esc(k)}=${esc(v)}`).join(", ") || "none";
  const rows = e.episodes.map((x) => `<tr><td>${x.episode}</td><td class="l">${esc(x.status)}</td><td>${fmt(x.speed_cm_s, 4)}</td>
    <td>${fmt(x.distance_m, 4)}</td><td>${fmt(x.cot, 4)}</td><td>${fmt(x.friction_scale, 4)}</td><td>${fmt(x.mass_scale, 4)}</td></tr>`).join("");
  document.getElementById("episodes").innerHTML = `<div class="panel" style="margin-top:1em"><h2>Episodes</h2>
    <p id="episode-spread">${e.episodes.length} episodes (draws: ${draws}; objective: ${esc(e.robust.statistic)} over them):
      speed median ${fmt(s.median, 4)} cm/s, quartiles ${fmt(s.q25, 4)} – ${fmt(s.q75, 4)}, min ${fmt(s.min, 4)}, max ${fmt(s.max, 4)}</p>
    <div class="tablewrap"><table id="episode-table"><thead><tr><th>episode</th><th class="l">status</th><th>speed (cm/s)</th>
      <th>distance (m)</th><th>COT</th><th>friction ×</th><th>mass ×</th></tr></thead><tbody>${rows}</tbody></table></div></div>`;
}

// ---------------------------------------------------------------- routing
function showError(e) {
  view.innerHTML = `<p class="error" id="page-error">${esc(e.message || e)}</p>`;
}

function route() {
  generation++;
  clearTimeout(timer);
  liveBadge.hidden = true;
  const gen = generation;
  const parts = location.hash.replace(/^#\/?/, "").split("/").map(decodeURIComponent);
  let p;
  if (parts[0] === "run" && parts[1] && parts[2] === "trial" && parts[3] !== undefined) {
    p = showTrial(parts[1], Number(parts[3]), gen);
  } else if (parts[0] === "run" && parts[1]) {
    runState.page = 0;
    p = showRun(parts[1], gen, true);
  } else {
    p = showRuns(gen);
  }
  p.catch(showError);
}

window.addEventListener("hashchange", route);
route();
