// The live view: ask the server for the run's state, redraw when it changed. Plots by uPlot
// (vendor/, MIT): the loop as x-y curves (uPlot's mode 2), the time series as lines.
"use strict";

const MEASURED = "#1f77b4";
const MODEL = "#ff7f0e";
const VOLTAGE = "#2ca02c";
const EARLIER = "#a9b4c2";
const FINAL = ["complete", "aborted", "failed"];
// once the run has ended the file no longer changes: ask now and then only
const ENDED_POLL_MS = 1000;

// what a test (or a curious person) can read: draws, their times, the last documents
window.labrigLive = {
  draws: 0, drawTimes: [], firstDataDraw: null, doc: null, fetchErrors: 0,
  loops: null, entry: null, view: null, readout: null, plots: {}, zoomed: {}, updateMs: [],
};
const L = window.labrigLive;

function text(id, value) { document.getElementById(id).textContent = value; }

function statusLine(doc) {
  if (doc.status === "waiting") { return ["waiting", "waiting for the run file"]; }
  if (doc.status === "running") {
    if (doc.writing === "being written") { return ["running", "running (being written)"]; }
    return ["incomplete", "incomplete: " + doc.writing];
  }
  const why = doc.reason ? ": " + doc.reason : "";
  return [doc.status, doc.status + why];
}

// -- the plots ----------------------------------------------------------------------------

// x-y curves for uPlot's mode 2: a polyline through the points in their order (null: pen up)
function xyPath(u, si) {
  const [xs, ys] = u.data[si];
  const p = new Path2D();
  let pen = false;
  for (let i = 0; i < xs.length; i++) {
    const x = xs[i], y = ys[i];
    if (x === null || y === null) { pen = false; continue; }
    const px = u.valToPos(x, "x", true), py = u.valToPos(y, "y", true);
    if (pen) { p.lineTo(px, py); } else { p.moveTo(px, py); pen = true; }
  }
  return { stroke: p, fill: null, clip: null, band: null, gaps: null, flags: 0 };
}

function num(v, digits) { return v === null || v === undefined ? "-" : String(+(+v).toPrecision(digits)); }

// a drag zooms (the plot keeps that zoom while new data come); a double-click resets it
function zoomHooks(key) {
  return {
    setSelect: [(u) => { if (u.select.width > 2 || u.select.height > 2) { L.zoomed[key] = true; } }],
    ready: [(u) => u.over.addEventListener("dblclick", () => { L.zoomed[key] = false; })],
  };
}

function loopPlot() {
  const s = (label, stroke, width, dash) => ({ label, stroke, width, dash, paths: xyPath, points: { show: false } });
  return new uPlot({
    mode: 2,
    width: 560, height: 420,
    legend: { show: false },
    scales: { x: { time: false }, y: {} },
    cursor: { drag: { x: true, y: true, setScale: true }, points: { show: false }, dataIdx: () => null },
    axes: [{ label: "command voltage (V)" }, { label: "strain (ue)" }],
    series: [{}, s("other entries", EARLIER, 1), s("shown entry", MEASURED, 1.5), s("model", MODEL, 1.5, [6, 4])],
    hooks: Object.assign(zoomHooks("loop"), { setCursor: [loopReadout] }),
  }, [null, [[], []], [[], []], [[], []]], document.getElementById("loop"));
}

function seriesPlot(id, label, series) {
  return new uPlot({
    width: 620, height: 200,
    scales: { x: { time: false } },
    cursor: { sync: { key: "labrig-time" }, drag: { x: true, y: false, setScale: true } },
    axes: [{ label: "time (s)" }, { label }],
    series: [{ label: "time (s)", value: (u, v) => num(v, 6) }, ...series.map((s) => Object.assign({
      width: 1.5, value: (u, v) => num(v, 5), points: { show: false },
    }, s))],
    hooks: zoomHooks(id),
  }, [[], ...series.map(() => [])], document.getElementById(id));
}

function plots(withModel) {
  if (!L.plots.loop) {
    L.plots.loop = loopPlot();
    const strain = [{ label: "measured (ue)", stroke: MEASURED }];
    if (withModel) { strain.push({ label: "model (ue)", stroke: MODEL, dash: [6, 4] }); }
    L.plots.strain = seriesPlot("strain", "strain (ue)", strain);
    L.plots.voltage = seriesPlot("voltage", "voltage (V)", [{ label: "command (V)", stroke: VOLTAGE }]);
    L.withModel = withModel;
  }
  return L.plots;
}

