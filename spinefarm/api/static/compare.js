// Runs side by side (#/compare/ID,ID,...): best so far against trials and against time, one colour per run,
// and a table of what each run is and the best it found.
"use strict";

const COMPARE_COLOURS = ["#3461c1", "#c0392b", "#2e9e5b", "#c27b12", "#8e44ad", "#16a085", "#6b7385", "#d35400"];
// the score each curve follows; COT is better lower
const COMPARE_METRICS = [["objective", "each run's objective", 1], ["distance_m", "distance (m)", 1],
  ["speed_cm_s", "speed (cm/s)", 1], ["cot", "cost of transport (lower is better)", -1]];
const compareState = {ids: "", metric: null};  // the score picked, while the same runs are compared

/** Rows that count (complete, finite score, not refuted at a finer step), in trial order, with the running best. */
function bestSoFar(cols, key, sense) {
  const c = cols.columns;
  const rows = [];
  for (let i = 0; i < cols.n_trials; i++) {
    if (c.status[i] === "complete" && c[key][i] !== null && !["not_reproduced", "diverged"].includes(c.verification[i])) rows.push(i);
  }
  const trace = (order, x) => {
    let best = null;
    const ys = order.map((i) => {
      const v = c[key][i];
      if (best === null || (v - best) * sense > 0) best = v;
      return best;
    });
    return {x: order.map(x), y: ys, ids: order.map((i) => c.trial_id[i])};
  };
  const timed = rows.filter((i) => c.finished_at_unix_s[i] !== null)
    .sort((a, b) => c.finished_at_unix_s[a] - c.finished_at_unix_s[b]);
  const t0 = timed.length ? c.finished_at_unix_s[timed[0]] : 0;
  return {byTrial: trace(rows, (i) => c.trial_id[i] + 1), byTime: trace(timed, (i) => c.finished_at_unix_s[i] - t0),
    rows};
}

// the best's figure as it ranks: a judged set's judged distance, speed and COT (the screen's without them)
function bestFigure(b, key) {
  const v = b.verification || {};
  const judged = {distance_m: v.counted_distance_m, speed_cm_s: v.judged_speed_cm_s, cot: b.judged_cot}[key];
  return judged !== undefined && judged !== null ? judged : b.scores[key];
}

function extreme(cols, rows, key, sense) {
  const vals = rows.map((i) => cols.columns[key][i]).filter((v) => v !== null && Number.isFinite(v));
  return vals.length ? (sense > 0 ? Math.max(...vals) : Math.min(...vals)) : null;
}

async function showCompare(ids, gen, first = true) {
  setCrumbs([["#/", "runs"], [`#/compare/${ids.map(enc).join(",")}`, `comparing ${ids.length} runs`]]);
  if (ids.length < 2) throw new Error(`comparing needs two or more runs; received ${ids.length}: pick them on the runs list`);
  const data = await Promise.all(ids.map((id) => Promise.all([api(`/runs/${enc(id)}`),
    api(`/runs/${enc(id)}/columns?params=false`)])));
  if (gen !== generation) return;
  const objectives = [...new Set(data.map(([st]) => st.objective))];
  if (compareState.ids !== ids.join(",")) Object.assign(compareState, {ids: ids.join(","), metric: null});
  if (!compareState.metric) compareState.metric = objectives.length === 1 ? "objective" : "distance_m";
  if (first) {
    view.innerHTML = `<h1>Comparing ${ids.length} runs</h1>
      ${objectives.length > 1 ? `<div class="notice" id="mixed-objectives">These runs optimise different objectives
        (${objectives.map(esc).join(", ")}): compare them on a score they share.</div>` : ""}
      <div class="filters"><label>score <select id="compare-metric">${COMPARE_METRICS.map(([k, label]) =>
        `<option value="${k}"${k === compareState.metric ? " selected" : ""}>${esc(label)}</option>`).join("")}</select></label></div>
      <div class="grid">
        <div class="panel"><h2>Best so far against trials</h2><div class="plot" id="compare-trials"></div></div>
        <div class="panel"><h2>Best so far against time</h2><div class="plot" id="compare-time"></div></div>
        <div class="panel"><h2>Distribution <span class="muted">(EDF: share of each run's trials at most x)</span></h2>
          <div class="plot" id="compare-edf"></div></div>
      </div>
      <h2 style="margin-top:1em">The runs</h2><div class="tablewrap"><table id="compare-table"></table></div>`;
    document.getElementById("compare-metric").onchange = (ev) => {
      compareState.metric = ev.target.value;
      drawCompare(ids, compareData);
    };
  }
  compareData = data;
  drawCompare(ids, data);
  schedule(() => showCompare(ids, gen, false).catch((e) => serverGone(e, gen)),
    data.some(([st]) => st.state === "running"));
}
let compareData = [];

