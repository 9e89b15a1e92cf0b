// The page's one source of truth: the server's feed (WebSocket) and the HTTP calls, and what the views derive from them.
// Views subscribe with Store.on(name, fn); "records" fires with the new records, "state" on any change of
// the run's state, "snapshot" when a new run (or replay) starts, "cursor" when the time slider moves.
"use strict";

const Store = (() => {
  const listeners = {};
  const store = {
    snapshot: null,          // the run's snapshot (groups, structures, operations, plan, status, ...)
    records: [],             // every record of the run, in order: the trace, line for line
    joints: {names: [], samples: []},
    cursor: null,            // null: live; a number: every view shows that run time
    catalog: null,
    connected: false,
  };

  store.on = (name, fn) => { (listeners[name] = listeners[name] || []).push(fn); };
  store.emit = (name, arg) => { for (const fn of listeners[name] || []) { try { fn(arg); } catch (e) { console.error(name, e); } } };

  // Every call is JSON and carries the page's session cookie (HttpOnly, SameSite=Strict: set by the station
  // when it served this page); the station refuses anything else, so a refusal says why in its "error".
  const refused = (url, status) => ({ok: false, error: status === 401 ? `${url}: no session: load the station's page again (with its token when it serves the network)` : `${url}: HTTP ${status}`});
  store.post = async (url, body) => {
    const response = await fetch(url, {method: "POST", credentials: "same-origin", headers: {"Content-Type": "application/json"}, body: JSON.stringify(body || {})});
    let data;
    try { data = await response.json(); } catch (e) { data = refused(url, response.status); }
    return data;
  };
  store.get = async (url) => (await fetch(url, {credentials: "same-origin"})).json();

  store.now = () => {
    if (store.cursor !== null) return store.cursor;
    const status = store.snapshot && store.snapshot.status;
    const last = store.records.length ? store.records[store.records.length - 1].t : 0;
    return Math.max(status ? status.t || 0 : 0, last);
  };

  // The records up to the cursor (all of them when live).
  store.visible = () => {
    if (store.cursor === null) return store.records;
    let hi = store.records.length;
    while (hi > 0 && store.records[hi - 1].t > store.cursor) hi--;
    return store.records.slice(0, hi);
  };

  // Each group's state, function and primitive at the cursor, derived from the records alone.
  store.groupView = () => {
    const out = {};
    for (const g of (store.snapshot && store.snapshot.groups) || []) out[g] = {state: "Ready", function: null, operation: null, iteration: null, primitive: null, error: null, last: null};
    for (const r of store.visible()) {
      const g = out[r.group];
      if (!g) continue;
      if (r.event === "transition") { g.state = r.to; g.last = {from: r.from, signal: r.signal, to: r.to, t: r.t}; }  // the last transition, drawn on the graph
      else if (r.event === "function_start") { g.function = r.function; g.operation = r.operation; g.iteration = r.iteration || null; g.primitive = null; g.error = null; }
      else if (r.event === "function_end") { g.function = null; g.primitive = null; }
      else if (r.event === "primitive_start") g.primitive = r.primitive;
      else if (r.event === "primitive_end") g.primitive = null;
      else if (r.event === "error") g.error = r.error;
    }
    return out;
  };

  // The engine's state at the cursor: the live status, or the last engine_state record before it.
  store.engineView = () => {
    const status = (store.snapshot && store.snapshot.status) || {};
    if (store.cursor === null && store.snapshot && store.snapshot.mode === "live") return status;
    let state = "idle", operation = null;
    const ops = (store.snapshot && store.snapshot.operations) || [];
    const seen = new Set();  // a replay knows no operation list: the operations met so far, in order
    for (const r of store.visible()) {
      if (r.event === "engine_state") state = r.to;
      if (r.operation && r.group !== "engine") { operation = r.operation; seen.add(r.operation); }
    }
    const index = ops.length ? ops.findIndex((o) => o.id === operation) + 1 : seen.size;
    return {state, operation_id: operation, operation_index: index, operation_count: ops.length || status.operation_count || 0, t: store.now()};
  };

  function connect() {
    const socket = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
    socket.onopen = () => { store.connected = true; };
    socket.onclose = () => { store.connected = false; setTimeout(connect, 1000); };  // the station busy (1013) or gone: try again
    socket.onmessage = (event) => {
      const message = JSON.parse(event.data);
      if (message.type === "snapshot") {
        store.snapshot = message.snapshot;
        store.records = [];
        store.joints = {names: message.snapshot.joint_names || [], samples: []};
        store.cursor = null;
        store.emit("snapshot", store.snapshot);
        store.emit("state", store.snapshot);
      } else if (message.type === "state") {
        Object.assign(store.snapshot, message.state);
        store.emit("state", store.snapshot);
      } else if (message.type === "records") {
        if (message.from !== store.records.length) {  // never silently: a gap means the page missed records
          console.error(`feed gap: expected record ${store.records.length}, got ${message.from}`);
        }
        for (const r of message.records) store.records.push(r);
        store.emit("records", message.records);
      } else if (message.type === "joints") {
        store.joints.names = message.names;
        for (const s of message.samples) store.joints.samples.push(s);
        store.emit("joints", message.samples);
      }
    };
  }

  store.setCursor = (t) => { store.cursor = t; store.emit("cursor", t); };
  store.start = async () => {
    store.catalog = await store.get("/api/catalog");
    store.emit("catalog", store.catalog);
    connect();
  };
  return store;
})();

// Tabs: one view at a time.
document.addEventListener("DOMContentLoaded", () => {
  for (const tab of document.querySelectorAll(".tab")) {
    tab.addEventListener("click", () => {
      for (const t of document.querySelectorAll(".tab")) t.classList.toggle("active", t === tab);
      for (const v of document.querySelectorAll(".view")) v.classList.toggle("active", v.id === `view-${tab.dataset.view}`);
      Store.emit("view", tab.dataset.view);
    });
  }
  Store.start();
});
