// The dual-arm timeline (paper Figure 12): one lane per group on a run-time axis, a bar per function
// coloured by the state it ran in (its primitives inside it when zoomed in), operation boundaries,
// flag and zone waits drawn as named idle time, the critical path outlined, the dry run's planned
// duration as a thin bar under each function, errors as marks at their time, retries badged.  The
// model is the server's (/api/timeline, computed from the records by the project's timeline module,
// critical path included); this file only draws it.  Zoom with the wheel or the buttons, pan by
// dragging, "fit" resets.  The slider moves the store's cursor: every view goes back to that
// instant; the timeline then holds only what had happened by then, on the whole run's axis.
"use strict";

const Timeline = (() => {
  const $ = (id) => document.getElementById(id);
  const SVG = "http://www.w3.org/2000/svg";
  const svg = (tag, attrs, text) => { const n = document.createElementNS(SVG, tag); for (const [k, v] of Object.entries(attrs || {})) n.setAttribute(k, v); if (text !== undefined) n.textContent = text; return n; };
  const LANE = 52, LEFT = 118, RIGHT = 18, AXIS = 44, PRIMITIVES_FROM = 25;  // px per second from which primitives are drawn
  const TICK_PX = 90, MIN_SPAN = 0.005;  // px between axis ticks at least; the narrowest window (s)
  // Axis steps: 1-2-5 below a second, then steps a clock reads (15 s, 30 s, 1 min, 5 min, ...).
  const STEPS = [0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600, 7200, 10800, 21600, 43200, 86400];
  let model = null, view = null, pending = false, timer = null, drag = null, frame = 0;

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

  // The run's whole time range (a replay's recording to its end, whatever the slider), and the window shown.
  const domain = () => [0, Math.max(model.total_end || 0, model.end || 0, 1e-3)];
  const shownRange = () => view || domain();
  function clampView(t0, t1) {
    const [d0, d1] = domain();
    let span = Math.max(MIN_SPAN, t1 - t0);
    if (span >= d1 - d0) return null;  // all of it: fit
    if (t0 < d0) t0 = d0;
    if (t0 + span > d1) t0 = d1 - span;
    return [t0, t0 + span];
  }

  function step(span, width) {
    const raw = span * TICK_PX / Math.max(width, 1);
    return STEPS.find((s) => s >= raw) || Math.pow(10, Math.ceil(Math.log10(raw)));
  }
  // "12.5 s" while the window stays under a minute, "1:05" / "1:05.5" / "1:02:05" past it.
  function label(t, s, clock) {
    const decimals = s >= 1 ? 0 : Math.ceil(-Math.log10(s) - 1e-9);
    if (!clock) return `${t.toFixed(decimals)} s`;
    const h = Math.floor(t / 3600), m = Math.floor((t - h * 3600) / 60), sec = t - h * 3600 - m * 60;
    const secs = sec.toFixed(decimals).padStart(decimals ? decimals + 3 : 2, "0");
    return h ? `${h}:${String(m).padStart(2, "0")}:${secs}` : `${m}:${secs}`;
  }
  const seconds = (d) => `${d.toFixed(d < 10 ? 2 : 1)} s`;

  function draw() {
    if (!model) return;
    const box = $("timeline");
    const width = Math.max(box.clientWidth || window.innerWidth - 40, 400);
    const plot = width - LEFT - RIGHT;
    const [t0, t1] = shownRange();
    const scale = plot / (t1 - t0);
    const px = (t) => LEFT + (t - t0) * scale;
    const visible = (a, b) => b >= t0 && a <= t1;
    // A label kept inside its bar (the part of it in the window): a nested svg clips what would run over the next one.
    const inside = (x, y, w, h, className, text) => {
      const left = Math.max(x, LEFT), right = Math.min(x + w, LEFT + plot);
      const box = svg("svg", {x: left, y, width: Math.max(0, right - left), height: h});
      box.append(svg("text", {x: 3, y: h - 5, class: className}, text));
      return box;
    };
    const height = AXIS + model.groups.length * LANE + 12;
    const root = svg("svg", {id: "timeline-svg", width, height, "data-t0": t0, "data-t1": t1, "data-end": model.end});
    const defs = svg("defs");
    const clip = svg("clipPath", {id: "tl-clip"});
    clip.append(svg("rect", {x: LEFT, y: 0, width: plot, height}));
    defs.append(clip);
    root.append(defs);
    const area = svg("g", {"clip-path": "url(#tl-clip)"});

    // The axis: ticks at a step the eye reads, their labels, a light grid under everything.
    const s = step(t1 - t0, plot), clock = t1 >= 60;
    const axis = svg("g", {id: "tl-axis", "data-step": s});
    axis.append(svg("line", {x1: LEFT, x2: LEFT + plot, y1: AXIS - 4, y2: AXIS - 4, class: "axis-line"}));
    for (let k = Math.ceil(t0 / s - 1e-9); k * s <= t1 + 1e-9; k++) {
      const t = Math.round(k * s * 1e6) / 1e6, x = px(t);
      area.append(svg("line", {x1: x, x2: x, y1: AXIS - 4, y2: height - 8, class: "grid"}));
      axis.append(svg("line", {x1: x, x2: x, y1: AXIS - 9, y2: AXIS - 4, class: "axis-tick"}));
      axis.append(svg("text", {x, y: AXIS - 12, class: "tick-label", "data-t": t, "text-anchor": "middle"}, label(t, s, clock)));
    }
    axis.append(svg("text", {x: 4, y: AXIS - 12, class: "axis-name"}, clock ? "run time (min:s)" : "run time (s)"));

    // Operation boundaries, under the bars.
    const iterations = Object.fromEntries(model.operations.map((op) => [op.id, op.iteration]));
    let free = -Infinity;  // where the next operation label has room (labels never overlap; every boundary is drawn)
    for (const op of model.operations) {
      if (!visible(op.start, op.start)) continue;
      area.append(svg("line", {x1: px(op.start), x2: px(op.start), y1: 4, y2: height - 8, class: "op-boundary", "data-operation": op.id}));
      if (px(op.start) < free) continue;
      const text = svg("text", {x: px(op.start) + 2, y: 12, class: "op-label", "data-iteration": op.iteration || ""}, op.id);
      if (op.iteration) text.append(svg("title", {}, `${op.id}: ${op.iteration}`));  // the loop iteration or call it was made for
      area.append(text);
      free = px(op.start) + 8 + 7 * op.id.length;
    }
    const critical = new Map((model.critical || []).map((step) => [step.id, step]));
    const planOf = new Map((model.plan || []).map((p) => [`${p.group}\u0000${p.operation}`, p]));
    const laneY = new Map(model.groups.map((group, lane) => [group, AXIS + lane * LANE]));
    const cursor = Store.cursor === null ? model.end : Store.cursor;
    model.groups.forEach((group) => {
      const y = laneY.get(group);
      area.append(svg("rect", {x: Math.max(LEFT, px(0)), y: y + 4, width: Math.max(0, Math.min(px(cursor), LEFT + plot) - Math.max(LEFT, px(0))), height: LANE - 10, class: "lane-idle"}));
      root.append(svg("text", {x: 4, y: y + LANE / 2 - 2, class: "lane-label"}, group));
      const idle = model.idle && model.idle[group];
      if (idle !== undefined) root.append(svg("text", {x: 4, y: y + LANE / 2 + 11, class: "lane-idle-label"}, `idle ${idle.toFixed(1)} s`));
      for (const bar of model.lanes[group] || []) {
        if (!visible(bar.start, bar.end)) continue;
        const x = px(bar.start), w = Math.max(1, (bar.end - bar.start) * scale);
        const path = critical.get(bar.id), plan = planOf.get(`${group}\u0000${bar.operation}`);
        const classes = ["bar", `state-${bar.state}`, bar.outcome && bar.outcome !== "succeeded" ? "failed" : "", bar.open ? "open" : "", path ? "critical" : "", bar.attempt > 1 ? "retry" : ""];
        const g = svg("g", {class: classes.filter(Boolean).join(" "), "data-span": bar.id, "data-group": group, "data-operation": bar.operation,
          "data-function": bar.function, "data-iteration": iterations[bar.operation] || "", "data-attempt": bar.attempt});
        const lines = [`${group} · operation ${bar.operation}${iterations[bar.operation] ? ` (${iterations[bar.operation]})` : ""} · ${bar.function} (${bar.state})`,
          `${bar.start.toFixed(3)} – ${bar.end.toFixed(3)} s: ${seconds(bar.end - bar.start)}${bar.outcome ? ` · ${bar.outcome}` : " · running"}`];
        if (bar.planned !== null && bar.planned !== undefined) lines.push(`planned ${seconds(bar.planned)} (dry run), actual ${seconds(bar.end - bar.start)}${plan && plan.attempts > 1 ? `; with its ${plan.attempts} attempts ${seconds(plan.actual)}` : ""} (${plan && plan.delta >= 0 ? "+" : ""}${plan ? plan.delta.toFixed(2) : "?"} s)`);
        if (bar.attempt > 1) lines.push(`attempt ${bar.attempt} (retried)`);
        if (bar.error) lines.push(`error: ${bar.error}`);
        if (path) lines.push(`on the critical path${path.via && path.via !== "then" ? ` (the next step waited on it: ${path.via})` : ""}`);
        g.append(svg("title", {}, lines.join("\n")));
        g.append(svg("rect", {x, y: y + 6, width: w, height: LANE - 22, rx: 3, style: `fill:${bar.colour};stroke:${bar.edge}`}));
        if (path) g.append(svg("rect", {x: x - 1, y: y + 4, width: w + 2, height: LANE - 18, rx: 4, class: "critical-outline"}));
        if (scale >= PRIMITIVES_FROM) {
          for (const p of bar.primitives || []) {
            const pr = svg("rect", {x: px(p.start), y: y + LANE / 2 - 4, width: Math.max(1, (p.end - p.start) * scale), height: LANE / 2 - 14, class: `primitive state-${p.state}`, style: `fill:${p.colour}`});
            pr.append(svg("title", {}, `${p.primitive} ${p.start.toFixed(3)} – ${p.end.toFixed(3)} s`));
            g.append(pr);
          }
        }
        if (bar.planned !== null && bar.planned !== undefined && bar.attempt === 1) {  // the plan, from the function's (first) start
          g.append(svg("rect", {x, y: y + LANE - 14, width: Math.max(1, bar.planned * scale), height: 4, class: "planned", "data-planned": bar.planned}));
        }
        if (w > 40) g.append(inside(x, y + 6, w, 17, "bar-label", bar.function));
        if (bar.attempt > 1 && w > 12) g.append(inside(x, y + 22, w, 14, "retry-label", w > 50 ? `try ${bar.attempt}` : String(bar.attempt)));
        area.append(g);
      }
      // Named idle time, over the bars: a zone holds a function before its motion, so its wait lies inside the bar.
      for (const wait of (model.waits && model.waits[group]) || []) {  // named idle time: what it waited for, on whom
        if (!visible(wait.start, wait.end)) continue;
        const x = px(wait.start), w = Math.max(1, (wait.end - wait.start) * scale);
        const g = svg("g", {class: "wait", "data-group": group, "data-label": wait.label, "data-waiting": wait.waiting});
        g.append(svg("title", {}, `${group} ${wait.label}\n${wait.start.toFixed(3)} – ${wait.end.toFixed(3)} s (${seconds(wait.end - wait.start)})${wait.outcome ? ` · ${wait.outcome}` : " · still waiting"}`));
        g.append(svg("rect", {x, y: y + 21, width: w, height: 15}));
        if (w > 60) g.append(inside(x, y + 21, w, 15, "wait-label", wait.label.replace(/^waiting for /, "waits: ")));
        area.append(g);
      }
    });
    // The critical path's links between groups: from the step that released a wait (or ended an operation) to the one it let go.
    const steps = model.critical || [];
    for (let i = 1; i < steps.length; i++) {
      const a = steps[i - 1], b = steps[i];
      if (a.group === b.group) continue;
      const at = a.wait ? a.wait.end : b.start;
      if (!visible(a.end, at)) continue;
      area.append(svg("path", {d: `M${px(a.end)},${laneY.get(a.group) + LANE / 2 - 4} L${px(at)},${laneY.get(b.group) + LANE / 2 - 4}`, class: "critical-link", "data-via": a.via}));
    }
    // Marks: an error on its group's lane at its time, its message on hover; operator actions and engine errors on the axis.
    for (const mark of model.marks || []) {
      if (!["error", "operator", "outcome", "branch"].includes(mark.kind) || !visible(mark.t, mark.t)) continue;
      const x = px(mark.t), lane = laneY.get(mark.group);
      const y = lane === undefined ? AXIS - 2 : lane + LANE / 2 - 4;
      const g = svg("g", {class: `mark mark-${mark.kind}`, "data-group": mark.group, "data-t": mark.t});
      g.append(svg("title", {}, `${mark.t.toFixed(3)} s · ${mark.group} · ${mark.kind}: ${mark.text}`));
      if (mark.kind === "error") g.append(svg("path", {d: `M${x - 6},${y - 6} L${x + 6},${y + 6} M${x - 6},${y + 6} L${x + 6},${y - 6}`}));
      else g.append(svg("path", {d: `M${x - 5},${y - 7} L${x + 5},${y - 7} L${x},${y} Z`}));
      area.append(g);
    }
    area.append(svg("line", {x1: px(cursor), x2: px(cursor), y1: AXIS - 8, y2: height - 6, class: "cursor", "data-t": cursor}));
    root.append(area, axis);
    box.replaceChildren(root);

    const slider = $("tl-slider");
    slider.max = String(domain()[1]);
    slider.value = Store.cursor === null ? slider.max : String(Store.cursor);
    $("tl-cursor").textContent = Store.cursor === null ? `live (${model.end.toFixed(2)} s)` : `${Store.cursor.toFixed(2)} s`;
    const swatch = (text, className, style) => Object.assign(document.createElement("span"), {className, textContent: text, style: style || ""});
    const onPath = steps.length ? `critical path: ${steps.length} function(s) across ${new Set(steps.map((p) => p.group)).size} group(s)` : "";
    $("tl-legend").replaceChildren(`${model.bars} function bar(s), ${model.records} record(s) `,
      ...Object.entries(model.colours).map(([state, colour]) => swatch(state, "swatch", `background:${colour}`)),
      swatch("waiting (flag, zone)", "swatch swatch-wait"), swatch("planned (dry run)", "swatch swatch-planned"),
      swatch(onPath || "critical path", "swatch swatch-critical"), swatch("× error", "swatch swatch-error"));
    document.body.dataset.timelineRecords = String(model.records);
  }

  function redrawSoon() { if (!frame) frame = requestAnimationFrame(() => { frame = 0; draw(); }); }
  function zoomAt(t, factor) {
    const [t0, t1] = shownRange();
    view = clampView(t - (t - t0) / factor, t - (t - t0) / factor + (t1 - t0) / factor);
    redrawSoon();
  }
  function zoom(factor) { if (!model) return; const [t0, t1] = shownRange(); zoomAt((t0 + t1) / 2, factor); }
  function timeAt(clientX) {
    const rect = $("timeline").getBoundingClientRect(), [t0, t1] = shownRange();
    const plot = Math.max(rect.width - LEFT - RIGHT, 1);
    return t0 + Math.min(Math.max(clientX - rect.left - LEFT, 0), plot) / plot * (t1 - t0);
  }
  document.addEventListener("DOMContentLoaded", () => {
    const box = $("timeline");
    $("tl-zoom-in").addEventListener("click", () => zoom(2));
    $("tl-zoom-out").addEventListener("click", () => zoom(0.5));
    $("tl-fit").addEventListener("click", () => { view = null; draw(); });
    $("tl-slider").addEventListener("input", () => Store.setCursor(parseFloat($("tl-slider").value)));
    $("tl-live").addEventListener("click", () => Store.setCursor(null));
    box.addEventListener("wheel", (e) => { if (!model) return; e.preventDefault(); zoomAt(timeAt(e.clientX), Math.exp(-e.deltaY * 0.0015)); }, {passive: false});
    box.addEventListener("pointerdown", (e) => {
      if (!model || e.button !== 0) return;
      drag = {x: e.clientX, range: shownRange()};
      box.setPointerCapture(e.pointerId);
      box.classList.add("dragging");
    });
    box.addEventListener("pointermove", (e) => {
      if (!drag) return;
      const [t0, t1] = drag.range, plot = Math.max(box.getBoundingClientRect().width - LEFT - RIGHT, 1);
      const dt = -(e.clientX - drag.x) / plot * (t1 - t0);
      if (view || dt) view = clampView(t0 + dt, t1 + dt) || view;
      redrawSoon();
    });
    const release = () => { drag = null; box.classList.remove("dragging"); };
    box.addEventListener("pointerup", release);
    box.addEventListener("pointercancel", release);
  });
  Store.on("snapshot", () => { view = null; refreshSoon(0); });
  const shown = () => document.getElementById("view-timeline").classList.contains("active");
  Store.on("records", () => { if (shown()) refreshSoon(300); });  // the model is asked for only while it is looked at
  Store.on("cursor", () => refreshSoon(0));
  Store.on("view", (v) => { if (v === "timeline") refreshSoon(0); });
  // show(t0, t1): the window of run time to draw (a link, a screenshot); fit(): the whole run.
  return {refresh, zoom, model: () => model, range: () => (model ? shownRange() : null),
    show: (t0, t1) => { if (model) { view = clampView(t0, t1); draw(); } }, fit: () => { view = null; draw(); }};
})();
