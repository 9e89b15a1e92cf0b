// Who this page is, what its role lets it do, and the station's audit trail.
// GET /api/whoami gives the session's name and role: for an operator every control marked
// data-needs="engineer" (Save, Apply to the paused run, jog's reconnect) -- or inside an element so marked
// (the jog pad, the teach bar) -- is disabled with the reason as its title -- the station refuses those requests anyway (403, audited); this only says so beforehand.
// The Audit view polls GET /api/audit with the last entry it has (seq) and shows the newest first:
// who did what, when, in which role, and the digests of what an edit, teach or save replaced. It asks
// only while it is shown and the live feed is connected (a station gone is not asked every second).
"use strict";

const Audit = (() => {
  const $ = (id) => document.getElementById(id);
  const POLL_MS = 1000;     // how often the trail is asked for news (one small GET)
  const MAX_ROWS = 1000;    // rows kept in the table (the file keeps everything)
  const state = {who: null, last: 0, entries: []};

  const allows = (role) => !!state.who && (state.who.role === "engineer" || role === "operator");
  function reason(role) {
    const who = state.who || {};
    return `needs the ${role} role; this ${who.kind === "token" ? "token" : "session"} is ${who.role} '${who.name}'`;
  }
  // Disable what this role may not do (run again as controls appear: other views add theirs).
  function applyRole() {
    if (!state.who) return;
    for (const marked of document.querySelectorAll("[data-needs]")) {
      const needed = marked.dataset.needs;
      if (allows(needed)) continue;
      const controls = marked.matches("button, input, select, textarea") ? [marked] : marked.querySelectorAll("button, input, select, textarea");
      for (const element of controls) {
        element.disabled = true;
        element.title = reason(needed);
        element.classList.add("role-refused");
      }
    }
  }
  async function whoami() {
    try { state.who = await Store.get("/api/whoami"); } catch (e) { return; }
    const line = $("who-line");
    line.textContent = state.who.name ? `${state.who.name} · ${state.who.role}` : "";
    line.title = state.who.session ? `session ${state.who.session}` : state.who.kind;
    $("logout-btn").hidden = !state.who.users || state.who.kind !== "session";
    document.body.dataset.role = state.who.role || "";
    applyRole();
  }
  async function logout() {
    await Store.post("/api/logout", {});
    window.location.replace("/");
  }

  const short = (digest) => (digest ? digest.replace("sha256:", "").slice(0, 12) : "–");
  const KNOWN = new Set(["seq", "when", "who", "role", "kind", "session", "address", "what", "ok", "answer", "before", "after"]);
  function row(entry) {
    const tr = document.createElement("tr");
    tr.className = entry.ok ? "ok" : "bad";
    tr.dataset.seq = entry.seq;
    const shown = (v) => (typeof v === "string" ? (v.startsWith("sha256:") ? short(v) : v) : JSON.stringify(v));
    const details = Object.entries(entry).filter(([k]) => !KNOWN.has(k)).map(([k, v]) => `${k}=${shown(v)}`);
    const digests = entry.before !== undefined || entry.after !== undefined ? `${short(entry.before)} → ${short(entry.after)}` : "";
    const cells = [entry.when.replace("T", " ").replace("+00:00", "Z"), entry.who, entry.role, entry.what, entry.ok ? "ok" : "refused",
                   entry.answer || "", digests, details.join(" "), entry.session ? `${entry.session} ${entry.address}` : entry.address];
    for (const text of cells) {
      const td = document.createElement("td");
      td.textContent = text;
      tr.appendChild(td);
    }
    const digests_in = Object.entries(entry).filter(([k, v]) => typeof v === "string" && v.startsWith("sha256:")).map(([k, v]) => `${k} ${v}`);
    if (digests_in.length) tr.title = digests_in.join("\n");  // the whole digests, on hover
    return tr;
  }
  const shown = () => $("view-audit").classList.contains("active");
  let timer = null, busy = false;
  async function poll() {
    if (busy) return;  // a poll is under way (the view was opened meanwhile): it schedules the next
    clearTimeout(timer);
    if (!shown() || !Store.connected) {
      applyRole();
      timer = setTimeout(poll, POLL_MS);
      return;
    }
    busy = true;
    try {
      const answer = await Store.get(`/api/audit?after=${state.last}`);
      if (answer.ok && answer.entries.length) {
        const body = $("audit-rows");
        const fresh = document.createDocumentFragment();
        for (const entry of answer.entries) fresh.appendChild(row(entry));  // newest first, as the table
        body.insertBefore(fresh, body.firstChild);
        state.last = Math.max(state.last, ...answer.entries.map((e) => e.seq));
        state.entries = [...answer.entries, ...state.entries].slice(0, MAX_ROWS);
        while (body.children.length > MAX_ROWS) body.removeChild(body.lastChild);
      }
      if (answer.ok) {
        $("audit-file").textContent = answer.file ? `appended to ${answer.file}` : "kept in memory only (no --audit file)";
        $("audit-problem").textContent = answer.problem || "";
      }
      applyRole();
    } catch (e) {
      /* the station is gone or restarting: try again at the next tick */
    } finally {
      busy = false;
    }
    timer = setTimeout(poll, POLL_MS);
  }

  document.addEventListener("DOMContentLoaded", () => {
    $("logout-btn").addEventListener("click", logout);
    Store.on("view", (view) => { if (view === "audit") poll(); });
    whoami();
    poll();
  });
  // The reason this page may not do what needs `role` ("" when it may, or while its role is not known yet).
  const refuses = (role) => (state.who && !allows(role) ? reason(role) : "");
  return {state, allows, refuses, reason, applyRole};
})();