function drawCompare(ids, data) {
  const [key, label, sense] = COMPARE_METRICS.find((m) => m[0] === compareState.metric);
  const curves = data.map(([, cols]) => bestSoFar(cols, key, sense));
  const name = (k) => `${ids[k]} (${data[k][0].morphology})`;
  const traces = (which) => curves.map((cv, k) => ({x: cv[which].x, y: cv[which].y, customdata: cv[which].ids,
    mode: "lines", type: "scatter", name: name(k), line: {color: COMPARE_COLOURS[k % COMPARE_COLOURS.length], shape: "hv"},
    hovertemplate: `${esc(ids[k])}: %{y:.4g} (trial %{customdata})<extra></extra>`}));
  const yTitle = key === "objective" ? data[0][0].objective : label;
  plot("compare-trials", traces("byTrial"), {xaxis: {title: {text: "trials"}}, yaxis: {title: {text: yTitle}}, legend: {orientation: "h", y: -0.3}},
    curves.reduce((s, cv) => s + cv.byTrial.x.length, 0));
  plot("compare-time", traces("byTime"), {xaxis: {title: {text: "time since the run's first result (s)"}},
    yaxis: {title: {text: yTitle}}, legend: {orientation: "h", y: -0.3}}, curves.reduce((s, cv) => s + cv.byTime.x.length, 0));
  // the EDF of the score over each run's trials that count
  const edf = curves.map((cv, k) => cv.rows.map((i) => data[k][1].columns[key][i]).sort((a, b) => a - b));
  plot("compare-edf", edf.map((xs, k) => ({x: xs, y: xs.map((_, j) => (j + 1) / xs.length), mode: "lines",
    type: "scatter", name: name(k), line: {color: COMPARE_COLOURS[k % COMPARE_COLOURS.length], shape: "hv"}})),
  {xaxis: {title: {text: yTitle}}, yaxis: {title: {text: "share of trials ≤ x"}, range: [0, 1.02]},
    legend: {orientation: "h", y: -0.3}}, edf.reduce((s, xs) => s + xs.length, 0));
  const rows = data.map(([st, cols], k) => {
    const b = st.best;
    const counted = curves[k].rows;
    const cells = [`<td class="l swatch"><span style="background:${COMPARE_COLOURS[k % COMPARE_COLOURS.length]}"></span>
      <a href="#/run/${enc(st.run_id)}">${esc(st.run_id)}</a></td>`, `<td class="l">${esc(st.morphology)}</td>`,
    `<td class="l">${esc(st.controller || (st.engine ? "default" : "–"))}</td>`, `<td class="l">${esc(st.engine || "–")}${
      st.rungs_s ? ` <span class="muted">rungs ${st.rungs_s.join(", ")} s</span>` : ""}</td>`,
    `<td class="l">${esc(st.sampler || "–")}</td>`, `<td class="l">${esc(st.objective)}</td>`,
    `<td>${st.trials_done} / ${st.trials_planned}</td>`,
    `<td data-best="objective">${b ? `<a href="#/run/${enc(st.run_id)}/trial/${b.trial_id}">${fmt(b.objective)}</a>` : "–"}</td>`,
    ...["distance_m", "speed_cm_s", "cot"].map((s) => `<td data-best="${s}">${b ? fmt(bestFigure(b, s)) : "–"}</td>`),
    `<td data-extreme="distance_m">${fmt(extreme(cols, counted, "distance_m", 1))}</td>`,
    `<td data-extreme="speed_cm_s">${fmt(extreme(cols, counted, "speed_cm_s", 1))}</td>`,
    `<td data-extreme="cot">${fmt(extreme(cols, counted, "cot", -1))}</td>`];
    return `<tr data-run="${esc(st.run_id)}">${cells.join("")}</tr>`;
  }).join("");
  document.getElementById("compare-table").innerHTML = `<thead><tr><th class="l">run</th><th class="l">robot</th>
    <th class="l">controller</th><th class="l">engine</th><th class="l">sampler</th><th class="l">objective</th>
    <th>trials done</th><th>best objective</th><th>its distance (m)</th><th>its speed (cm/s)</th><th>its COT</th>
    <th>longest distance (m)</th><th>fastest (cm/s)</th><th>lowest COT</th></tr></thead><tbody>${rows}</tbody>`;
}
