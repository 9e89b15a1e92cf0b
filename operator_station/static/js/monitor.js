// The live monitor: each group machine's state graph (from the structure it published, laid out by
// ELK through graph_layout.js, the active state and the last transition highlighted), its current function and primitive, the engine's status
// with an ETA in run and wall time, errors and alarms with the operator actions
// that resolve them, and the joint positions as plots (uPlot).  Everything is derived from the
// feed at the store's cursor, so the time slider puts this view back at any instant too.  The ETA is the
// station's (operator_station/eta.py), in run time and in wall time at the run's speed.
"use strict";

const Monitor = (() => {
  const $ = (id) => document.getElementById(id);
  const SVG = "http://www.w3.org/2000/svg";
  const svg = (tag, attrs) => { const n = document.createElementNS(SVG, tag); for (const [k, v] of Object.entries(attrs || {})) n.setAttribute(k, v); return n; };
  const graphs = {};   // group -> {svg, nodes: {state: rect}}
  const plots = {};    // group -> uPlot
  let frame = null;

  const fmt = (s) => (s === null || s === undefined || !isFinite(s)) ? "–" : s < 60 ? `${s.toFixed(1)} s` : `${Math.floor(s / 60)} min ${(s % 60).toFixed(0)} s`;

  // The graph is laid out by ELK (graph_layout.js: Ready at the centre of the working states, the exceptional
  // states in a band apart, the transitions every working state has into them bundled) and drawn 1:1, so its
  // labels keep their size (GraphLayout.FONT) whatever the card's width: a wide graph scrolls, it never shrinks.
  let elk = null;
  function drawGraph(group, structure, box) {
    const key = JSON.stringify(structure);
    graphs[group] = {structure: key, pending: true, nodes: {}, edges: {}};
    elk = elk || new ELK();
    GraphLayout.layout(structure, elk).then((geometry) => {
      if (!graphs[group] || graphs[group].structure !== key) return;  // a newer structure (or run) came meanwhile
      graphs[group] = {structure: key, ...paint(group, geometry, box), geometry};
      soon();
    }).catch((error) => { box.textContent = `the state graph could not be laid out: ${error}`; console.error(error); });
  }

  function paint(group, geometry, box) {
    const w = Math.ceil(geometry.width), h = Math.ceil(geometry.height);
    const root = svg("svg", {class: "state-graph", width: w, height: h, viewBox: `0 0 ${w} ${h}`, "data-group": group});
    const defs = svg("defs");
    for (const [id, cls] of [[`arrow-${group}`, "arrow"], [`arrow-last-${group}`, "arrow last"]]) {
      const marker = svg("marker", {id, markerWidth: 8, markerHeight: 8, refX: 7, refY: 3, orient: "auto-start-reverse", markerUnits: "userSpaceOnUse"});
      marker.append(svg("path", {d: "M0,0 L7,3 L0,6 z", class: cls}));
      defs.append(marker);
    }
    root.append(defs);
    for (const [id, c] of Object.entries(geometry.clusters)) {
      root.append(svg("rect", {x: c.x, y: c.y, width: c.width, height: c.height, rx: 8, class: `cluster cluster-${id}`}));
    }
    const edges = {};
    for (const e of geometry.edges) {
      const d = e.points.map((p, i) => `${i ? "L" : "M"}${p.x.toFixed(1)},${p.y.toFixed(1)}`).join(" ");
      const path = svg("path", {d, class: `edge edge-${e.kind}`, "data-edge": e.id, "marker-end": `url(#arrow-${group})`});
      if (e.kind === "spoke") path.setAttribute("marker-start", `url(#arrow-${group})`);  // request out, ok back
      const title = svg("title");
      title.textContent = e.title;
      path.append(title);
      root.append(path);
      let text = null;
      if (e.label) {
        text = svg("text", {x: e.label.x, y: e.label.y + GraphLayout.FONT * 0.35, class: "edge-label", "data-edge": e.id});
        text.textContent = e.label.text;
        root.append(text);
      }
      edges[e.id] = {path, text, edge: e};
    }
    // The last transition's trigger, placed on its edge when it is drawn (a spoke has no label of its own).
    const trigger = svg("text", {class: "edge-label trigger", "data-trigger": group});
    const nodes = {};
    for (const [name, n] of Object.entries(geometry.nodes)) {
      const rect = svg("rect", {x: n.x, y: n.y, width: n.width, height: n.height, rx: 5, class: `state state-${n.kind}`, "data-state": name});
      const text = svg("text", {x: n.x + n.width / 2, y: n.y + n.height / 2 + GraphLayout.FONT * 0.35, class: "state-label", "data-state": name});
      text.textContent = name;
      root.append(rect, text);
      nodes[name] = rect;
    }
    root.append(trigger);
    box.replaceChildren(root);
    return {svg: root, nodes, edges, trigger};
  }

  // The current state, and the last transition (at the cursor) as a coloured edge with its trigger, from ``view``.
  function highlight(graph, view) {
    for (const [name, rect] of Object.entries(graph.nodes)) {
      rect.classList.toggle("active", name === view.state);
      rect.classList.toggle("left", !!view.last && name === view.last.from && name !== view.state);
    }
    const last = view.last ? GraphLayout.edgeOf(graph.geometry, view.last.from, view.last.signal, view.last.to) : null;
    for (const [id, each] of Object.entries(graph.edges)) {
      const on = !!last && id === last.id;
      each.path.classList.toggle("last", on);
      each.path.setAttribute("marker-end", `url(#arrow-${on ? "last-" : ""}${graph.svg.dataset.group})`);
      if (each.edge.kind === "spoke") each.path.setAttribute("marker-start", `url(#arrow-${on ? "last-" : ""}${graph.svg.dataset.group})`);
      if (each.text) each.text.classList.toggle("last", on);
    }
    const trigger = graph.trigger;
    trigger.textContent = "";
    trigger.removeAttribute("data-edge");
    for (const each of Object.values(graph.edges)) if (each.text) each.text.toggleAttribute("data-trigger", !!last && each.edge.id === last.id);
    if (!last || graph.edges[last.id].text) return;  // an edge with a label of its own (its signal) shows it lit
    // A spoke has none: the trigger (the signal) beside the middle of the edge, on the side away from its run.
    trigger.textContent = view.last.signal;
    trigger.dataset.edge = last.id;
    const [a, b] = midSegment(last.points);
    const mx = (a.x + b.x) / 2, my = (a.y + b.y) / 2, vertical = Math.abs(b.y - a.y) > Math.abs(b.x - a.x);
    trigger.setAttribute("x", (mx + (vertical ? 6 : 0)).toFixed(1));
    trigger.setAttribute("y", (my + (vertical ? 4 : -5)).toFixed(1));
    trigger.setAttribute("text-anchor", vertical ? "start" : "middle");
    graph.svg.append(trigger);  // on top
  }
  const midSegment = (points) => { const i = Math.max(0, Math.floor((points.length - 1) / 2)); return [points[i], points[Math.min(points.length - 1, i + 1)]]; };

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
          <span>primitive <b class="g-primitive"></b></span><span class="g-last"></span></div><div class="graph-box"></div><div class="g-error"></div>`;
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
      card.querySelector(".g-last").textContent = view.last ? `last ${view.last.from} —${view.last.signal}→ ${view.last.to === GraphLayout.HISTORY ? "back" : view.last.to} at ${fmt(view.last.t)}` : "";
      card.querySelector(".g-error").textContent = view.error ? `error: ${view.error}` : "";
      card.dataset.state = view.state;
      const graph = graphs[group];
      if (graph && graph.geometry) highlight(graph, view);
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
    $("engine-eta").textContent = etaText(engine, now);
  }

  // ETA (operator_station/eta.py): the run seconds left by the dry run's plan and the wall seconds they take at the
  // run's speed -- both shown, since at --speed 10 they differ tenfold.  The station sends an estimate as each
  // operation starts; between two the wall seconds count down here (and the run seconds with them, at the speed),
  // held while the run is paused.  A replay shows what is left of the recording at the cursor.
  let etaSeen = null, etaAt = 0;
  function etaText(engine, now) {
    const snap = Store.snapshot;
    if (["finished", "failed", "stopped"].includes(engine.state)) return "–";
    if (snap.mode === "replay") {
      const end = Store.records.length ? Store.records[Store.records.length - 1].t : 0;
      return Store.cursor === null ? "–" : `${fmt(Math.max(0, end - now))} left in the recording`;
    }
    const eta = snap.eta;
    if (!eta) return "–";
    if (eta !== etaSeen) { etaSeen = eta; etaAt = performance.now(); }
    if (eta.speed === null) return `${fmt(eta.remaining)} run time (simulated: no wait)`;
    const going = !eta.held && engine.state === "running";
    const wall = Math.max(0, eta.wall - (going ? (performance.now() - etaAt) / 1000 : 0));
    return `${fmt(wall)} (${fmt(wall * eta.speed)} run time at x${eta.speed})${eta.held ? " held" : ""}`;
  }
  setInterval(() => { if (Store.snapshot && Store.snapshot.eta && Store.cursor === null) renderEngine(); }, 250);

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
    return cellJointGroups(robots, names);
  }
  // A cell of several robots: each joint name is a robot's own joint with the cell's prefix before it (kuka_A1,
  // viper_joint_1; none in a cell that renames nothing), so the joints fall to their robot (the model whose own joint
  // name ends the name the longest way, prefix what comes before it), and each robot's are plotted group by group.
  // A plot is named by the application's group: the prefix before the model's group name (kuka_arm), else, for a
  // group the cell names outright (<group as="inspector">), the application's groups no robot's prefix explains, in
  // the cell's order; joints of no known robot share one plot.
  function cellJointGroups(robots, names) {
    const buckets = new Map();  // prefix + model -> {prefix, model, joints: own joint -> index}
    const strangers = [];
    names.forEach((name, i) => {
      let best = null;
      for (const [model, robot] of Object.entries(robots)) {
        for (const own of robot.joint_order) {
          if (name.endsWith(own) && (!best || own.length > best.own.length)) best = {model, own, prefix: name.slice(0, name.length - own.length)};
        }
      }
      if (!best) { strangers.push(i); return; }
      const key = `${best.prefix}\u0000${best.model}`;
      if (!buckets.has(key)) buckets.set(key, {prefix: best.prefix, model: best.model, joints: {}});
      buckets.get(key).joints[best.own] = i;
    });
    const found = [];
    for (const b of buckets.values()) {
      for (const [g, info] of Object.entries(robots[b.model].groups)) {
        const indices = info.joints.map((j) => b.joints[j.name]).filter((i) => i !== undefined);
        if (indices.length) found.push({name: b.prefix + g, model: b.model, indices});
      }
    }
    const groups = (Store.snapshot && Store.snapshot.groups) || [];
    const spare = groups.filter((g) => !found.some((p) => p.name === g));
    const out = found.map((p) => [groups.includes(p.name) ? p.name : (spare.shift() || `${p.name} (${p.model})`), p.indices]);
    return strangers.length ? [...out, ["joints", strangers]] : out;
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
