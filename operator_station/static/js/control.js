// Operator control: start (validate the builder's application, then run it), pause, resume, step,
// stop and reset go to the engine's own operator commands (recorded in the trace with source
// "studio"); the safety stop raises the cell's safety input, which the engine obeys and records.
// Clearing the safety stop is never a toggle: a dialog asks first, then /api/safety/clear with
// {confirm: true}; the station logs who cleared it and when, and the robot moves again on Resume.
"use strict";

const Control = (() => {
  const $ = (id) => document.getElementById(id);
  let safetyActive = false;

  function answer(text, ok) {
    const box = $("control-answer");
    box.textContent = text;
    box.className = ok ? "ok" : "bad";
  }
  async function command(name) {
    const reply = await Store.post(`/api/operator/${name}`);
    answer(reply.ok ? `${name}: ${reply.answer}` : `${name}: ${reply.answer || reply.error}`, reply.ok);
    return reply;
  }
  async function start() {
    const state = Store.snapshot && Store.snapshot.status && Store.snapshot.status.state;
    if (Store.snapshot && Store.snapshot.mode === "live" && !Store.snapshot.ended && state === "idle") return command("start");
    const reply = await Store.post("/api/run", Builder.current());
    if (reply.messages) Builder.showMessages(reply.messages, reply.ok || !reply.error);
    answer(reply.ok ? "start: the dry run checks the application, then it runs" : `start: ${reply.error || reply.answer}`, reply.ok);
    if (reply.ok) document.getElementById("tab-monitor").click();
    return reply;
  }
  function showSafety(active) {
    safetyActive = active;
    $("safety-stop").classList.toggle("active", safetyActive);
    $("safety-stop").textContent = safetyActive ? "SAFETY STOP ACTIVE (click to clear)" : "SAFETY STOP";
  }
  async function safety(active) {
    if (!active) return clearSafety();
    const reply = await Store.post("/api/safety", {active: true});
    if (reply.ok) showSafety(true);
    answer(reply.answer || reply.error, reply.ok);
    return reply;
  }
  // The confirmation dialog; the clear is sent only on its confirm button.
  function clearSafety() {
    const dialog = $("safety-dialog");
    return new Promise((resolve) => {
      dialog.addEventListener("close", async () => {
        if (dialog.returnValue !== "confirm") {
          answer("safety stop: not cleared", false);
          resolve(null);
          return;
        }
        const reply = await Store.post("/api/safety/clear", {confirm: true});
        if (reply.ok) showSafety(false);
        answer(reply.ok ? `${reply.answer} (logged: ${reply.who}, ${reply.when})` : (reply.error || reply.answer), reply.ok);
        resolve(reply);
      }, {once: true});
      dialog.returnValue = "";
      dialog.showModal();
    });
  }
  function safetyButton(active) {
    const button = document.createElement("button");
    button.textContent = active ? "Raise the safety stop" : "Clear the safety stop";
    button.onclick = () => safety(active);
    return button;
  }
  function updateButtons() {
    const snap = Store.snapshot;
    const replay = snap && snap.mode === "replay";
    const state = (snap && snap.status && snap.status.state) || "idle";
    const live = snap && snap.mode === "live" && !snap.ended;
    const enable = (id, on) => { $(id).disabled = !on; };
    enable("ctl-start", !replay && !(live && state !== "idle"));
    enable("ctl-pause", live && ["running", "stepping"].includes(state));
    enable("ctl-resume", live && state === "paused");
    enable("ctl-step", live && ["running", "paused"].includes(state));
    enable("ctl-stop", live && !["finished", "failed", "stopped"].includes(state));
    enable("ctl-reset", live && state === "alarm");
    enable("safety-stop", live);
    document.body.classList.toggle("replay", !!replay);
  }

  document.addEventListener("DOMContentLoaded", () => {
    $("ctl-start").addEventListener("click", start);
    for (const name of ["pause", "resume", "step", "stop", "reset"]) $(`ctl-${name}`).addEventListener("click", () => command(name));
    $("safety-stop").addEventListener("click", () => safety(!safetyActive));
    updateButtons();
  });
  Store.on("state", updateButtons);
  Store.on("snapshot", () => showSafety(false));
  return {command, start, safety, clearSafety, safetyButton};
})();