// the readout of the loop: the shown entry's sample nearest the cursor
function loopReadout(u) {
  const v = L.view;
  const left = u.cursor.left, top = u.cursor.top;
  if (!v || !v.loop || left === null || left < 0) { return; }
  const lp = v.loop;
  let best = -1, bestD = Infinity;
  for (let i = 0; i < lp.voltage.length; i++) {
    if (lp.voltage[i] === null || lp.strain[i] === null) { continue; }
    const dx = u.valToPos(lp.voltage[i], "x") - left, dy = u.valToPos(lp.strain[i], "y") - top;
    const d = dx * dx + dy * dy;
    if (d < bestD) { bestD = d; best = i; }
  }
  const at = `cursor ${num(u.posToVal(left, "x"), 4)} V, ${num(u.posToVal(top, "y"), 4)} ue`;
  if (best < 0) { text("readout", at); return; }
  const m = lp.model ? `, model ${num(lp.model[best], 5)} ue` : "";
  L.readout = { t: lp.t[best], voltage: lp.voltage[best], strain: lp.strain[best] };
  text("readout", `${v.name}: t ${num(lp.t[best], 6)} s, ${num(lp.voltage[best], 5)} V, ` +
    `${num(lp.strain[best], 5)} ue${m} (nearest sample; ${at})`);
}

function joined(loops, skip) {
  // the other entries' loops as one curve, a null between two entries
  const xs = [], ys = [];
  for (const e of loops) {
    if (e.name === skip) { continue; }
    if (xs.length) { xs.push(null); ys.push(null); }
    for (let i = 0; i < e.loop.voltage.length; i++) { xs.push(e.loop.voltage[i]); ys.push(e.loop.strain[i]); }
  }
  return [xs, ys];
}

function setData(key, data) {
  const u = L.plots[key];
  u.setData(data, !L.zoomed[key]);
}

// view: {name, live, loop: {t, voltage, strain, model?}, series: {t, strain, voltage, model?}}
function draw(view, doc) {
  const p = plots(!!doc.model);
  L.view = view;
  const loops = (L.loops && L.loops.entries) || [];
  const lp = view.loop, sr = view.series;
  setData("loop", [null, joined(loops, view.name), [lp.voltage, lp.strain], [lp.model ? lp.voltage : [], lp.model || []]]);
  const strain = [sr.t, sr.strain];
  if (L.withModel) { strain.push(sr.model || sr.t.map(() => null)); }
  setData("strain", strain);
  setData("voltage", [sr.t, sr.voltage]);
  const others = loops.filter((e) => e.name !== view.name).length;
  const what = view.live ? `${view.name} (current entry, as measured)` : `${view.name} (whole entry)`;
  text("loop-caption", what + (others ? `; ${others} other ${others === 1 ? "entry" : "entries"} in grey` : ""));
  text("series-caption", view.live ? `${view.name}, the last 5 s` : `${view.name}, the whole entry`);
  if (L.firstDataDraw === null) { L.firstDataDraw = Date.now(); }
  return p;
}

// -- the documents --------------------------------------------------------------------------

function renderStatus(doc) {
  const [cls, line] = statusLine(doc);
  const st = document.getElementById("status");
  st.className = "status " + cls;
  st.textContent = line;
  text("protocol", doc.protocol ? "- " + doc.protocol : "");
  const p = doc.progress;
  if (p) {
    const entry = p.entry ? `${p.entry} (${p.entry_status}, ${(100 * p.entry_fraction).toFixed(0)} %)` : "-";
    text("progress-text", `entries complete: ${p.complete} of ${p.planned}; current: ${entry}`);
    document.getElementById("progress-fill").style.width = (100 * p.fraction).toFixed(1) + "%";
    updateSelector(p.entries || [], doc);
  }
  const a = doc.amplifier;
  if (a) {
    let s = "amplifier: " + a.state;
    if (a.amplifier_voltage_V !== undefined && doc.status === "running") { s += `, monitor ${a.amplifier_voltage_V} V`; }
    if (a.command_voltage_V !== undefined && doc.status === "running") { s += `, command ${a.command_voltage_V} V`; }
    if (a.exit_code !== undefined) { s += `; exit code ${a.exit_code}`; }
    text("amplifier", s);
  }
  const refused = doc.refused ? `, ${doc.refused} requests refused (wrong Host, method or path)` : "";
  text("footer", `${doc.source} - update ${doc.seq}, file read in ${doc.read_ms} ms, ${doc.reads} reads, ${doc.skipped} skipped` +
    (doc.error ? ` (last skipped: ${doc.error})` : "") + refused + (doc.ended ? " - the run has ended" : ""));
}

