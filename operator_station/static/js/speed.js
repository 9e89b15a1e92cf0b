// The speed override in the control bar: a slider of 0..100 % of the application's own speed. Moving it
// (on release, or each arrow key) posts /api/speed; the engine scales every running motion on its path
// (0 %: a controlled stop that holds on the path and goes on when raised again) and records the change
// with source "studio" in the trace, so the page's log shows it as any command.  The value shown is the
// engine's (its status) while live, and in replay the last change recorded up to the slider's instant
// (the operator records of command speed_override), so it moves with the time slider.
"use strict";

const Speed = (() => {
  const $ = (id) => document.getElementById(id);
  const CHANGE = /^speed override ([0-9.]+) %/;
  let sending = false;

  // The override at the cursor: the live status, or the last accepted change among the visible records.
  function percentNow() {
    const snap = Store.snapshot;
    if (!snap) return 100;
    if (Store.cursor === null && snap.mode === "live" && snap.status && typeof snap.status.speed_override === "number") return snap.status.speed_override;
    let percent = 100;
    for (const r of Store.visible()) {
      if (r.event !== "operator" || r.command !== "speed_override" || !r.accepted) continue;
      const m = CHANGE.exec(r.answer || "");
      if (m) percent = Number(m[1]);
    }
    return percent;
  }
  function show() {
    const percent = percentNow();
    const slider = $("speed-override");
    if (!sending && document.activeElement !== slider) slider.value = String(percent);
    $("speed-value").textContent = `${percent} %`;
    $("speed-hold").hidden = percent !== 0;
    const snap = Store.snapshot;
    slider.disabled = !!(snap && snap.mode === "replay") || Store.cursor !== null;
  }
  async function set(percent) {
    sending = true;
    try {
      const reply = await Store.post("/api/speed", {percent: Number(percent)});
      const box = $("control-answer");
      box.textContent = reply.ok ? reply.answer : `speed: ${reply.error || reply.answer}`;
      box.className = reply.ok ? "ok" : "bad";
      if (typeof reply.percent === "number") $("speed-override").value = String(reply.percent);
      return reply;
    } finally {
      sending = false;
      show();
    }
  }
  document.addEventListener("DOMContentLoaded", () => {
    const slider = $("speed-override");
    slider.addEventListener("change", () => set(slider.value));
    slider.addEventListener("input", () => { $("speed-value").textContent = `${slider.value} %`; });
    show();
  });
  for (const name of ["state", "records", "snapshot", "cursor"]) Store.on(name, show);
  return {set, percentNow};
})();
