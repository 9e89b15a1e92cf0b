// The dual-arm timeline (paper Figure 12): one lane per group, a bar per function coloured by the
// state it ran in (its primitives inside it when zoomed in), operation boundaries, idle time as
// the lane's background.  The model is the server's (/api/timeline, computed from the records by
// the project's timeline module); this file only draws it.  The slider moves the store's cursor:
// every view goes back to that instant.
"use strict";

const Timeline = (() => {
  const $ = (id) => document.getElementById(id);
  const SVG = "http://www.w3.org/2000/svg";
  const svg = (tag, attrs, text) => { const n = document.createElementNS(SVG, tag); for (const [k, v] of Object.entries(attrs || {})) n.setAttribute(k, v); if (text !== undefined) n.textContent = text; return n; };
  const LANE = 46, LEFT = 110, TOP = 26, PRIMITIVES_FROM = 25;  // px per second from which primitives are drawn
  let model = null, zoomFactor = 1, scale = 1, pending = false, timer = null;

  async function refresh() {
    pending = false;
    const until = Store.cursor === null ? "" : `?until=${Store.cursor}`;
    model = await Store.get(`/api/timeline${until}`);
    draw();
  }
  function refreshSoon(delay) {
    if (pending) return;
    pending = true;
    clearTimeout(timer);
    timer = setTimeout(refresh, delay);
  }

  function draw() {
    if (!model) return;
    const box = $("timeline");
    const width = Math.max(box.clientWidth || window.innerWidth - 40, 400);
    const end = Math.max(model.end || 0, 1e-3);
    scale = (width - LEFT - 20) / end * zoomFactor;  // zoom is relative to the whole run fitting the width
    const px = (t) => LEFT + t * scale;
    const height = TOP + model.groups.length * LANE + 20;
    const root = svg("svg", {id: "timeline-svg", width: Math.max(width, px(end) + 20), height, "data-end": end});
    // Operation boundaries first, under the bars.
    const iterations = Object.fromEntries(model.operations.map((op) => [op.id, op.iteration]));
    for (const op of model.operations) {
      root.append(svg("line", {x1: px(op.start), x2: px(op.start), y1: 12, y2: height - 10, class: "op-boundary", "data-operation": op.id}));
      const label = svg("text", {x: px(op.start) + 2, y: 20, class: "op-label", "data-iteration": op.iteration || ""}, op.id);
      if (op.iteration) label.append(svg("title", {}, `${op.id}: ${op.iteration}`));  // the loop iteration or call it was made for
      root.append(label);
    }
    model.groups.forEach((group, lane) => {
      const y = TOP + lane * LANE;
      root.append(svg("rect", {x: LEFT, y: y + 4, width: Math.max(0, px(end) - LEFT), height: LANE - 8, class: "lane-idle"}));
      root.append(svg("text", {x: 4, y: y + LANE / 2 + 4, class: "lane-label"}, group));
      const idle = model.idle && model.idle[group];
      if (idle !== undefined) root.append(svg("text", {x: 4, y: y + LANE / 2 + 16, class: "lane-idle-label"}, `idle ${idle.toFixed(1)} s`));
      for (const bar of model.lanes[group] || []) {
        const x = px(bar.start), w = Math.max(1, (bar.end - bar.start) * scale);
        const g = svg("g", {class: `bar state-${bar.state}${bar.outcome && bar.outcome !== "succeeded" ? " failed" : ""}${bar.open ? " open" : ""}`,
          "data-group": group, "data-operation": bar.operation, "data-function": bar.function, "data-iteration": iterations[bar.operation] || ""});
        g.append(svg("title", {}, `${group} · operation ${bar.operation}${iterations[bar.operation] ? ` (${iterations[bar.operation]})` : ""} · ${bar.function} (${bar.state})\n${bar.start.toFixed(3)} – ${bar.end.toFixed(3)} s${bar.outcome ? ` · ${bar.outcome}` : ""}`));
        g.append(svg("rect", {x, y: y + 6, width: w, height: LANE - 12, rx: 3, style: `fill:${bar.colour};stroke:${bar.edge}`}));
        if (scale >= PRIMITIVES_FROM) {
          for (const p of bar.primitives || []) {
            const pr = svg("rect", {x: px(p.start), y: y + LANE / 2, width: Math.max(1, (p.end - p.start) * scale), height: LANE / 2 - 8, class: `primitive state-${p.state}`, style: `fill:${p.colour}`});
            pr.append(svg("title", {}, `${p.primitive} ${p.start.toFixed(3)} – ${p.end.toFixed(3)} s`));
            g.append(pr);
          }
        }
        if (w > 40) g.append(svg("text", {x: x + 3, y: y + 20, class: "bar-label"}, bar.function));
        root.append(g);
      }
    });
    const cursor = Store.cursor === null ? model.end : Store.cursor;
    root.append(svg("line", {x1: px(cursor), x2: px(cursor), y1: 8, y2: height - 6, class: "cursor"}));
    box.replaceChildren(root);
    const slider = $("tl-slider");
    slider.max = String(Math.max(model.total_end || end, end));
    slider.value = Store.cursor === null ? slider.max : String(Store.cursor);
    $("tl-cursor").textContent = Store.cursor === null ? `live (${end.toFixed(2)} s)` : `${Store.cursor.toFixed(2)} s`;
    $("tl-legend").replaceChildren(`${model.bars} function bar(s), ${model.records} record(s) `,
      ...Object.entries(model.colours).map(([state, colour]) => Object.assign(document.createElement("span"), {className: "swatch", textContent: state, style: `background:${colour}`})));
    document.body.dataset.timelineRecords = String(model.records);
  }

  function zoom(factor) { zoomFactor *= factor; draw(); }
  document.addEventListener("DOMContentLoaded", () => {
    $("tl-zoom-in").addEventListener("click", () => zoom(2));
    $("tl-zoom-out").addEventListener("click", () => zoom(0.5));
    $("tl-fit").addEventListener("click", () => { zoomFactor = 1; draw(); });
    $("tl-slider").addEventListener("input", () => Store.setCursor(parseFloat($("tl-slider").value)));
    $("tl-live").addEventListener("click", () => Store.setCursor(null));
  });
  Store.on("snapshot", () => { zoomFactor = 1; refreshSoon(0); });
  const shown = () => document.getElementById("view-timeline").classList.contains("active");
  Store.on("records", () => { if (shown()) refreshSoon(300); });  // the model is asked for only while it is looked at
  Store.on("cursor", () => refreshSoon(0));
  Store.on("view", (view) => { if (view === "timeline") refreshSoon(0); });
  return {refresh, zoom, model: () => model};
})();
