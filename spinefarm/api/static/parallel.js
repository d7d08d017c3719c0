// Interactive parallel coordinates (hand-written SVG): one axis per chosen parameter and one for the objective;
// drag along an axis to brush a range, brushes on several axes combine, lines outside them fade.
"use strict";

const PC_DEFAULT_AXES = 8;
const PC_HEIGHT = 300;       // plot height in px, labels below it
const PC_LABEL_ANGLE = 35;   // degrees; labels slant down-left from their axis
const OBJ_KEY = "__objective";
const SVG_NS = "http://www.w3.org/2000/svg";
let pcDragging = false;

function svgEl(tag, attrs, parent) {
  const el = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, v);
  if (parent) parent.appendChild(el);
  return el;
}

/** A co-designed run's body constant (docs/codesign.md): the parameters a `search:` block frees. */
function isBody(name) { return name.startsWith("body."); }

/** Parameter indices, most important first (the first ones when importance is flat). */
function byImportance(names, analysis) {
  const imp = names.map((nm) => (analysis.importance && analysis.importance[nm]) || 0);
  return names.map((_, j) => j).sort((a, b) => imp[b] - imp[a] || a - b);
}

/** The axes shown by default: a co-designed run's body constants, then the most important other parameters. */
function pcDefaultAxes(names, analysis) {
  const order = byImportance(names, analysis);
  const body = order.filter((j) => isBody(names[j])).slice(0, PC_DEFAULT_AXES);
  const rest = order.filter((j) => !isBody(names[j])).slice(0, PC_DEFAULT_AXES - body.length);
  return body.concat(rest).sort((a, b) => a - b).map((j) => names[j]);
}

function pcAxes(cols, ok) {
  const pc = runState.pc;
  const c = cols.columns;
  const axes = pc.axes.filter((nm) => cols.param_names.includes(nm)).map((nm) => {
    const j = cols.param_names.indexOf(nm);
    const unit = cols.param_units[j];
    return {key: nm, label: unit && unit !== "1" ? `${nm} (${unit})` : nm, values: cols.params[nm],
      lo: cols.param_lows[j], hi: cols.param_highs[j]};
  });
  const objs = ok.map((i) => c.objective[i]);
  axes.push({key: OBJ_KEY, label: cols.objective, values: c.objective,
    lo: objs.length ? Math.min(...objs) : 0, hi: objs.length ? Math.max(...objs) : 1});
  for (const a of axes) if (!(a.hi > a.lo)) { a.lo -= 0.5; a.hi += 0.5; }  // one value: a unit span around it
  return axes;
}

/** Rows of `ok` inside every brush (all of them when nothing is brushed). */
function pcInside(axes, ok) {
  const brushes = runState.pc.brushes;
  const active = axes.filter((a) => brushes[a.key]);
  return ok.filter((i) => active.every((a) => {
    const v = a.values[i], [lo, hi] = brushes[a.key];
    return v !== null && v >= lo && v <= hi;
  }));
}

function pcControls(runId, cols, analysis, ok, onBrush) {
  const box = document.getElementById("pc-controls");
  const pc = runState.pc;
  const names = cols.param_names;
  const sig = names.join("\u0000") + "|" + pc.axes.join("\u0000");
  if (box.dataset.sig === sig) return;
  box.dataset.sig = sig;
  box.innerHTML = `<details id="pc-axes"><summary>axes: ${pc.axes.length} of ${names.length} parameters</summary>
    <div class="pc-list">${names.map((nm) => `<label><input type="checkbox" value="${esc(nm)}"${
      pc.axes.includes(nm) ? " checked" : ""}> ${esc(nm)}</label>`).join("")}</div></details>
    <button type="button" id="pc-clear">clear brushes</button>`;
  box.querySelectorAll("#pc-axes input").forEach((cb) => cb.addEventListener("change", () => {
    pc.axes = names.filter((nm) => nm === cb.value ? cb.checked : pc.axes.includes(nm));
    for (const k of Object.keys(pc.brushes)) if (k !== OBJ_KEY && !pc.axes.includes(k)) delete pc.brushes[k];
    pcOpen = true;
    drawParallel(runId, cols, analysis, ok, onBrush);
  }));
  if (pcOpen) document.getElementById("pc-axes").open = true;
  document.getElementById("pc-clear").onclick = () => {
    pc.brushes = {};
    drawParallel(runId, cols, analysis, ok, onBrush);
    onBrush();
  };
}
let pcOpen = false;

