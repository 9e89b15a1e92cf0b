// The live monitor: each group machine's state graph (from the structure it published, laid out by
// dagre, the active state highlighted), its current function and primitive, the engine's status
// with an ETA from the dry run's planned durations, errors and alarms with the operator actions
// that resolve them, and the joint positions as plots (uPlot).  Everything is derived from the
// feed at the store's cursor, so the time slider puts this view back at any instant too.
"use strict";

const Monitor = (() => {
  const $ = (id) => document.getElementById(id);
  const SVG = "http://www.w3.org/2000/svg";
  const svg = (tag, attrs) => { const n = document.createElementNS(SVG, tag); for (const [k, v] of Object.entries(attrs || {})) n.setAttribute(k, v); return n; };
  const graphs = {};   // group -> {svg, nodes: {state: rect}}
  const plots = {};    // group -> uPlot
  let frame = null;

  const fmt = (s) => (s === null || s === undefined || !isFinite(s)) ? "–" : s < 60 ? `${s.toFixed(1)} s` : `${Math.floor(s / 60)} min ${(s % 60).toFixed(0)} s`;

  function layout(structure) {
    const g = new dagre.graphlib.Graph({multigraph: true});
    g.setGraph({rankdir: "LR", nodesep: 10, ranksep: 70, marginx: 8, marginy: 8});
    g.setDefaultEdgeLabel(() => ({}));
    for (const s of structure.states) g.setNode(s, {label: s, width: Math.max(60, s.length * 7.5 + 16), height: 26});
    structure.transitions.forEach((t, i) => {
      const target = structure.states.includes(t.to) ? t.to : null;  // HISTORY: back to the paused state
      if (target) g.setEdge(t.from, target, {label: t.signal}, `${t.from}-${t.signal}-${i}`);
    });
    dagre.layout(g);
    return g;
  }

  function drawGraph(group, structure, box) {
    const g = layout(structure);
    const info = g.graph();
    const root = svg("svg", {class: "state-graph", viewBox: `0 0 ${info.width} ${info.height}`, preserveAspectRatio: "xMidYMin meet", "data-group": group});
    const defs = svg("defs");
    const marker = svg("marker", {id: `arrow-${group}`, markerWidth: 8, markerHeight: 8, refX: 7, refY: 3, orient: "auto"});
    marker.append(svg("path", {d: "M0,0 L7,3 L0,6 z", class: "arrow"}));
    defs.append(marker);
    root.append(defs);
    for (const e of g.edges()) {
      const edge = g.edge(e);
      const d = edge.points.map((p, i) => `${i ? "L" : "M"}${p.x.toFixed(1)},${p.y.toFixed(1)}`).join(" ");
      root.append(svg("path", {d, class: "edge", "marker-end": `url(#arrow-${group})`}));
    }
    const nodes = {};
    for (const name of g.nodes()) {
      const n = g.node(name);
      const rect = svg("rect", {x: n.x - n.width / 2, y: n.y - n.height / 2, width: n.width, height: n.height, rx: 5, class: "state", "data-state": name});
      const text = svg("text", {x: n.x, y: n.y + 4, class: "state-label"});
      text.textContent = name;
      root.append(rect, text);
      nodes[name] = rect;
    }
    box.replaceChildren(root);
    graphs[group] = {svg: root, nodes, structure: JSON.stringify(structure)};
  }

  function ensureGroups() {
    const snap = Store.snapshot;
    if (!snap) return;
    const box = $("groups");
    for (const group of snap.groups) {
      let card = box.querySelector(`.group-card[data-group="${group}"]`);
      if (!card) {
        card = document.createElement("div");
        card.className = "group-card";
        card.dataset.group = group;
        card.innerHTML = `<h3>${group}</h3><div class="group-now"><span>state <b class="g-state"></b></span>
          <span>operation <b class="g-op"></b> <span class="g-iteration"></span></span><span>function <b class="g-function"></b></span>
          <span>primitive <b class="g-primitive"></b></span></div><div class="graph-box"></div><div class="g-error"></div>`;
        box.append(card);
      }
      const structure = snap.structures && snap.structures[group];
      if (structure && (!graphs[group] || graphs[group].structure !== JSON.stringify(structure))) drawGraph(group, structure, card.querySelector(".graph-box"));
    }
    for (const card of box.querySelectorAll(".group-card")) if (!snap.groups.includes(card.dataset.group)) card.remove();
  }

  function render() {
    frame = null;
    ensureGroups();
    const views = Store.groupView();
    for (const [group, view] of Object.entries(views)) {
      const card = $("groups").querySelector(`.group-card[data-group="${group}"]`);
      if (!card) continue;
      card.querySelector(".g-state").textContent = view.state;
      card.querySelector(".g-op").textContent = view.operation || "–";
      const iteration = card.querySelector(".g-iteration");  // the loop iteration or call it was made for; where the call is written on hover
      iteration.textContent = view.iteration ? `(${view.iteration.replace(/ at \S+:\d+/g, "")})` : "";
      iteration.title = view.iteration || "";
      card.querySelector(".g-function").textContent = view.function || "–";
      card.querySelector(".g-primitive").textContent = view.primitive || "–";
      card.querySelector(".g-error").textContent = view.error ? `error: ${view.error}` : "";
      card.dataset.state = view.state;
      const graph = graphs[group];
      if (graph) for (const [name, rect] of Object.entries(graph.nodes)) rect.classList.toggle("active", name === view.state);
    }
    renderEngine();
    renderAlarms(views);
  }

  function renderEngine() {
    const snap = Store.snapshot;
    if (!snap) return;
    const engine = Store.engineView();
    const now = Store.now();
    $("engine-state").textContent = engine.state || "idle";
    document.body.dataset.engineState = engine.state || "idle";
    const made = ((engine.operation_id ? ((snap.operations || []).find((o) => o.id === engine.operation_id) || {}).iteration : "") || "").replace(/ at \S+:\d+/g, "");
    $("engine-op").textContent = engine.operation_count ? `${engine.operation_index}/${engine.operation_count}${engine.operation_id ? ` (id ${engine.operation_id}${made ? `, ${made}` : ""})` : ""}` : "–";
    $("engine-elapsed").textContent = fmt(now);
    // ETA: the planned (dry run) durations of the operations still to run, the current one counted from its start.
    const plan = snap.plan || [];
    if (plan.length && engine.operation_index) {
      const i = engine.operation_index - 1;
      const started = Store.visible().find((r) => r.event === "function_start" && r.operation === engine.operation_id);
      const inCurrent = started ? Math.max(0, (plan[i] || 0) - (now - started.t)) : plan[i] || 0;
      const rest = plan.slice(i + 1).reduce((a, x) => a + x, 0);
      $("engine-eta").textContent = ["finished", "failed", "stopped"].includes(engine.state) ? "–" : fmt(inCurrent + rest);
    } else $("engine-eta").textContent = "–";
  }

  // Each problem with the operator actions that resolve it.
  function renderAlarms(views) {
    const snap = Store.snapshot;
    const engine = Store.engineView();
    const items = [];
    const action = (label, command) => { const b = document.createElement("button"); b.textContent = label; b.onclick = () => Control.command(command); return b; };
    const safety = (snap.status && snap.status.message) || "";
    // A resumed run's interrupted function is redone by reset or left out by skip (docs/recording.md).
    const interrupted = /interrupted:/.test(safety);
    const answers = () => interrupted ? [action("Reset (redo)", "reset"), action("Skip", "skip")] : [action("Reset (retry)", "reset")];  // fresh buttons per item
    if (engine.state === "alarm") items.push([`ALARM: ${safety}`, [...answers(), action("Stop", "stop")]]);
    if (engine.state === "paused" && /safety stop/.test(safety)) items.push([`paused by the safety stop: ${safety}`, [Control.safetyButton(false), action("Resume", "resume")]]);
    else if (engine.state === "paused") items.push([`paused: ${safety}`, [action("Resume", "resume"), action("Step", "step"), action("Stop", "stop")]]);
    if (engine.state === "failed") items.push([`the run failed: ${safety}`, [Object.assign(document.createElement("button"), {textContent: "Open the builder", onclick: () => document.getElementById("tab-builder").click()})]]);
    for (const [group, view] of Object.entries(views)) if (view.error) items.push([`${group}: ${view.error}`, engine.state === "alarm" ? answers() : []]);
    for (const m of snap.messages || []) items.push([m.message, []]);
    const box = $("alarms");
    box.replaceChildren(...items.map(([text, actions]) => {
      const div = document.createElement("div");
      div.className = "alarm";
      div.append(document.createTextNode(text), ...actions);
      return div;
    }));
  }

  // ------------------------------------------------------------------------------ joint plots
  function jointGroups() {
    const robots = (Store.catalog && Store.catalog.robots) || {};
    const names = Store.joints.names;
    for (const robot of Object.values(robots)) {
      if (names.length && names.every((n) => robot.joint_order.includes(n))) {
        return Object.entries(robot.groups).map(([g, info]) => [g, info.joints.map((j) => names.indexOf(j.name)).filter((i) => i >= 0)]);
      }
    }
    return names.length ? [["joints", names.map((_, i) => i)]] : [];
  }
  const COLOURS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f"];
  function renderPlots() {
    const box = $("joint-plots");
    const samples = Store.cursor === null ? Store.joints.samples : Store.joints.samples.filter((s) => s[0] <= Store.cursor);
    for (const [group, indices] of jointGroups()) {
      if (!indices.length) continue;
      const data = [samples.map((s) => s[0]), ...indices.map((i) => samples.map((s) => s[i + 1]))];
      if (!plots[group]) {
        const holder = document.createElement("div");
        holder.className = "joint-plot";
        holder.dataset.group = group;
        box.append(holder);
        plots[group] = new uPlot({title: `${group} (rad)`, width: 420, height: 200, scales: {x: {time: false}},
          series: [{label: "t (s)"}, ...indices.map((i, k) => ({label: Store.joints.names[i], stroke: COLOURS[k % COLOURS.length]}))]}, data, holder);
      } else plots[group].setData(data);
    }
  }
  function resetPlots() { for (const p of Object.values(plots)) p.destroy(); for (const k of Object.keys(plots)) delete plots[k]; $("joint-plots").replaceChildren(); }

  const soon = () => { if (frame === null) frame = requestAnimationFrame(render); };
  let plotTimer = null;
  const plotSoon = () => { if (plotTimer === null) plotTimer = setTimeout(() => { plotTimer = null; renderPlots(); }, 250); };
  Store.on("snapshot", () => { for (const k of Object.keys(graphs)) delete graphs[k]; $("groups").replaceChildren(); resetPlots(); soon(); });
  Store.on("state", soon);
  Store.on("records", soon);
  Store.on("cursor", () => { soon(); renderPlots(); });
  Store.on("joints", plotSoon);
  return {render};
})();
