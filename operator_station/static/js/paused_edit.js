// Editing the paused run (docs/studio.md, "Editing a paused run"): while the station's run is paused, the builder
// marks the operations that have run (✓) or are running (▶) and locks them (sync="flags": those some group has
// started, from each group's position in the engine's status); the others may change, and "Apply to the paused run"
// sends the builder's application to POST /api/edit.  The engine swaps the operations not started only if the done
// part is unchanged and the dry run of the new remainder from where the robot is finds nothing; its findings come
// back placed at their cells (Builder.showMessages), and nothing changes then.
"use strict";

const PausedEdit = (() => {
  const $ = (id) => document.getElementById(id);
  const ENDED = ["finished", "failed", "stopped"];
  const edit = {locked: new Map(), applying: false, answers: 0};

  const status = () => (Store.snapshot && Store.snapshot.mode === "live" && !Store.snapshot.ended && Store.snapshot.status) || null;
  const paused = () => { const s = status(); return s !== null && s.state === "paused"; };

  // sync="flags": each group's place in its own calls from the engine's status ("in:4", "before:5", "finished:8",
  // operations counted from 1); null in lock-step, where the engine's one operation count is every group's.
  function positions(s) {
    const out = {};
    for (const [group, g] of Object.entries(s.groups || {})) {
      const m = /^(in|before|finished):(\d+)$/.exec(g.position || "");
      if (m) out[group] = {kind: m[1], n: Number(m[2])};
    }
    return Object.keys(out).length ? out : null;
  }

  // sync="flags": an operation is started once some group has entered its own step there (or passed it): "running"
  // while a group is in it, else "done"; what no group has started stays open, as the engine's refusals count it.
  function lockedByGroups(ops, at) {
    const out = new Map();
    ops.forEach((op, i) => {
      let lock;
      for (const group of op.steps || Object.keys(op.calls || {})) {
        const p = at[group];
        if (p === undefined) continue;
        if (p.kind === "in" && p.n === i + 1) lock = "running";
        else if (i + 1 < p.n && lock === undefined) lock = "done";
      }
      if (lock !== undefined) out.set(op.id, lock);
    });
    return out;
  }

  // The operations started so far, by id: "done", or "running" for the last one when a group is still inside it.
  function lockedNow() {
    const s = status(), out = new Map();
    if (s === null || ENDED.includes(s.state)) return out;
    const ops = Store.snapshot.operations || [];
    const at = s.state === "idle" ? null : positions(s);  // idle: positions left from a run before, none of this one
    if (at !== null) return lockedByGroups(ops, at);
    const started = Math.min(s.operation_index || 0, ops.length);
    const inside = Object.values(s.groups || {}).some((g) => !["Ready", "Finish"].includes(g.state) && !String(g.state).startsWith("waiting"));
    for (let i = 0; i < started; i++) out.set(ops[i].id, i === started - 1 && inside ? "running" : "done");
    return out;
  }

  // Marks the drawn rows (the builder draws only the visible ones, again on every scroll and edit).
  function mark() {
    for (const row of document.querySelectorAll("#ops-rows .ops-row[data-op]")) {
      const input = row.querySelector("input.op-id");
      const lock = input ? edit.locked.get(input.value) : undefined;
      row.classList.toggle("op-locked", lock !== undefined);
      if (lock === undefined) {
        if (row.dataset.lock) for (const field of row.querySelectorAll("input, select, button")) field.disabled = false;
        delete row.dataset.lock;
        continue;
      }
      if (row.dataset.lock === lock) continue;
      row.dataset.lock = lock;
      row.title = lock === "running" ? "running: the paused run is inside this operation; it cannot change" : "done: this operation has run; it cannot change";
      for (const field of row.querySelectorAll("input, select, button")) field.disabled = true;
    }
  }

  function refresh() {
    edit.locked = lockedNow();
    const button = $("apply-edit-btn");
    if (button) {
      button.disabled = !paused() || edit.applying;
      button.title = paused() ? "swap the operations not started yet for the builder's, if the dry run from where the robot is passes"
        : "only a paused run can be edited: pause it first";
    }
    mark();
  }

  async function apply() {
    if (edit.applying) return;
    edit.applying = true;
    refresh();
    const summary = $("validation-summary");
    try {
      await Builder.validateNow();  // the field left for this button validates now, not over the edit's answer later
      Builder.state.validating++;  // a validation still under way must not overwrite the answer either
      summary.textContent = "checking the edit from where the robot is…";
      const answer = await Store.post("/api/edit", Builder.current());
      if (answer.messages) Builder.showMessages(answer.messages, answer.ok);
      summary.textContent = answer.answer || answer.error || "edit: no answer";
      summary.className = `summary ${answer.ok ? "ok" : "bad"}`;
      if (answer.ok && Store.snapshot) { Store.snapshot.operations = answer.operations; Store.emit("state", Store.snapshot); }
      document.body.dataset.editAnswer = answer.ok ? "swapped" : "refused";
    } finally {
      edit.applying = false;
      edit.answers += 1;
      document.body.dataset.editAnswers = String(edit.answers);
      refresh();
    }
  }

  document.addEventListener("DOMContentLoaded", () => {
    const save = $("save-btn");
    const button = document.createElement("button");
    button.id = "apply-edit-btn";
    button.dataset.needs = "engineer";
    button.textContent = "Apply to the paused run";
    button.disabled = true;
    button.addEventListener("click", apply);
    save.after(button);
    new MutationObserver(mark).observe($("ops-rows"), {childList: true});
    Store.on("state", refresh);
    Store.on("snapshot", refresh);
  });
  return {state: edit, refresh};
})();
