// One score over two chosen parameters: the API's grid (a kernel-weighted mean of the complete trials) drawn as
// filled bands in hand-written SVG, the trials as dots on it.
"use strict";

const CONTOUR_GRID = 40;
const CONTOUR_LEVELS = 10;
const CONTOUR_REFRESH_MS = 10000;
const CONTOUR_UPSAMPLE = 4;  // pixels per grid cell along each axis: bands with smooth edges
// light to dark: low to high (viridis-like, reversed so that high reads as strong)
const CONTOUR_COLOURS = ["#fde725", "#b5de2b", "#6ece58", "#35b779", "#1f9e89", "#26828e", "#31688e", "#3e4989",
  "#482878", "#440154"];

function contourChoice(cols, analysis) {
  const names = cols.param_names;
  const st = runState.contour || {};
  if (!names.includes(st.x) || !names.includes(st.y) || st.x === st.y) {
    // the two most important parameters; in a co-designed run the strongest body constant against the
    // strongest gait parameter (body against gait), or two body constants when the body is all it searches
    const order = byImportance(names, analysis);
    const body = order.filter((j) => isBody(names[j]));
    const gait = order.filter((j) => !isBody(names[j]));
    const pair = body.length ? [body[0], gait.length ? gait[0] : body[1]] : order;
    st.x = names[pair[0]];
    st.y = names[pair[1]];
  }
  runState.contour = st;
  return st;
}

function drawContour(runId, cols, analysis) {
  const panel = document.getElementById("contour-panel");
  const names = cols.param_names;
  if (names.length < 2) { panel.hidden = true; return; }
  const st = contourChoice(cols, analysis);
  const bar = document.getElementById("contour-controls");
  const options = (sel) => names.map((nm) => `<option value="${esc(nm)}"${nm === sel ? " selected" : ""}>${esc(nm)}</option>`).join("");
  if (bar.dataset.sig !== names.join("\u0000")) {
    bar.dataset.sig = names.join("\u0000");
    bar.innerHTML = `<label>x <select id="contour-x">${options(st.x)}</select></label>
      <label>y <select id="contour-y">${options(st.y)}</select></label>`;
    for (const axis of ["x", "y"]) {
      document.getElementById(`contour-${axis}`).onchange = (ev) => {
        st[axis] = ev.target.value;
        drawContour(runId, cols, analysis);
      };
    }
  }
  const key = `${st.x}|${st.y}|${cols.n_trials}`;
  const box = document.getElementById("contour-box");
  if (box.dataset.key === key) return;  // a live refresh without new trials keeps the drawing
  // a running search redraws at most every CONTOUR_REFRESH_MS: the grid is recomputed from every trial
  const sameAxes = box.dataset.key && box.dataset.key.startsWith(`${st.x}|${st.y}|`);
  if (sameAxes && Date.now() - (st.fetchedAt || 0) < CONTOUR_REFRESH_MS) return;
  st.fetchedAt = Date.now();
  box.dataset.key = key;
  if (st.x === st.y) {
    box.innerHTML = "<p class='muted'>pick two different parameters</p>";
    return;
  }
  api(`/runs/${enc(runId)}/contour?x=${enc(st.x)}&y=${enc(st.y)}&grid=${CONTOUR_GRID}`).then((g) => {
    if (box.dataset.key !== key) return;  // another pair was picked meanwhile
    contourSvg(runId, box, g, cols);
    box.dataset.drawn = key;
  }).catch((e) => { box.innerHTML = `<p class="error" id="contour-error">${esc(e.message || e)}</p>`; });
}

/** The grid upsampled bilinearly and cut into levels, as an image (transparent where no trial is near). */
function contourImage(g, lo, hi) {
  const n = g.grid, m = n * CONTOUR_UPSAMPLE;
  const canvas = document.createElement("canvas");
  canvas.width = canvas.height = m;
  const ctx = canvas.getContext("2d");
  const img = ctx.createImageData(m, m);
  const rgb = CONTOUR_COLOURS.map((h) => [1, 3, 5].map((k) => parseInt(h.slice(k, k + 2), 16)));
  const at = (i, j) => g.z[Math.max(0, Math.min(n - 1, i))][Math.max(0, Math.min(n - 1, j))];
  for (let py = 0; py < m; py++) {
    const fy = (m - 1 - py + 0.5) / CONTOUR_UPSAMPLE - 0.5;  // row 0 of the grid is the bottom of the picture
    const i0 = Math.floor(fy), ty = fy - i0;
    for (let px = 0; px < m; px++) {
      const fx = (px + 0.5) / CONTOUR_UPSAMPLE - 0.5;
      const j0 = Math.floor(fx), tx = fx - j0;
      const q = [at(i0, j0), at(i0, j0 + 1), at(i0 + 1, j0), at(i0 + 1, j0 + 1)];
      if (q.some((v) => v === null)) continue;
      const v = (q[0] * (1 - tx) + q[1] * tx) * (1 - ty) + (q[2] * (1 - tx) + q[3] * tx) * ty;
      const level = Math.min(CONTOUR_LEVELS - 1, Math.max(0, Math.floor((v - lo) / (hi - lo) * CONTOUR_LEVELS)));
      const o = 4 * (py * m + px);
      [img.data[o], img.data[o + 1], img.data[o + 2]] = rgb[level];
      img.data[o + 3] = 255;
    }
  }
  ctx.putImageData(img, 0, 0);
  return canvas.toDataURL("image/png");
}

