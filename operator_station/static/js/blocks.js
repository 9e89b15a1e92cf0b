// The application as a tree of steps (issue 24): operations, and the loops and calls around them, shown as
// blocks in the builder's table.  The tree is the document's `body`; the table draws it flattened into rows
// (a block's head, its steps indented, its end), so a 10,000-operation file still draws only the visible rows.
// The kinds of block are data (KINDS, as operator_station/blocks.py's BLOCK_KINDS): a branch is one more kind, its
// attributes shown as plain fields until it is given fields of its own in renderBlock.
"use strict";

const Blocks = (() => {
  const KINDS = {
    for_each: {label: "for each", body: true, help: "The steps inside run once for each value: {VAR} is the value, {index} its place (from 1). " +
      "Values: a list (drill_1 drill_2), every frame of a kind of the cell (kind:hole), or a pallet grid made under a frame (grid:ORIGIN RxC PITCH_X PITCH_Y, pitches in metres)."},
    repeat: {label: "repeat", body: true, help: "The steps inside run COUNT times: {VAR} (index unless named) counts from 1."},
    call: {label: "call", body: false, help: "The operations of another application file (a library block, its path relative to this file), with each param bound to its {NAME}."},
    if: {label: "if", body: true, attributes: ["group", "operation", "outcome"], help: "The steps inside run only when GROUP's function in OPERATION " +
      "(one before this block; {VAR} of the loops around it allowed) ended with OUTCOME (the outcomes of each function: `functions`, e.g. locate: found / not_found)."},
    else: {label: "else", body: true, attributes: [], help: "Right after an if: the steps run when the if's outcome was not met."},
  };
  const isBlock = (step) => step.type !== "operation";
  // A kind the page does not know yet (the server's model has more): shown by its name, its body drawn, its attributes as fields.
  const kind = (type) => KINDS[type] || {label: type, body: true, help: ""};

  // Rows of the table: {kind: "op"|"block"|"end", step, list (the body holding it), index, key ("0.2.1"), depth,
  // leaf (an operation's place among all of them), parents (the blocks around it, outermost first)}.
  function flatten(body) {
    const rows = [], leaves = [], byKey = new Map();
    const visit = (list, prefix, parents) => list.forEach((step, index) => {
      const path = [...prefix, index], key = path.join(".");
      const row = {kind: isBlock(step) ? "block" : "op", step, list, index, key, depth: parents.length, parents, leaf: isBlock(step) ? -1 : leaves.length};
      rows.push(row);
      byKey.set(key, row);
      if (!isBlock(step)) { leaves.push(row); return; }
      if (kind(step.type).body && Array.isArray(step.body)) {
        visit(step.body, path, [...parents, step]);
        rows.push({kind: "end", step, list, index, key: `${key}.end`, depth: parents.length, parents});
      }
    });
    visit(body, [], []);
    return {rows, leaves, byKey};
  }

  // The {variables} a step inside these blocks may use, innermost last.
  function scope(parents) {
    const out = [];
    for (const p of parents) {
      if (p.type === "for_each") out.push(p.attributes.var || "", p.attributes.index || "index");
      else if (p.type === "repeat") out.push(p.attributes.var || "index");
    }
    return out.filter((v) => v);
  }

  // `in` as the page edits it: a mode and its fields; composed back to the text the file holds.
  function parseIn(text) {
    const t = (text || "").trim();
    if (t.startsWith("kind:")) return {mode: "kind", kind: t.slice(5).trim()};
    if (t.startsWith("grid:")) {
      const parts = t.slice(5).trim().split(/\s+/);
      if (parts.length === 4) return {mode: "grid", origin: parts[0], size: parts[1], px: parts[2], py: parts[3]};
      return {mode: "text", text: t};
    }
    return {mode: "list", list: t};
  }
  function composeIn(spec) {
    if (spec.mode === "kind") return `kind:${spec.kind || ""}`;
    if (spec.mode === "grid") return `grid:${spec.origin || ""} ${spec.size || ""} ${spec.px || ""} ${spec.py || ""}`;
    if (spec.mode === "text") return spec.text || "";
    return spec.list || "";
  }
  // How many iterations a for_each makes, when the page can tell (the validator says it for every case).
  function iterations(step, cellNames) {
    if (step.type === "repeat") return /^\d+$/.test(step.attributes.count || "") ? Number(step.attributes.count) : null;
    if (step.type !== "for_each") return null;
    const spec = parseIn(step.attributes.in);
    if (spec.mode === "list") return spec.list.split(/[\s,]+/).filter((v) => v).length;
    if (spec.mode === "kind") return cellNames ? (cellNames.frames || []).filter((f) => f.kind === spec.kind).length : null;
    const size = spec.mode === "grid" && spec.size.match(/^(\d+)x(\d+)$/);
    return size ? Number(size[1]) * Number(size[2]) : null;
  }

  // A new block: a loop holds one operation (its id made unique per iteration by the loop's variable).
  function newBlock(type, fresh, cellNames) {
    if (type === "call") return {type, attributes: {application: ""}, params: [], body: [], comments: [], trailer: []};
    if (type === "if" || type === "else") {  // a branch: its group, the operation before it and the outcome are filled in by hand
      const attributes = type === "if" ? {group: "", operation: "", outcome: "found"} : {};
      return {type, attributes, params: [], body: [{type: "operation", id: `${fresh}_${type}`, name: null, calls: [], comments: []}], comments: [], trailer: []};
    }
    const counts = new Map();  // the cell's most frequent kind of frame (holes, pockets): the likeliest to loop over
    for (const f of (cellNames && cellNames.frames) || []) counts.set(f.kind, (counts.get(f.kind) || 0) + 1);
    const kind = [...counts.entries()].sort((a, b) => b[1] - a[1])[0];
    const attributes = type === "for_each" ? {var: "item", in: kind ? `kind:${kind[0]}` : ""} : {count: "2"};
    const op = {type: "operation", id: `${fresh}_{${type === "for_each" ? "item" : "index"}}`, name: null, calls: [], comments: []};
    return {type, attributes, params: [], body: [op], comments: [], trailer: []};
  }

  // Structure edits on a row: each returns whether the tree changed.
  function move(row, delta) {
    const j = row.index + delta;
    if (j < 0 || j >= row.list.length) return false;
    [row.list[row.index], row.list[j]] = [row.list[j], row.list[row.index]];
    return true;
  }
  function indent(row) {  // into the block just above it, at its end
    const above = row.list[row.index - 1];
    if (!above || !isBlock(above) || !kind(above.type).body || !Array.isArray(above.body)) return false;
    row.list.splice(row.index, 1);
    above.body.push(row.step);
    return true;
  }
  function outdent(row, rows) {  // out of its block, just after it
    if (!row.parents.length) return false;
    const parent = row.parents[row.parents.length - 1];
    const holder = rows.find((r) => r.kind === "block" && r.step === parent);
    row.list.splice(row.index, 1);
    holder.list.splice(holder.index + 1, 0, row.step);
    return true;
  }

  // ------------------------------------------------------------------------------ drawing a block's rows
  function field(el, cls, value, placeholder, apply, attrs) {
    const input = el("input", {class: `blk-field ${cls}`, value: value || "", placeholder, title: placeholder, ...(attrs || {})});
    input.addEventListener("change", () => apply(input.value));
    return input;
  }
  function inFields(el, step, cellNames, edited, redraw, where) {
    const spec = parseIn(step.attributes.in);
    const set = (changes) => { Object.assign(spec, changes); step.attributes.in = composeIn(spec); edited(); };
    const mode = el("select", {class: "blk-field blk-mode", title: "the values"},
      ...[["list", "list"], ["kind", "kind:"], ["grid", "grid:"], ...(spec.mode === "text" ? [["text", "as written"]] : [])].map(([v, t]) => el("option", {value: v, text: t})));
    mode.value = spec.mode;
    mode.addEventListener("change", () => {
      const fresh = {mode: mode.value, list: "", kind: "", origin: "", size: "1x1", px: "0.0", py: "0.0", text: ""};
      Object.keys(spec).forEach((k) => delete spec[k]);
      set(fresh);
      redraw();
    });
    const frames = ((cellNames && cellNames.frames) || []).map((f) => f.name);
    const kinds = [...new Set(((cellNames && cellNames.frames) || []).map((f) => f.kind))];
    const parts = [mode];
    if (spec.mode === "list") parts.push(field(el, "blk-list", spec.list, "values, e.g. drill_1 drill_2", (v) => set({list: v}), {size: 28}));
    else if (spec.mode === "kind") parts.push(field(el, "blk-kind", spec.kind, "a kind of frame", (v) => set({kind: v}), {list: `blk-kinds-${where}`, size: 10}),
      el("datalist", {id: `blk-kinds-${where}`}, ...kinds.map((k) => el("option", {value: k}))));
    else if (spec.mode === "grid") parts.push(
      field(el, "blk-origin", spec.origin, "origin frame", (v) => set({origin: v}), {list: `blk-frames-${where}`, size: 10}),
      el("datalist", {id: `blk-frames-${where}`}, ...frames.map((f) => el("option", {value: f}))),
      field(el, "blk-size", spec.size, "rows x columns, e.g. 3x4", (v) => set({size: v}), {size: 4}),
      field(el, "blk-px", spec.px, "pitch along x [m]", (v) => set({px: v}), {size: 5}),
      field(el, "blk-py", spec.py, "pitch along y [m]", (v) => set({py: v}), {size: 5}));
    else parts.push(field(el, "blk-text", spec.text, "in, as written", (v) => set({text: v}), {size: 28}));
    return parts;
  }
  function renderBlock(el, row, ctx) {
    const {step} = row;
    const attr = (name) => (v) => { if (v === "" && !["var", "in", "count", "application"].includes(name)) delete step.attributes[name]; else step.attributes[name] = v; ctx.edited(); };
    const parts = [el("span", {class: `blk-kind blk-${step.type}`, text: kind(step.type).label, title: kind(step.type).help})];
    if (step.type === "for_each") {
      parts.push(field(el, "blk-var", step.attributes.var, "variable", attr("var"), {size: 7}), el("span", {text: "in"}),
        ...inFields(el, step, ctx.cellNames, ctx.edited, ctx.redraw, ctx.where),
        field(el, "blk-index", step.attributes.index, "index", attr("index"), {size: 6}));
    } else if (step.type === "repeat") {
      parts.push(field(el, "blk-count", step.attributes.count, "count", attr("count"), {size: 4}), el("span", {text: "times, counting"}),
        field(el, "blk-var", step.attributes.var, "index", attr("var"), {size: 7}));
    } else if (step.type === "call") {
      parts.push(field(el, "blk-application", step.attributes.application, "application file, e.g. blocks/rivet_block.xml", attr("application"), {size: 22}));
      step.params.forEach((p, i) => parts.push(el("span", {class: "blk-param"},
        field(el, "blk-param-name", p.name, "name", (v) => { p.name = v; ctx.edited(); }, {size: 5}), "=",
        field(el, "blk-param-value", p.value, "value", (v) => { p.value = v; ctx.edited(); }, {size: 9}),
        el("button", {class: "blk-param-del", title: "remove the param", text: "✕", onclick: () => { step.params.splice(i, 1); ctx.changed(); }}))));
      parts.push(el("button", {class: "blk-param-add", text: "+ param", onclick: () => { step.params.push({name: "", value: ""}); ctx.changed(); }}));
    } else {  // a kind without fields of its own: each attribute it has, as written
      for (const name of (KINDS[step.type] || {}).attributes || Object.keys(step.attributes)) {
        parts.push(field(el, `blk-attr-${name}`, step.attributes[name], name, attr(name), {size: 10}));
      }
    }
    const count = iterations(step, ctx.cellNames);
    if (count !== null) parts.push(el("span", {class: "blk-count-shown", text: `→ ${count} iteration(s)`}));
    if (ctx.messages.length) parts.push(el("span", {class: "cell-msg", text: ctx.messages[0].message}));
    return parts;
  }

  return {KINDS, kind, isBlock, flatten, scope, parseIn, composeIn, iterations, newBlock, move, indent, outdent, renderBlock};
})();
