// Breakpoints of the run (docs/studio.md, "Breakpoints"): the run's operations, each with a toggle that sets or
// clears a breakpoint in the engine without touching the file (the builder's gutter changes the file's
// break="true"), "Run to here" (a breakpoint for once, then the run goes on), and Continue / Step / Clear all.
// Which operations hold a breakpoint, where the run is paused and why, and the run-to target are derived from
// the run's records at the store's cursor (the file's breakpoints, then every command the engine took and
// every pause), so the time slider of a replay shows them as they were.
"use strict";

const Breakpoints = (() => {
  const $ = (id) => document.getElementById(id);
  const WINDOW = 300;  // operations listed at most: around the current one, plus every one with a breakpoint
  let frame = null;

  // The breakpoints, the run-to target and the pause at the cursor, from the records alone.
  function derive() {
    const ops = (Store.snapshot && Store.snapshot.operations) || [];
    const set = new Set(ops.filter((o) => o.break).map((o) => o.id));
    let target = null, paused = null;
    for (const r of Store.visible()) {
      if (r.event === "operator" && r.accepted) {
        if (r.command === "break") set.add(r.target);
        else if (r.command === "unbreak") set.delete(r.target);
        else if (r.command === "unbreak_all") { set.clear(); target = null; }
        else if (r.command === "run_to") target = r.target;
      } else if (r.event === "breakpoint") {
        if (r.held) paused = {operation: r.operation, kind: r.kind, message: r.message, groups: r.groups || []};
        if (r.kind === "run_to") target = null;
      } else if (r.event === "engine_state" && r.to !== "paused") paused = null;
    }
    return {ops, set, target, paused};
  }

  function live() {
    const snap = Store.snapshot;
    return !!(snap && snap.mode === "live" && !snap.ended && Store.cursor === null);
  }

  function say(text, ok) {
    const box = $("bp-answer");
    if (box) { box.textContent = text; box.className = ok ? "ok" : "bad"; }
  }

  async function send(url, body, what) {
    const reply = await Store.post(url, body);
    say(`${what}: ${reply.ok ? reply.answer : (reply.answer || reply.error)}`, reply.ok);
    return reply;
  }
  const toggle = (id) => send("/api/breakpoint", {action: "toggle", operation: id}, "breakpoint");
  const runTo = (id) => send("/api/run_to", {operation: id}, "run to here");
  const clearAll = () => send("/api/breakpoint", {action: "clear_all", operation: ""}, "clear breakpoints");

  function button(cls, text, title, act, enabled) {
    const b = document.createElement("button");
    b.className = cls;
    b.textContent = text;
    b.title = title;
    b.disabled = !enabled;
    b.onclick = act;
    return b;
  }

  function render() {
    frame = null;
    const bar = $("bp-bar"), list = $("bp-list");
    if (!bar || !list) return;
    const {ops, set, target, paused} = derive();
    const engine = Store.engineView();
    const on = live();
    const state = engine.state || "idle";
    const where = document.createElement("span");
    where.className = "bp-where";
    where.textContent = paused ? paused.message : target ? `running to ${target}` : `${set.size} breakpoint(s)`;
    bar.replaceChildren(
      button("bp-continue", "Continue", "resume: the held groups go on", () => Control.command("resume"), on && state === "paused"),
      button("bp-step", "Step", "run the next operation, then pause again", () => Control.command("step"), on && ["paused", "running"].includes(state)),
      button("bp-clear", "Clear all", "clear every breakpoint of this run (the file is not changed)", clearAll, on && (set.size > 0 || !!target)),
      where, Object.assign(document.createElement("span"), {id: "bp-answer"}));
    const current = Math.max(0, (engine.operation_index || 1) - 1);
    const shown = ops.length <= WINDOW ? ops.map((o, i) => [o, i])
      : ops.map((o, i) => [o, i]).filter(([o, i]) => Math.abs(i - current) < WINDOW / 3 || set.has(o.id) || o.id === target);
    list.replaceChildren(...shown.map(([op, i]) => {
      const row = document.createElement("div");
      const here = paused && paused.operation === op.id;
      row.className = `bp-row${set.has(op.id) ? " on" : ""}${here ? " paused-here" : ""}${op.id === target ? " target" : ""}`;
      row.dataset.op = op.id;
      const mark = button("bp-toggle", set.has(op.id) ? "●" : "○", set.has(op.id) ? "clear this breakpoint (this run only)" : "pause before this operation (this run only)",
        () => toggle(op.id), on);
      const label = document.createElement("span");
      label.className = "bp-label";
      label.textContent = `${i + 1} ${op.id}${op.name ? ` – ${op.name}` : ""}${op.line ? ` (line ${op.line})` : ""}${here ? " · paused here" : ""}${op.id === target ? " · run-to target" : ""}`;
      row.append(mark, label, button("bp-run-to", "Run to here", "go on and pause before this operation", () => runTo(op.id), on && i >= current && !here));
      return row;
    }));
  }

  const soon = () => { if (frame === null) frame = requestAnimationFrame(render); };
  Store.on("snapshot", soon);
  Store.on("state", soon);
  Store.on("records", soon);
  Store.on("cursor", soon);
  return {render, derive, toggle, runTo, clearAll};
})();