function contourAxis(svg, ticks, place, label, x, y, rotate) {
  ticks.forEach(([v, pos]) => {
    const t = svgEl("text", place(pos), svg);
    t.textContent = fmt(v, 3);
  });
  const t = svgEl("text", {x, y, "text-anchor": "middle", class: "pc-label",
    ...(rotate ? {transform: `rotate(-90 ${x} ${y})`} : {})}, svg);
  t.textContent = label;
}

function contourSvg(runId, box, g, cols) {
  const vals = g.z.flat().filter((v) => v !== null);
  document.getElementById("contour-title").textContent = g.value_name;
  const note = document.getElementById("contour-note");
  if (!vals.length) {
    box.innerHTML = "<p class='muted' id='contour-empty'>no complete trial to draw from yet</p>";
    note.textContent = "";
    return;
  }
  const lo = Math.min(...vals), hi = Math.max(...vals) > lo ? Math.max(...vals) : lo + 1;
  const width = box.clientWidth || 480, left = 64, right = 84, top = 10, bottom = 44;
  const size = Math.max(120, Math.min(340, width - left - right));
  const svg = svgEl("svg", {id: "contour-svg", width: left + size + right, height: top + size + bottom});
  box.replaceChildren(svg);
  box.dataset.cells = String(vals.length);
  box.dataset.points = String(g.points.trial_id.length);
  svgEl("rect", {x: left, y: top, width: size, height: size, fill: "#f0f2f6"}, svg);
  svgEl("image", {x: left, y: top, width: size, height: size, preserveAspectRatio: "none",
    href: contourImage(g, lo, hi)}, svg);
  const sx = (v) => left + (v - g.x_range[0]) / ((g.x_range[1] - g.x_range[0]) || 1) * size;
  const sy = (v) => top + size - (v - g.y_range[0]) / ((g.y_range[1] - g.y_range[0]) || 1) * size;
  const ticks = (r) => [0, 0.25, 0.5, 0.75, 1].map((f) => r[0] + f * (r[1] - r[0]));
  const unit = (nm) => { const u = cols.param_units[cols.param_names.indexOf(nm)]; return u && u !== "1" ? ` (${u})` : ""; };
  contourAxis(svg, ticks(g.x_range).map((v) => [v, sx(v)]), (p) => ({x: p, y: top + size + 14, "text-anchor": "middle",
    class: "pc-tick"}), g.x + unit(g.x), left + size / 2, top + size + 36, false);
  contourAxis(svg, ticks(g.y_range).map((v) => [v, sy(v)]), (p) => ({x: left - 5, y: p + 3.5, "text-anchor": "end",
    class: "pc-tick"}), g.y + unit(g.y), 14, top + size / 2, true);
  const dots = svgEl("g", {class: "contour-dots"}, svg);
  g.points.trial_id.forEach((id, k) => {
    const dot = svgEl("circle", {cx: sx(g.points.x[k]), cy: sy(g.points.y[k]), r: 3, "data-trial": id}, dots);
    svgEl("title", {}, dot).textContent = `trial ${id}: ${fmt(g.points.value[k])}`;
    dot.addEventListener("click", () => { location.hash = `#/run/${enc(runId)}/trial/${id}`; });
  });
  // colour bar: one band per level
  const bx = left + size + 14, bh = size / CONTOUR_LEVELS;
  CONTOUR_COLOURS.forEach((col, k) => svgEl("rect", {x: bx, y: top + size - (k + 1) * bh, width: 12, height: bh,
    fill: col}, svg));
  [[lo, top + size], [hi, top]].forEach(([v, y]) => {
    svgEl("text", {x: bx + 16, y: y + 3.5, class: "pc-tick"}, svg).textContent = fmt(v, 3);
  });
  note.textContent = `${g.points.trial_id.length} complete trials; each cell is their Gaussian-weighted mean (width
    ${fmt(g.bandwidth, 2)} of each range); blank: no trial near`;
}
