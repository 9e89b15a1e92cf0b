// The layout of a group machine's state graph, from the structure it published (paper Table 2), by ELK (elkjs).
//
// Drawn as one edge per transition, Table 2 is a tangle: every working state has its own pause, stop and error
// edge into the same three states (21 edges crossing everything).  So the graph is read as the paper's figures
// draw it (Fig. 11): a hub -- the initial state, Ready, at the centre of the working states it requests, laid out
// by ELK's radial algorithm around it -- and a band of the exceptional states (Pause, Stop, ErrorHandling,
// Finish) apart, laid out by ELK's layered algorithm in a row.  A transition every working state has on one
// signal into one state is one edge, from the hub's border to the band (its ports), with that signal's label;
// so is a transition back to the hub (ok -> Ready, resume -> the paused state).  Nothing is named here: the
// hub is the machine's initial state, the working states are the ones it requests that come back to it, the
// band is every other state, so a machine with other states is drawn by the same rule.
"use strict";

const GraphLayout = (() => {
  const HISTORY = "<history>";
  const FONT = 12;                 // px, the label size at the default zoom (the card draws the graph 1:1 or larger)
  const NODE_H = 24;
  const HUB = "hub", BAND = "band";

  // Text width: the page measures with a canvas in the page's font; elsewhere (node, tests) an estimate.
  let canvas = null;
  function textWidth(text, size) {
    if (typeof document !== "undefined") {
      canvas = canvas || document.createElement("canvas");
      const ctx = canvas.getContext("2d");
      ctx.font = `${size}px sans-serif`;
      return Math.ceil(ctx.measureText(text).width);
    }
    return Math.ceil(text.length * size * 0.6);
  }

  // The reading of a structure: the hub, its working states, the band and the transitions grouped into edges.
  function model(structure) {
    const states = structure.states.slice();
    const hub = structure.initial && states.includes(structure.initial) ? structure.initial : states[0];
    const out = (s) => structure.transitions.filter((t) => t.from === s);
    const working = states.filter((s) => s !== hub && out(hub).some((t) => t.to === s) && out(s).some((t) => t.to === hub));
    const band = states.filter((s) => s !== hub && !working.includes(s));
    const inHub = (s) => s === hub || working.includes(s);
    const spokes = working.map((s) => ({state: s, transitions: [...out(hub).filter((t) => t.to === s), ...out(s).filter((t) => t.to === hub)]}));
    // Edges between the hub and the band: grouped by (signal, target) out of the hub, by (source, signal, target) into it.
    const bundles = new Map();
    const internal = [];
    for (const t of structure.transitions) {
      const to = t.to === HISTORY ? HISTORY : t.to;
      if (inHub(t.from) && inHub(to)) continue;  // a spoke
      if (inHub(t.from)) {
        const key = `out:${t.signal}:${to}`;
        if (!bundles.has(key)) bundles.set(key, {id: key, from: HUB, to, signal: t.signal, transitions: []});
        bundles.get(key).transitions.push(t);
      } else if (inHub(to) || to === HISTORY) {
        const key = `in:${t.from}:${t.signal}:${to}`;
        bundles.set(key, {id: key, from: t.from, to: HUB, target: to, signal: t.signal, transitions: [t]});
      } else internal.push({id: `band:${t.from}:${t.signal}:${to}`, from: t.from, to, signal: t.signal, transitions: [t]});
    }
    for (const b of bundles.values()) {
      const sources = [...new Set(b.transitions.map((t) => t.from))];
      // Short labels (the tooltip lists every transition an edge stands for): the signal, and where an edge
      // into the hub goes when that is one state (ok -> Ready); resume goes back to the state it paused.
      if (b.from === HUB) b.label = b.signal;
      else b.label = b.target === HISTORY ? b.signal : `${b.signal} → ${b.target}`;
      b.title = b.transitions.map((t) => `${t.from} —${t.signal}→ ${t.to === HISTORY ? "the state it paused" : t.to}`).join("\n");
    }
    return {hub, working, band, spokes, bundles: [...bundles.values()], internal};
  }

  const label = (text) => ({text, width: textWidth(text, FONT) + 4, height: FONT + 4});
  const node = (id) => ({id, width: Math.max(56, textWidth(id, FONT) + 16), height: NODE_H});

  // Hub above, the band below in one row: ELK's layered algorithm lays out the hub (itself laid out radially) and
  // the band's states as one layer under it, routing the hub <-> band edges orthogonally between them; the
  // band's own transitions (pause -> stop -> error handling -> finish) run along the row (see ``bandEdges``).
  function elkGraph(m) {
    const hubEdges = m.spokes.map((s) => ({id: `spoke:${s.state}`, sources: [m.hub], targets: [s.state]}));
    const topEdges = m.bundles.map((b) => b.from === HUB
      ? {id: b.id, sources: [HUB], targets: [b.to], labels: [label(b.label)]}
      : {id: b.id, sources: [b.from], targets: [HUB], labels: [label(b.label)]});
    return {
      id: "root",
      layoutOptions: {
        "elk.algorithm": "layered", "elk.direction": "DOWN", "elk.hierarchyHandling": "SEPARATE_CHILDREN",
        "elk.edgeRouting": "ORTHOGONAL", "elk.padding": "[top=4,left=4,bottom=4,right=4]",
        "elk.layered.spacing.nodeNodeBetweenLayers": "20", "elk.spacing.nodeNode": "34", "elk.spacing.edgeEdge": "10", "elk.spacing.edgeLabel": "2",
        "elk.layered.spacing.edgeEdgeBetweenLayers": "8", "elk.edgeLabels.inline": "false",
        "elk.layered.considerModelOrder.strategy": "NODES_AND_EDGES", "elk.layered.crossingMinimization.forceNodeModelOrder": "true",
      },
      children: [
        {id: HUB, layoutOptions: {"elk.algorithm": "radial", "elk.padding": "[top=10,left=10,bottom=10,right=10]", "elk.spacing.nodeNode": "14",
                                  "elk.radial.compactor": "NONE"},
         children: [node(m.hub), ...m.working.map(node)], edges: hubEdges},
        ...m.band.map(node),
      ],
      edges: topEdges,
    };
  }

  // Absolute geometry: {width, height, hub, nodes: {state: {x, y, width, height, kind}}, clusters, edges: [{id, kind,
  // points, label: {x, y, text}, transitions, title}]}; ``elk`` is an ELK instance (the page's, or elkjs in node).
  async function layout(structure, elk) {
    const m = model(structure);
    const g = await elk.layout(elkGraph(m));
    const out = {width: g.width, height: g.height, hub: m.hub, nodes: {}, clusters: {}, edges: [], model: m};
    for (const c of g.children) {
      if (c.id === HUB) {
        out.clusters[HUB] = {x: c.x, y: c.y, width: c.width, height: c.height};
        for (const n of c.children) out.nodes[n.id] = {x: c.x + n.x, y: c.y + n.y, width: n.width, height: n.height, kind: n.id === m.hub ? "hub" : "working"};
      } else out.nodes[c.id] = {x: c.x, y: c.y, width: c.width, height: c.height, kind: "band"};
    }
    const centre = (n) => ({x: n.x + n.width / 2, y: n.y + n.height / 2});
    // Spokes: straight between the hub and each working state, both ways (request out, ok back).
    for (const s of m.spokes) {
      const a = centre(out.nodes[m.hub]), b = centre(out.nodes[s.state]);
      out.edges.push({id: `spoke:${s.state}`, kind: "spoke", points: [clip(out.nodes[m.hub], b), clip(out.nodes[s.state], a)], transitions: s.transitions,
                      title: s.transitions.map((t) => `${t.from} —${t.signal}→ ${t.to}`).join("\n")});
    }
    // Hub <-> band: ELK's routes.
    for (const b of m.bundles) {
      const e = g.edges.find((x) => x.id === b.id);
      const points = (e.sections || []).flatMap((x) => [x.startPoint, ...(x.bendPoints || []), x.endPoint]);
      const l = e.labels && e.labels[0];
      out.edges.push({id: b.id, kind: "bundle", points, transitions: b.transitions, title: b.title, text: b.label,
                      label: l ? {x: l.x + l.width / 2, y: l.y + l.height / 2, text: b.label} : null});
    }
    bandEdges(m, out);
    const band = m.band.map((s) => out.nodes[s]);
    if (band.length) {
      const x0 = Math.min(...band.map((n) => n.x)) - 8, x1 = Math.max(...band.map((n) => n.x + n.width)) + 8;
      const y0 = Math.min(...band.map((n) => n.y)) - 8;
      const y1 = Math.max(...band.map((n) => n.y + n.height), ...out.edges.filter((e) => e.kind === "band").flatMap((e) => [...e.points.map((p) => p.y), e.label ? e.label.y + FONT / 2 : 0])) + 6;
      out.clusters[BAND] = {x: x0, y: y0, width: x1 - x0, height: y1 - y0};
      out.height = Math.max(out.height, y1 + 4);
      out.width = Math.max(out.width, x1 + 4);
    }
    return out;
  }

  // The band's own transitions, along its row: a neighbour to the right by a straight arrow (its signal under it),
  // any other (a skip, or back to the left) by a detour under the row, one lane each.
  function bandEdges(m, out) {
    const row = m.band.slice().sort((a, b) => out.nodes[a].x - out.nodes[b].x);
    const bottom = Math.max(...row.map((s) => out.nodes[s].y + out.nodes[s].height));
    let lane = 0;
    for (const e of m.internal) {
      const a = out.nodes[e.from], b = out.nodes[e.to];
      const right = row.indexOf(e.to) === row.indexOf(e.from) + 1;
      let points, lx, ly;
      if (right) {
        const y = Math.max(a.y, b.y) + Math.min(a.height, b.height) / 2;
        points = [{x: a.x + a.width, y}, {x: b.x, y}];
        lx = (a.x + a.width + b.x) / 2; ly = y + FONT;
      } else {
        lane += 1;
        const y = bottom + lane * (FONT + 8);
        const xa = a.x + a.width * (b.x > a.x ? 0.75 : 0.25), xb = b.x + b.width * (b.x > a.x ? 0.25 : 0.75);
        points = [{x: xa, y: a.y + a.height}, {x: xa, y}, {x: xb, y}, {x: xb, y: b.y + b.height}];
        lx = (xa + xb) / 2; ly = y - 3;
      }
      out.edges.push({id: e.id, kind: "band", points, transitions: e.transitions, text: e.signal, title: `${e.from} —${e.signal}→ ${e.to}`,
                      label: {x: lx, y: ly, text: e.signal}});
    }
  }

  // The point where the segment from the centre of ``n`` towards ``p`` leaves its box.
  function clip(n, p) {
    const c = {x: n.x + n.width / 2, y: n.y + n.height / 2};
    const dx = p.x - c.x, dy = p.y - c.y;
    const s = Math.min(dx ? (n.width / 2) / Math.abs(dx) : Infinity, dy ? (n.height / 2) / Math.abs(dy) : Infinity, 1);
    return {x: c.x + dx * s, y: c.y + dy * s};
  }

  // The edge a transition record was drawn on (a spoke, a bundle or a band edge), or null.
  function edgeOf(geometry, from, signal, to) {
    return geometry.edges.find((e) => e.transitions.some((t) => t.from === from && t.signal === signal && (t.to === to || t.to === HISTORY))) || null;
  }

  return {layout, model, elkGraph, edgeOf, FONT, HISTORY};
})();

if (typeof module !== "undefined") module.exports = GraphLayout;
