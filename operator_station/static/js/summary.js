// The run summary panel of the monitor: shown once a run has ended (live), and in a replay from the recording's
// end on (the slider before it hides it: the run had not ended there).  The station computes it from the
// run's records (operator_station/run_summary.py, the same timeline model as `report`); this only draws it.
"use strict";

const Summary = (() => {
  const $ = (id) => document.getElementById(id);
  const esc = (s) => String(s).replace(/[&<>"]/g, (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", "\"": "&quot;"})[c]);
  const sec = (s) => (s === null || s === undefined || !isFinite(s)) ? "–" : s < 60 ? `${s.toFixed(2)} s` : `${Math.floor(s / 60)} min ${(s % 60).toFixed(1)} s`;
  const pct = (a, b) => b > 0 ? `${(100 * a / b).toFixed(0)} %` : "–";

  // The summary to show at the cursor, or null.
  function current() {
    const snap = Store.snapshot;
    const s = snap && snap.summary;
    if (!s) return null;
    return Store.cursor === null || Store.cursor >= s.t_end - 1e-9 ? s : null;
  }

  function render() {
    const box = $("run-summary");
    if (!box) return;
    const s = current();
    box.hidden = !s;
    document.body.dataset.summary = s ? s.outcome : "";
    if (!s) { box.replaceChildren(); return; }
    const predicted = s.predicted === null ? `<span class="hint">no prediction (no dry run${Store.snapshot.mode === "replay" ? " in a recording" : ""})</span>`
      : `against <b>${sec(s.predicted)}</b> predicted (<b class="${Math.abs(s.deviation) < 0.01 ? "" : s.deviation > 0 ? "late" : "early"}">${s.deviation >= 0 ? "+" : ""}${sec(s.deviation)}</b>, ${s.deviation >= 0 ? "+" : ""}${pct(s.deviation, s.predicted)})`;
    const groups = s.groups.map((g) => `<tr data-group="${esc(g.group)}"><td>${esc(g.group)}</td><td>${sec(g.busy)}</td><td>${pct(g.busy, s.cycle_time)}</td>
      <td>${sec(g.idle)}</td><td>${g.waiting > 0 ? sec(g.waiting) : "–"}</td><td>${g.functions}${g.failed ? `, ${g.failed} failed` : ""}</td></tr>`).join("");
    const waits = s.waits.length ? `<h4>The waits that cost most</h4><ol class="summary-waits">${s.waits.map((w) =>
      `<li data-wait="${esc(w.what)}"><b>${sec(w.seconds)}</b> ${esc(w.group)} ${esc(w.label)}</li>`).join("")}</ol>` : "";
    const errors = s.errors.length ? `<h4>Errors (${s.errors.length})</h4>${s.errors.map((e) => `<div class="summary-error${e.recovered ? " recovered" : ""}" data-group="${esc(e.group)}">
      <div><b>${esc(e.group)}</b> at ${sec(e.t)}${e.operation ? `, operation ${esc(e.operation)}` : ""}${e.function ? ` (${esc(e.function)})` : ""}${e.recovered ? " — <i>recovered by a retry</i>" : ""}:
      <span class="summary-error-text">${esc(e.error)}</span></div>
      <ul class="summary-actions">${e.actions.map((a) => `<li>${esc(a)}</li>`).join("")}${e.faults_row ? `<li>see ${esc(e.faults_row)}</li>` : ""}</ul></div>`).join("")}`
      : `<p class="hint">no errors</p>`;
    box.innerHTML = `<h3>Run summary: <span class="summary-outcome outcome-${esc(s.outcome)}">${esc(s.outcome)}</span>
      <span class="hint">operations ${s.operations_done}/${s.operations_total}, ${s.retries} retr${s.retries === 1 ? "y" : "ies"}</span></h3>
      <p>cycle time <b class="summary-cycle">${sec(s.cycle_time)}</b>${s.held > 0 ? ` <span class="summary-held">(${sec(s.held)} of it paused or at an alarm)</span>` : ""} ${predicted}</p>
      <table class="summary-groups"><thead><tr><th>group</th><th>busy</th><th></th><th>idle</th><th>of it waiting</th><th>functions</th></tr></thead><tbody>${groups}</tbody></table>
      ${waits}${errors}`;
  }

  let frame = null;
  const soon = () => { if (frame === null) frame = requestAnimationFrame(() => { frame = null; render(); }); };
  Store.on("snapshot", soon);
  Store.on("state", soon);
  Store.on("cursor", soon);
  return {render, current};
})();