function pcLayout(svg, axes, width) {
  // measure the labels, then leave room for the slanted ones at both ends and below
  const probe = svgEl("text", {class: "pc-label"}, svg);
  const widths = axes.map((a) => { probe.textContent = a.label; return probe.getComputedTextLength(); });
  probe.remove();
  const cos = Math.cos(PC_LABEL_ANGLE * Math.PI / 180), sin = Math.sin(PC_LABEL_ANGLE * Math.PI / 180);
  const right = 16;
  let left = 56, step = 0;
  for (let pass = 0; pass < 3; pass++) {
    step = axes.length > 1 ? (width - left - right) / (axes.length - 1) : 0;
    left = Math.max(56, ...widths.map((w, k) => w * cos + 6 - k * step));
  }
  const top = 18;
  const bottom = 18 + Math.max(...widths) * sin + 12;
  return {top, left, step, bottom, height: top + PC_HEIGHT + bottom,
    x: (k) => left + k * step, y: (a, v) => top + (1 - (v - a.lo) / (a.hi - a.lo)) * PC_HEIGHT};
}

function pcLines(g, axes, ok, inside, L, c) {
  g.replaceChildren();
  const inSet = new Set(inside);
  const objs = inside.map((i) => c.objective[i]).sort((a, b) => a - b);
  const q = (f) => objs.length ? objs[Math.min(objs.length - 1, Math.floor(f * objs.length))] : 0;
  const cuts = [q(0.5), q(0.8), q(0.95)];
  const groups = [[], [], [], [], []];  // faded, then bands of the objective among the brushed, low to high
  for (const i of ok) {
    const pts = [];
    for (let k = 0; k < axes.length; k++) {
      const v = axes[k].values[i];
      if (v === null) continue;
      pts.push(`${L.x(k).toFixed(1)},${L.y(axes[k], v).toFixed(1)}`);
    }
    const d = "M" + pts.join("L");
    if (!inSet.has(i)) groups[0].push(d);
    else groups[1 + cuts.filter((t) => c.objective[i] >= t).length].push(d);
  }
  const styles = [["#c9d1de", 0.25], ["#aab6ca", 0.45], ["#6f8fd0", 0.6], ["#3461c1", 0.8], ["#c0392b", 0.95]];
  groups.forEach((ds, k) => {
    if (ds.length) svgEl("path", {d: ds.join(""), fill: "none", stroke: styles[k][0], "stroke-opacity": styles[k][1],
      "stroke-width": k ? 1.2 : 1, class: k ? "pc-in" : "pc-out"}, g);
  });
}

function pcTicks(ax, a, L, k) {
  const n = 4;
  for (let t = 0; t <= n; t++) {
    const v = a.lo + (a.hi - a.lo) * t / n;
    const y = L.y(a, v);
    svgEl("line", {x1: L.x(k) - 4, x2: L.x(k), y1: y, y2: y, stroke: "#6b7385"}, ax);
    svgEl("text", {x: L.x(k) - 6, y: y + 3.5, "text-anchor": "end", class: "pc-tick"}, ax).textContent = fmt(v, 3);
  }
}

