// Notes on a run and on a trial (loaded before dashboard.js, which shows them on the run and trial pages): kept
// by the API in a file beside the run file (RUN.h5.notes.json), never in the run file itself.
"use strict";

async function notesPanel(box, runId, trialId) {
  const r = enc(runId);
  const url = trialId === null ? `/runs/${r}/notes` : `/runs/${r}/trials/${trialId}/notes`;
  let notes;
  try {
    notes = await api(`/runs/${r}/notes`);
  } catch (e) {
    box.innerHTML = `<h2>Notes</h2><p class="error" id="notes-error">${esc(e.message || e)}</p>`;
    return;
  }
  const text = trialId === null ? notes.run : (notes.trials[String(trialId)] || "");
  box.innerHTML = `<h2>Notes on this ${trialId === null ? "run" : "trial"} <span class="muted small">(kept in a file
    beside the run file, never in it)</span></h2>
    <textarea id="notes-text" rows="3" maxlength="20000">${esc(text)}</textarea>
    <div class="buttons"><button type="button" class="button" id="notes-save">save the note</button>
    <span class="muted small" id="notes-state"></span></div>`;
  const state = box.querySelector("#notes-state");
  box.querySelector("#notes-save").onclick = async () => {
    state.textContent = "saving…";
    const resp = await fetch(url, {method: "PUT", headers: {"Content-Type": "application/json"},
      body: JSON.stringify({text: box.querySelector("#notes-text").value})}).catch((e) => ({ok: false, error: e}));
    const body = resp.json ? await resp.json().catch(() => null) : null;
    state.textContent = resp.ok ? "saved" : `not saved: ${(body && body.detail && body.detail.message) || resp.error || resp.status}`;
    state.className = resp.ok ? "muted small" : "error small";
    box.dataset.saved = resp.ok ? "1" : "0";
  };
}
