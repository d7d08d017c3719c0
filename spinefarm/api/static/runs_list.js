// The runs list (#/): every run file the API serves, sortable, runs ticked for the comparison page.
// Loaded before dashboard.js, which holds the helpers it uses and routes to it.
"use strict";

const RUN_COLUMNS = [  // [key, label, value of a run for sorting, left-aligned]
  ["run_id", "run", (r) => r.run_id, true], ["morphology", "robot", (r) => r.morphology, true],
  ["state", "state", (r) => r.state, true], ["started", "started", (r) => r.started_at_unix_s, false],
  ["controller", "controller", (r) => r.controller, true], ["engine", "engine", (r) => r.engine, true],
  ["sampler", "sampler", (r) => r.sampler, true], ["objective", "objective", (r) => r.objective, true],
  ["progress", "progress", (r) => runSets(r) / Math.max(1, r.trials_budget), false],
  ["distance", "best distance (m)", (r) => r.best_distance_m, false],
  ["failed", "failed", (r) => r.trials_failed, false], ["eta", "ETA", (r) => r.eta_s, false],
  ["speed", "best speed (cm/s)", (r) => r.best && (judgedSpeed(r.best) ?? r.best.scores.speed_cm_s), false],
  ["cot", "best COT", (r) => r.best && (r.best.judged_cot != null ? r.best.judged_cot : r.best.scores.cot), false],
  ["verified", "best verified", (r) => r.best && r.best.verification.verdict, true],
];
const runsSort = {key: "started", dir: -1};
const runsPicked = new Set();  // run ids ticked for comparison; kept while the list refreshes

/** Parameter sets done (an older API's status has only the trial rows). */
function runSets(r) { return r.parameter_sets_done != null ? r.parameter_sets_done : r.trials_done; }

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
    case "progress": {  // parameter sets against the budget; a multi-fidelity run evaluates a set more than once
      const pct = Math.min(100, 100 * runSets(r) / Math.max(1, r.trials_budget));
      return `<span class="bar"><span style="width:${pct}%"></span></span> ${runSets(r)}/${r.trials_budget} sets`
        + (r.evaluations_done != null ? ` <span class="muted">${r.evaluations_done} evaluations</span>` : "");
    }
    case "distance": return r.best_distance_m != null ? fmt(r.best_distance_m) : "–";
    case "failed": return String(r.trials_failed);
    case "eta": return r.state === "running" ? fmtDuration(r.eta_s) : "–";
    case "speed": return best ? bestSpeed(best) : "–";
    case "cot": return best ? bestCot(best) : "–";   // the judge's beside a judged distance
    case "verified": return best ? `<span class="verdict ${esc(best.verification.verdict)}">${esc(best.verification.label || best.verification.verdict)}</span>` : "–";
  }
  return "";
}

function damagedList(bad) {
  if (!bad.length) return "";
  return `<div class="notice warn" id="damaged"><b>${bad.length} file${bad.length > 1 ? "s" : ""} left out</b>
    (damaged, not a run file, or still being read): <ul>${bad.map((b) => `<li><code>${esc(b.file)}</code>: ${esc(b.reason)}</li>`).join("")}</ul></div>`;
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
  for (const id of [...runsPicked]) if (!runs.some((r) => r.run_id === id)) runsPicked.delete(id);
  const rows = runs.map((r) => `<tr class="row" data-run="${esc(r.run_id)}"><td class="compare-pick"><input
    type="checkbox" class="pick" value="${esc(r.run_id)}" title="compare"${runsPicked.has(r.run_id) ? " checked" : ""}></td>`
    + RUN_COLUMNS.map(([key, , , left]) => `<td${left ? " class=\"l\"" : ""}>${runCell(key, r)}</td>`).join("") + "</tr>").join("");
  const head = `<th class="compare-pick" title="pick runs to compare"></th>` + RUN_COLUMNS.map(([key, label, , left]) =>
    `<th data-key="${key}" class="${left ? "l " : ""}${key === runsSort.key ? (runsSort.dir > 0 ? "sorted-asc"
      : "sorted-desc") : ""}">${label}</th>`).join("");
  view.innerHTML = `<h1>Runs</h1>${damagedList(bad)}${runs.length ? "" : "<p class='muted' id='no-runs'>no run files found</p>"}
    <div class="buttons"><button type="button" class="button" id="compare-runs"></button></div>
    <div class="tablewrap"><table id="runs-table"><thead><tr>${head}</tr></thead><tbody>${rows}</tbody></table></div>`;
  const compareButton = document.getElementById("compare-runs");
  const pickedChanged = () => {
    compareButton.textContent = `compare the picked runs (${runsPicked.size})`;
    compareButton.disabled = runsPicked.size < 2;
    compareButton.title = runsPicked.size < 2 ? "tick two or more runs" : "";
  };
  pickedChanged();
  compareButton.onclick = () => { location.hash = `#/compare/${[...runsPicked].map(enc).join(",")}`; };
  view.querySelectorAll("#runs-table input.pick").forEach((cb) => {
    cb.addEventListener("click", (ev) => ev.stopPropagation());  // ticking is not opening the run
    cb.addEventListener("change", () => {
      if (cb.checked) runsPicked.add(cb.value); else runsPicked.delete(cb.value);
      pickedChanged();
    });
  });
  view.querySelectorAll("td.compare-pick").forEach((td) => td.addEventListener("click", (ev) => ev.stopPropagation()));
  view.querySelectorAll("#runs-table th[data-key]").forEach((th) => th.addEventListener("click", () => {
    if (runsSort.key === th.dataset.key) runsSort.dir *= -1;
    else { runsSort.key = th.dataset.key; runsSort.dir = th.classList.contains("l") ? 1 : -1; }
    showRuns(gen).catch(showError);
  }));
  view.querySelectorAll("tr.row").forEach((tr) => tr.addEventListener("click", () => {
    location.hash = `#/run/${enc(tr.dataset.run)}`;
  }));
  const reopen = runs.length === 1 ? runs[0].reopen_command : "spinefarm api runs/*.h5";
  // a file whose first read ran out of time (a busy machine) is read again by the server: look again too
  const pending = bad.some((b) => /did not finish within/.test(b.reason));
  schedule(() => showRuns(gen).catch((e) => serverGone(e, gen, reopen)),
    runs.some((r) => r.state === "running") || pending);
}

