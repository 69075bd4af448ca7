// The live view: ask the server for the run's state, redraw when it changed.
"use strict";

const MEASURED = "#1f77b4";
const MODEL = "#ff7f0e";
const VOLTAGE = "#2ca02c";

// what a test (or a curious person) can read: draws, their times, the last document
window.labrigLive = { draws: 0, drawTimes: [], firstDataDraw: null, doc: null, fetchErrors: 0 };

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

function render(doc) {
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
  }
  const a = doc.amplifier;
  if (a) {
    let s = "amplifier: " + a.state;
    if (a.amplifier_voltage_V !== undefined && doc.status === "running") { s += `, monitor ${a.amplifier_voltage_V} V`; }
    if (a.command_voltage_V !== undefined && doc.status === "running") { s += `, command ${a.command_voltage_V} V`; }
    if (a.exit_code !== undefined) { s += `; exit code ${a.exit_code}`; }
    text("amplifier", s);
  }
  const e = doc.entry;
  if (e) {
    const loop = [{ x: e.loop.voltage, y: e.loop.strain, color: MEASURED }];
    const strain = [{ x: e.series.t, y: e.series.strain, color: MEASURED }];
    if (e.loop.model) { loop.push({ x: e.loop.voltage, y: e.loop.model, color: MODEL, dash: [6, 4] }); }
    if (e.series.model) { strain.push({ x: e.series.t, y: e.series.model, color: MODEL, dash: [6, 4] }); }
    LabrigPlot.draw(document.getElementById("loop"), loop, { x: "command voltage (V)", y: "strain (ue)" });
    LabrigPlot.draw(document.getElementById("strain"), strain, { x: "time (s)", y: "strain (ue)" });
    LabrigPlot.draw(document.getElementById("voltage"), [{ x: e.series.t, y: e.series.voltage, color: VOLTAGE }], { x: "time (s)", y: "voltage (V)" });
    if (window.labrigLive.firstDataDraw === null) { window.labrigLive.firstDataDraw = Date.now(); }
  }
  text("footer", `${doc.source} - update ${doc.seq}, file read in ${doc.read_ms} ms, ${doc.reads} reads, ${doc.skipped} skipped` +
    (doc.error ? ` (last skipped: ${doc.error})` : "") + (doc.ended ? " - the run has ended" : ""));
  window.labrigLive.draws += 1;
  window.labrigLive.drawTimes.push(Date.now());
  window.labrigLive.doc = doc;
}

let lastSeq = -1;
let pollMs = 80;

async function poll() {
  try {
    const r = await fetch("/frame", { cache: "no-store" });
    const doc = await r.json();
    pollMs = doc.poll_ms || pollMs;
    if (doc.seq !== lastSeq || doc.ended !== (window.labrigLive.doc || {}).ended) { lastSeq = doc.seq; render(doc); }
    if (doc.ended && ["complete", "aborted", "failed"].includes(doc.status)) {
      text("footer", document.getElementById("footer").textContent + "; the live view has stopped");
      return;  // the run has ended and the server is about to stop: ask no more
    }
  } catch (err) {
    // the server stopped (the run ended): keep the last picture, say so, stop asking
    window.labrigLive.fetchErrors += 1;
    if (window.labrigLive.doc && window.labrigLive.doc.ended) {
      text("footer", document.getElementById("footer").textContent + " - the live view has stopped");
      return;
    }
  }
  setTimeout(poll, pollMs);
}

poll();
