// The spinefarm dashboard: one page over the read-only JSON API (#/, #/run/ID, #/run/ID/trial/N).
"use strict";

const view = document.getElementById("view");
const crumbs = document.getElementById("crumbs");
const liveBadge = document.getElementById("live");
const REFRESH_MS = 2000;
const WATCH_MS = 5000;
let timer = null;
let liveGen = -1; // the generation whose page last refreshed a running run
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
  if (live) {
    liveGen = generation;
    timer = setTimeout(fn, REFRESH_MS);
  } else if (liveGen === generation) {
    timer = setTimeout(() => watchServer(fn), WATCH_MS);
  }
}

// A page that saw its run live and then done (the search's last status) watches its server, lightly: the
// search's own server stops moments later, and the page says so (fn's refresh fails into serverGone).
async function watchServer(fn) {
  const gen = generation;
  try {
    await api("/health");
  } catch {
    if (gen === generation) fn();
    return;
  }
  if (gen === generation) timer = setTimeout(() => watchServer(fn), WATCH_MS);
}

const fmtDuration = (s) => (s === null || s === undefined) ? "–" : s < 90 ? `${Math.round(s)} s`
  : s < 5400 ? `${Math.round(s / 60)} min` : `${(s / 3600).toFixed(1)} h`;
const fmtDate = (t) => t ? new Date(t * 1000).toLocaleString(undefined, {dateStyle: "short", timeStyle: "short"}) : "–";

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

// ---------------------------------------------------------------- one run
// what went on beside the trials: the judge's raised fidelity, a status file set aside, workers left out of the run
function runWarnings(status) {
  const out = [];
  if (status.fidelity_raised) {
    out.push(`<div class="notice warn" id="fidelity-raised">The judge raised the screen's fidelity for the rest of
      the run: ${esc(status.fidelity_raised)}.</div>`);
  }
  if (status.status_file_error) {
    out.push(`<div class="notice warn" id="status-file-error">${esc(status.status_file_error)}; the state shown
      comes from the run file alone.</div>`);
  }
  const left = Object.entries(status.unservable_workers || {});
  if (left.length) {
    out.push(`<div class="notice warn" id="unservable-workers">${left.length} worker${left.length > 1 ? "s" : ""}
      left out of this run (the others serve it): <ul>${left.map(([w, why]) =>
      `<li><b>${esc(w)}</b>: ${esc(why)}</li>`).join("")}</ul></div>`);
  }
  return out.join("");
}

function runNotice(status, r) {
  const older = status.file_note ? `<div class="notice" id="older-file">${esc(status.file_note)}.</div>` : "";
  return older + runWarnings(status) + runOutcome(status, r);
}