/** Draw the panel; onBrush() is called when the brushed set changes (the trials table may show only it). */
function drawParallel(runId, cols, analysis, ok, onBrush) {
  if (pcDragging) return;  // a live refresh waits for the drag to end
  const pc = runState.pc;
  if (!pc.axes) pc.axes = pcDefaultAxes(cols.param_names, analysis);
  pcControls(runId, cols, analysis, ok, onBrush);
  const box = document.getElementById("pc-box");
  const axes = pcAxes(cols, ok);
  const c = cols.columns;
  runState.redrawParallel = () => drawParallel(runId, cols, analysis, ok, onBrush);
  const svg = svgEl("svg", {id: "pc-svg", width: box.clientWidth || 600});
  box.replaceChildren(svg);
  const L = pcLayout(svg, axes, box.clientWidth || 600);
  svg.setAttribute("height", L.height);
  const lines = svgEl("g", {class: "pc-lines"}, svg);
  const refresh = () => {
    const inside = pcInside(axes, ok);
    runState.brushed = Object.keys(pc.brushes).length ? new Set(inside) : null;
    if (!runState.brushed) runState.onlyBrushed = false;  // the next brush starts with the whole table
    pcLines(lines, axes, ok, inside, L, c);
    pcList(runId, inside, ok, c);
    box.dataset.lines = String(ok.length);
    box.dataset.brushed = String(inside.length);
  };
  axes.forEach((a, k) => {
    const ax = svgEl("g", {class: "pc-axis", "data-key": a.key}, svg);
    svgEl("line", {x1: L.x(k), x2: L.x(k), y1: L.top, y2: L.top + PC_HEIGHT, stroke: "#1d2430"}, ax);
    pcTicks(ax, a, L, k);
    const lx = L.x(k), ly = L.top + PC_HEIGHT + 16;
    const label = svgEl("text", {x: lx, y: ly, "text-anchor": "end", class: "pc-label",
      transform: `rotate(-${PC_LABEL_ANGLE} ${lx} ${ly})`}, ax);
    label.textContent = a.label;
    const brush = svgEl("rect", {x: lx - 8, width: 16, class: "pc-brush", visibility: "hidden"}, ax);
    const hit = svgEl("rect", {x: lx - 12, width: 24, y: L.top - 4, height: PC_HEIGHT + 8, class: "pc-hit"}, ax);
    const show = (range) => {
      if (range) {
        const [y1, y2] = [L.y(a, range[1]), L.y(a, range[0])];
        brush.setAttribute("y", y1); brush.setAttribute("height", Math.max(1, y2 - y1));
        brush.setAttribute("visibility", "visible");
        ax.dataset.lo = String(range[0]); ax.dataset.hi = String(range[1]);
      } else {
        brush.setAttribute("visibility", "hidden");
        delete ax.dataset.lo; delete ax.dataset.hi;
      }
    };
    show(pc.brushes[a.key]);
    pcBrushing(hit, svg, a, L, show, () => { refresh(); onBrush(); });
  });
  refresh();
}

function pcBrushing(hit, svg, a, L, show, changed) {
  const value = (ev) => {
    const pt = new DOMPoint(ev.clientX, ev.clientY).matrixTransform(svg.getScreenCTM().inverse());
    const f = 1 - (Math.min(L.top + PC_HEIGHT, Math.max(L.top, pt.y)) - L.top) / PC_HEIGHT;
    return {v: a.lo + f * (a.hi - a.lo), y: pt.y};
  };
  let start = null;
  hit.addEventListener("pointerdown", (ev) => {
    start = value(ev);
    pcDragging = true;
    hit.setPointerCapture(ev.pointerId);
    ev.preventDefault();
  });
  hit.addEventListener("pointermove", (ev) => {
    if (!start) return;
    const now = value(ev);
    show([Math.min(start.v, now.v), Math.max(start.v, now.v)]);
  });
  hit.addEventListener("pointerup", (ev) => {
    if (!start) return;
    const now = value(ev);
    const brushes = runState.pc.brushes;
    if (Math.abs(now.y - start.y) < 3) delete brushes[a.key];  // a click clears this axis' brush
    else brushes[a.key] = [Math.min(start.v, now.v), Math.max(start.v, now.v)];
    start = null;
    pcDragging = false;
    show(brushes[a.key]);
    changed();
  });
}

function pcList(runId, inside, ok, c) {
  const el = document.getElementById("pc-brushed");
  const brushed = Object.keys(runState.pc.brushes).length > 0;
  const r = enc(runId);
  const shown = inside.slice().sort((a, b) => c.objective[b] - c.objective[a]).slice(0, 40);
  el.innerHTML = brushed ? `<span id="pc-count">${inside.length} of ${ok.length} trials inside the brushes</span>
    <label><input type="checkbox" id="pc-only"${runState.onlyBrushed ? " checked" : ""}> only these in the trials
    table</label><div class="small" id="pc-ids">${shown.map((i) => `<a href="#/run/${r}/trial/${c.trial_id[i]}">${
      c.trial_id[i]}</a>`).join(" ")}${inside.length > shown.length ? ` … (the best ${shown.length})` : ""}</div>`
    : `<span class="muted" id="pc-count">${ok.length} trials; drag along an axis to select a range, click an axis to
    clear it</span>`;
  const only = document.getElementById("pc-only");
  if (only) only.onchange = () => { runState.onlyBrushed = only.checked; runState.page = 0; runState.redrawTable(); };
}

// the axes spread over the panel's width: draw again when it changes
let pcResizeTimer = null;
window.addEventListener("resize", () => {
  clearTimeout(pcResizeTimer);
  pcResizeTimer = setTimeout(() => {
    if (document.getElementById("pc-svg") && runState.redrawParallel) runState.redrawParallel();
  }, 200);
});