function updateSelector(entries, doc) {
  const sel = document.getElementById("entry-select");
  const ended = (L.loops && L.loops.entries || []).map((e) => e.name);
  const want = entries.filter((e) => ended.includes(e.name));
  const have = Array.from(sel.options).slice(1).map((o) => o.value);
  sel.options[0].textContent = FINAL.includes(doc.status) ? "the last entry" : "the current entry (follow the run)";
  if (have.join("\n") === want.map((e) => e.name).join("\n")) { return; }
  for (const o of Array.from(sel.options).slice(1)) { o.remove(); }
  for (const e of want) {
    const o = document.createElement("option");
    o.value = e.name;
    o.textContent = `${e.name} (${e.status}, ${e.samples} samples)`;
    sel.appendChild(o);
  }
}

async function getJSON(url) {
  const r = await fetch(url, { cache: "no-store" });
  if (!r.ok) { throw new Error(`${url}: ${r.status} ${await r.text()}`); }
  return r.json();
}

let lastSeq = -1;
let lastView = "";
let pollMs = 80;

function wanted(doc) {
  // which entry to show: the one chosen, else the current one while the run goes on, else
  // (the run has ended) the last entry, whole
  const chosen = document.getElementById("entry-select").value;
  if (chosen) { return chosen; }
  if (FINAL.includes(doc.status) && L.loops && L.loops.entries.length) {
    return L.loops.entries[L.loops.entries.length - 1].name;
  }
  return null;  // live
}

async function update(doc) {
  const t0 = performance.now();
  if (L.loops === null || L.loops.seq !== doc.loops_seq) {
    L.loops = await getJSON("/loops");
  }
  renderStatus(doc);
  if (L.doc && doc.files !== L.doc.files) { L.entry = null; }  // another file at the path
  const name = wanted(doc);
  let view = null;
  if (name === null) {
    if (doc.entry) { view = { name: doc.entry.name, live: true, loop: doc.entry.loop, series: doc.entry.series }; }
  } else {
    const known = L.loops.entries.find((e) => e.name === name);
    if (!L.entry || L.entry.name !== name || (known && L.entry.samples !== known.samples)) {
      try {
        L.entry = await getJSON("/entry?name=" + encodeURIComponent(name));
      } catch (err) {
        err.entryAsk = true;  // the server is there: the entry is not readable now
        throw err;
      }
    }
    view = { name, live: false, loop: L.entry.loop, series: L.entry.series };
  }
  if (view) {
    draw(view, doc);
    document.getElementById("view-note").textContent = view.live ? "" :
      (FINAL.includes(doc.status) ? "the run has ended: every entry's loop, the last one (or the one chosen) in blue" : "an ended entry, chosen above");
  }
  L.draws += 1;
  L.drawTimes.push(Date.now());
  L.updateMs.push(performance.now() - t0);
  L.doc = doc;
}

async function poll() {
  const started = performance.now();
  let ended = false;
  try {
    const doc = await getJSON("/frame");
    pollMs = doc.poll_ms || pollMs;
    const view = document.getElementById("entry-select").value;
    if (doc.seq !== lastSeq || doc.ended !== (L.doc || {}).ended || view !== lastView || doc.loops_seq !== (L.loops || {}).seq) {
      lastSeq = doc.seq;
      lastView = view;
      await update(doc);
    }
    ended = !!doc.final;
    if (doc.closing) {  // the view is closing: keep this picture, ask no more
      text("footer", document.getElementById("footer").textContent + " - the live view has stopped");
      return;
    }
  } catch (err) {
    // the server stopped (the run ended): keep the last picture, say so, stop asking
    L.fetchErrors += 1;
    if (err.entryAsk) {
      lastSeq = null;  // an entry not read now (busy, damaged): asked for again next time
    } else if (L.doc && FINAL.includes(L.doc.status)) {
      text("footer", document.getElementById("footer").textContent + " - the live view has stopped");
      return;
    }
  }
  // ask every pollMs from the start of this ask (not pollMs after its answer and drawing)
  const wait = (ended ? ENDED_POLL_MS : pollMs) - (performance.now() - started);
  setTimeout(poll, Math.max(10, wait));
}

document.getElementById("entry-select").addEventListener("change", () => { L.zoomed = {}; });
poll();