function runOutcome(status, r) {
  const best = status.best;
  if (status.state === "stopped") {
    return `<div class="notice" id="stopped">This run stopped before its budget (${status.parameter_sets_done} of
      ${status.trials_budget} parameter sets). Continue it with <code>${esc(status.resume_command)}</code>.</div>`;
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
    <div class="panel notes" id="notes-panel"></div>
    <div class="grid">
      <div class="panel"><h2>Best so far against trials</h2><div class="plot" id="plot-progress"></div></div>
      <div class="panel"><h2>Best so far against time</h2><div class="plot" id="plot-time"></div></div>
      <div class="panel"><h2>Speed against cost of transport <span class="muted" id="pareto-note"></span></h2><div class="plot" id="plot-pareto"></div></div>
      <div class="panel"><h2>Failed trials by reason</h2><div class="plot" id="plot-failed"></div></div>
      <div class="panel wide" id="pc-panel"><h2>Parallel coordinates <span class="muted">(drag along an axis to
        select a range)</span></h2><p class="muted small" id="params-rung-note" hidden></p>
        <div class="pc-controls" id="pc-controls"></div><div class="pc" id="pc-box"></div>
        <div class="pc-brushed" id="pc-brushed"></div></div>
      <div class="panel" id="contour-panel"><h2><span id="contour-title">objective</span> over two parameters</h2>
        <div class="filters" id="contour-controls"></div><div class="contour" id="contour-box"></div>
        <p class="muted small" id="contour-note"></p></div>
      <div class="panel"><h2>One parameter against the objective <select id="param-select"></select></h2>
        <div class="plot" id="plot-param"></div></div>
      <div class="panel"><h2>Objective distribution <span class="muted">(EDF: share of trials at most x)</span></h2>
        <div class="plot" id="plot-edf"></div></div>
      <div class="panel"><h2>Rank plot <span class="muted">(colour: the objective's rank)</span></h2>
        <div class="filters" id="rank-controls"></div><div class="plot" id="plot-rank"></div></div>
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
  if (first) {
    runSkeleton(runId);
    notesPanel(document.getElementById("notes-panel"), runId, null);
  }
  document.getElementById("run-title").innerHTML = `${esc(runId)} ${stateBadge(status.state)}`;
  const best = status.best;
  const alive = status.workers.filter((w) => w.alive).length;
  const step = status.step_s || meta.trial_config.dt_s;
  document.getElementById("cards").innerHTML = [
    card("robot", esc(status.morphology)), card("state", stateBadge(status.state)),
    card("parameter sets", `${status.parameter_sets_done} / ${status.trials_budget}`),
    card("evaluations", `${status.evaluations_done}`),
    ...(status.state === "running" ? [card("ETA", `<span id="eta">${fmtDuration(status.eta_s)}</span>`)] : []),
    card("failed", status.trials_failed), card("trials per second", fmt(status.rate_trials_s, 3)),
    ...(status.state === "running" || status.workers.length ? [card("workers", `${alive}${status.workers.length > alive
      ? " (+" + (status.workers.length - alive) + " gone)" : ""}`)] : []),
    card("best " + esc(meta.objective), best ? `<a href="#/run/${r}/trial/${best.trial_id}">${fmt(best.objective)}</a>` : "–"),
    card("best distance (m)", best ? `${fmt(status.best_distance_m)}${["holds", "moved", "judged"].includes(best.verification.verdict)
      ? ' <span class="muted">judged</span>' : ""}` : "–"),
    card("best speed (cm/s)", best ? `<span id="best-speed">${bestSpeed(best)}</span>` : "–"), card("best COT", best ? `<span id="best-cot">${bestCot(best)}</span>` : "–"),
    card("best verified", best ? `<span class="verdict ${esc(best.verification.verdict)}">${esc(best.verification.label || best.verification.verdict)}</span>` : "–"),
    // better than the best, but no other identity's audit has agreed yet: shown apart, never as the best
    ...(status.pending_audit ? [card("pending audit", `<a href="#/run/${r}/trial/${status.pending_audit.trial_id}">trial ${
      status.pending_audit.trial_id}</a>: ${fmt(status.pending_audit.verification.counted_distance_m)} m`)] : []),
    ...(status.audit && status.audit.fraction > 0 ? [card("audits agree / disagree",
      `${status.audit.audits_agrees} / ${status.audit.audits_disagrees}`)] : []),
    meta.physical ? card("engine, step", `${esc(status.engine || "bullet")}, ${step ? fmt(step * 1000) + " ms" : "not run yet"}`) : "",
    card("sampler", esc(status.sampler || "–")), card("started", fmtDate(status.started_at_unix_s)),
    meta.engine_choice ? engineChoiceCard(meta.engine_choice) : "",
    status.ladder ? ladderCard(status.ladder) : "",
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

// a judged set's speed: the API's judged_speed_cm_s (the report's figure); computed the same way from an older API
function judgedSpeed(t) {
  const v = t.verification;
  if (v.judged_speed_cm_s !== undefined) return v.judged_speed_cm_s;
  return ["holds", "moved", "judged"].includes(v.verdict) && v.counted_distance_m != null && t.scores.sim_time_s
    ? 100 * v.counted_distance_m / t.scores.sim_time_s : null;
}

// a judged best's speed is the judged one (the screen's on hover)
function bestSpeed(best) {
  const judged = judgedSpeed(best);
  if (judged == null) return fmt(best.scores.speed_cm_s);
  return `<span title="screen's speed ${fmt(best.scores.speed_cm_s)} cm/s">${fmt(judged)}</span> <span class="muted">judged</span>`;
}

// a judged best's COT is the judge's (the screen's on hover); one the judge did not measure says so
function bestCot(best) {
  if (best.judged_cot != null) {
    return `<span title="screen's COT ${fmt(best.scores.cot)}">${fmt(best.judged_cot)}</span> <span class="muted">judged</span>`;
  }
  const note = best.judged_cot_note ? ` <span class="muted">screen's; judge's ${esc(best.judged_cot_note)}</span>` : "";
  return `${fmt(best.scores.cot)}${note}`;
}

// how `search --engine auto` chose the tier: the calibration's figures, its reason on hover
function engineChoiceCard(c) {
  const text = `${esc(c.engine)}: ρ ${fmt(c.spearman, 3)}, top-${c.top_k} ${c.top_overlap}, ratio ${fmt(c.median_distance_ratio, 3)}`;
  const why = c.screen_fit ? `${c.reason || ""}\n${c.screen_fit.summary || ""}` : c.reason || "";
  return `<div class="card" title="${esc(why)}" data-engine-choice="${esc(c.engine)}"><div class="v">${text}</div>`
    + `<div class="k">engine auto${c.shipped ? " (shipped calibration)" : c.cached ? " (cached calibration)" : ""}`
    + `${c.screen_fit ? `; screen fitted to the judge (profile ${esc(c.screen_fit.profile_hash)}), then ${esc(c.screen_fit.decision)}` : ""}</div></div>`;
}

// the rungs the run screens with, and why these (the robot's ladder, the default, typed)
function ladderCard(l) {
  return `<div class="card" id="ladder"><div class="v">rungs ${esc(l.rungs)} s, eta ${l.eta}</div>`
    + `<div class="k">screening ladder: <span id="ladder-reason">${esc(l.reason || "reason not stored")}</span></div></div>`;
}

// ---------------------------------------------------------------- one trial
// a judged best in both engines: the judge's and the other engine's distance, their ratio, the step errors
function spreadRows(m) {
  if (!m) return "";
  const side = (s) => `${esc(s.engine)}${s.dt_s ? " at " + fmt(s.dt_s * 1000) + " ms" : ""}`;
  const dist = (s) => s.status && s.status !== "complete" ? `failed (${esc(s.reason || "no distance")})` : fmt(s.distance_m, 6);
  const errs = Object.entries(m.step_error).filter(([, e]) => e != null)
    .map(([t, e]) => `${esc(t)} ${fmt(100 * e, 2)} %`).join(", ");
  return `<tr><td class="l">model spread: judge, ${side(m.judge)} (m)</td><td id="spread-judge">${dist(m.judge)}</td></tr>
    <tr><td class="l">other engine, ${side(m.other)} (m)</td><td id="spread-other">${dist(m.other)}</td></tr>
    <tr><td class="l">other / judge ratio</td><td id="spread-ratio">${fmt(m.ratio, 4)}</td></tr>
    <tr><td class="l">step error (calibration)</td><td class="l" id="spread-step-error">${errs || "unknown (not calibrated)"}</td></tr>`;
}

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
    <div class="panel notes" id="notes-panel"></div>
    <div class="grid">
      <div class="panel"><h2>Verification</h2><table id="verification"><tbody>
        <tr><td class="l">verdict</td><td class="l verdict ${esc(v.verdict)}" id="verdict-label">${esc(v.label || v.verdict)}</td></tr>
        <tr><td class="l">distance at the search's step (m)</td><td>${fmt(t.scores.distance_m, 6)}</td></tr>
        <tr><td class="l">distance re-simulated in ${esc(v.judge || "a finer step")} (m)</td><td>${fmt(v.fine_step_distance_m, 6)}</td></tr>
        ${t.judged_cot != null || t.judged_cot_note ? `<tr><td class="l">COT in ${esc(v.judge || "a finer step")} (screen's: ${fmt(t.scores.cot, 4)})</td>
          <td id="judged-cot">${t.judged_cot != null ? fmt(t.judged_cot, 6) : esc(t.judged_cot_note)}</td></tr>` : ""}
        ${v.verdict === "judged" && v.screen_to_judge_ratio != null ? `<tr><td class="l">screen / judge ratio</td><td>${fmt(v.screen_to_judge_ratio, 4)}</td></tr>` : ""}
        ${spreadRows(t.model_spread)}
        ${t.audit && t.audit.state !== "not_audited" ? `<tr><td class="l">audit by ${esc(t.audit.worker_id || "another worker")}</td>
          <td class="l">${esc(t.audit.state)} (${fmt(t.audit.distance_m, 6)} m)</td></tr>` : ""}
        ${v.reason ? `<tr><td class="l">reason</td><td class="l">${esc(v.reason)}</td></tr>` : ""}</tbody></table>
        <h2 style="margin-top:1em">Score parts</h2><table id="scores"><tbody>${scoreRows}</tbody></table></div>
      <div class="panel"><h2>Parameters</h2><div class="tablewrap"><table id="params"><thead><tr><th class="l">name</th>
        <th>value</th><th class="l">unit</th><th>in range (0–1)</th></tr></thead><tbody>${paramRows}</tbody></table></div></div>
    </div>
    <div id="episodes"></div>
    <div class="panel" style="margin-top:1em"><h2>The gait, moving</h2><div id="motion-area"></div></div>
    <div class="panel picture" style="margin-top:1em"><h2>The gait in six frames</h2><div id="picture"></div></div>`;
  notesPanel(document.getElementById("notes-panel"), runId, t.trial_id);
  if (meta.robust && meta.robust.episodes) showEpisodes(r, t.trial_id, gen);
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
  // the gait moves when opened, unless the reader asked their system for less motion
  if (!window.matchMedia("(prefers-reduced-motion: reduce)").matches) window.spinefarmPlayer.play();
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
  if (window.spinefarmPlayer) window.spinefarmPlayer.pause();
  motionViews.forEach((v) => v.dispose());
  motionViews = [];
  liveBadge.hidden = true;
  const gen = generation;
  const parts = location.hash.replace(/^#\/?/, "").split("/").map(decodeURIComponent);
  let p;
  if (parts[0] === "compare") {
    p = showCompare((parts[1] || "").split(",").filter((x) => x), gen);
  } else if (parts[0] === "run" && parts[1] && parts[2] === "watch" && parts[3]) {
    p = showWatch(parts[1], parts[3].split(",").map(Number).filter((x) => Number.isInteger(x) && x >= 0), gen);
  } else if (parts[0] === "run" && parts[1] && parts[2] === "trial" && parts[3] !== undefined) {
    p = showTrial(parts[1], Number(parts[3]), gen);
  } else if (parts[0] === "run" && parts[1]) {
    resetRunState(parts[1]);
    p = showRun(parts[1], gen, true);
  } else {
    p = showRuns(gen);
  }
  p.catch((e) => {
    showError(e);
    // a run file the server has not read yet (a busy machine, a search just started): look again shortly
    if (/no such run/.test(e.message || "") && notYetRead++ < 15) timer = setTimeout(route, REFRESH_MS);
  });
}

let notYetRead = 0;
window.addEventListener("hashchange", () => { notYetRead = 0; route(); });
route();
