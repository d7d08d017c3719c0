// The run page's EDF and rank plots (loaded before dashboard.js; run_views.js calls them with the trials that
// count). EDF: the share of trials whose objective is at most x (a search that finds more good gaits moves it
// right). Rank: two parameters against each other, each trial coloured by its objective's rank (1 the best).
"use strict";

/** Ranks from 0 (the worst) to 1 (the best) of the values; ties share their mean rank. */
function rankShares(values) {
  const order = values.map((_, k) => k).sort((a, b) => values[a] - values[b]);
  const ranks = new Array(values.length);
  for (let s = 0; s < order.length;) {
    let e = s;
    while (e + 1 < order.length && values[order[e + 1]] === values[order[s]]) e++;
    for (let k = s; k <= e; k++) ranks[order[k]] = values.length > 1 ? (s + e) / 2 / (values.length - 1) : 1;
    s = e + 1;
  }
  return ranks;
}

function drawEdf(cols, ok, objName) {
  const ys = ok.map((i) => cols.columns.objective[i]).sort((a, b) => a - b);
  plot("plot-edf", [{x: ys, y: ys.map((_, k) => (k + 1) / ys.length), mode: "lines", type: "scatter",
    name: "trials", line: {color: "#3461c1", shape: "hv"}}],
  {xaxis: {title: {text: objName}}, yaxis: {title: {text: "share of trials ≤ x"}, range: [0, 1.02]},
    showlegend: false}, ys.length);
}

function drawRank(runId, cols, ok, order) {
  const names = cols.param_names;
  if (!runState.rank || !names.includes(runState.rank.x)) {
    runState.rank = {x: names[order[0]], y: names.length > 1 ? names[order[1]] : "objective"};
  }
  const box = document.getElementById("rank-controls");
  const options = (chosen, withObjective) => [...order.map((j) => names[j]), ...(withObjective ? ["objective"] : [])]
    .map((nm) => `<option value="${esc(nm)}"${nm === chosen ? " selected" : ""}>${esc(nm)}</option>`).join("");
  box.innerHTML = `<label>x <select id="rank-x">${options(runState.rank.x, false)}</select></label>
    <label>y <select id="rank-y">${options(runState.rank.y, true)}</select></label>`;
  box.querySelector("#rank-x").onchange = (ev) => { runState.rank.x = ev.target.value; drawRank(runId, cols, ok, order); };
  box.querySelector("#rank-y").onchange = (ev) => { runState.rank.y = ev.target.value; drawRank(runId, cols, ok, order); };
  const c = cols.columns;
  const value = (nm, i) => (nm === "objective" ? c.objective[i] : cols.params[nm][i]);
  const rank = rankShares(ok.map((i) => c.objective[i]));
  const el = plot("plot-rank", [{x: ok.map((i) => value(runState.rank.x, i)), y: ok.map((i) => value(runState.rank.y, i)),
    customdata: ok.map((i) => c.trial_id[i]), mode: "markers", type: "scatter", name: "trial",
    marker: {size: 8, color: rank, colorscale: "Viridis", cmin: 0, cmax: 1, line: {width: 0.5, color: "#1d2430"},
      colorbar: {title: {text: "rank"}, tickvals: [0, 1], ticktext: ["worst", "best"]}},
    hovertemplate: "trial %{customdata}: rank %{marker.color:.2f}<extra></extra>"}],
  {xaxis: {title: {text: runState.rank.x}}, yaxis: {title: {text: runState.rank.y}}, showlegend: false}, ok.length);
  el.dataset.run = runId; onPointClick(el);
}
