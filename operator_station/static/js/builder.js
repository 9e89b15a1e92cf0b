// The application builder (paper Figure 7): the catalog on the left, the application as a table of
// operations x groups, the selected cell's function and typed params on the right.  Loops and calls are
// blocks of rows around the operations they hold (blocks.js).  Every edit is validated by the project's
// own validator on the server; each message is shown at its cell, or at its block's row.
"use strict";

const Builder = (() => {
  const ROW_H = 30;
  const b = {doc: null, path: "", messages: [], byCell: new Map(), selected: null, cellNames: null, valid: null, validating: 0,
             view: {rows: [], leaves: [], byKey: new Map()}};
  const $ = (id) => document.getElementById(id);
  const el = (tag, attrs, ...children) => {
    const node = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (k === "class") node.className = v; else if (k === "text") node.textContent = v;
      else if (k.startsWith("on")) node.addEventListener(k.slice(2), v); else node.setAttribute(k, v);
    }
    for (const c of children) if (c !== null && c !== undefined) node.append(c);
    return node;
  };

  // ------------------------------------------------------------------------------ the robot and catalog
  const robotInfo = () => {
    const robots = (Store.catalog && Store.catalog.robots) || {};
    const name = b.doc ? b.doc.robot : "";
    for (const [key, robot] of Object.entries(robots)) if (key === name || (robot.aliases || []).includes(name)) return {name: key, ...robot};
    return null;
  };
  const groups = () => { const r = robotInfo(); return r ? Object.keys(r.groups) : []; };
  const groupKind = (g) => { const r = robotInfo(); return r && r.groups[g] ? r.groups[g].kind : g; };
  const fnSpec = (name) => (Store.catalog.functions || []).find((f) => f.name === name);
  const fits = (spec, group) => !spec.groups || spec.groups.length === 0 || spec.groups.includes(groupKind(group)) || spec.groups.includes(group);

  function renderCatalog() {
    const box = $("catalog");
    box.replaceChildren(el("h3", {text: "Functions"}), el("input", {id: "catalog-filter", placeholder: "filter", oninput: filterCatalog}));
    const kinds = [["core", "Core functions"], ["app", "Application functions"]];
    for (const [kind, title] of kinds) {
      const section = el("div", {class: `catalog-kind catalog-${kind}`}, el("h4", {text: title}));
      for (const library of Store.catalog.libraries.filter((l) => l.kind === kind)) {
        if (kind === "app") section.append(el("h5", {text: library.name}));
        for (const name of library.functions) {
          const spec = fnSpec(name);
          const item = el("div", {class: "catalog-fn", "data-name": name, title: spec.doc, onclick: () => assignFunction(name)},
            el("code", {text: spec.signature}), el("div", {class: "fn-doc", text: spec.doc.split("\n")[0]}),
            el("div", {class: "fn-groups", text: `groups: ${spec.groups.join(", ")}`}));
          section.append(item);
        }
      }
      box.append(section);
    }
  }
  function filterCatalog(event) {
    const text = event.target.value.toLowerCase();
    for (const item of document.querySelectorAll(".catalog-fn")) item.style.display = item.textContent.toLowerCase().includes(text) ? "" : "none";
  }

  // ------------------------------------------------------------------------------ the document
  // The page holds every document as a tree (`body`); a flat one arrives as `operations`.  `doc.operations`
  // stays readable (every operation, in document order) but is not sent: the server takes the body.
  function normalize(doc) {
    if (!Array.isArray(doc.body)) doc.body = (doc.operations || []).map((op) => ({type: "operation", ...op}));
    delete doc.operations;
    delete doc.steps;
    Object.defineProperty(doc, "operations", {get: () => b.view.leaves.map((r) => r.step), enumerable: false, configurable: true});
    return doc;
  }
  function setDocument(doc, path) {
    b.doc = normalize(doc);
    b.view = Blocks.flatten(b.doc.body);
    b.path = path || "";
    b.selected = null;
    $("doc-path").value = b.path;
    renderAppFields();
    renderTable();
    renderInspector();
    loadCellNames();
    validateSoon(0);
  }
  function renderAppFields() {
    const robots = Object.keys((Store.catalog && Store.catalog.robots) || {});
    const robot = robotInfo();
    $("app-robot").replaceChildren(...robots.map((r) => el("option", {value: r, text: r})));
    if (robot && !robots.includes(b.doc.robot)) $("app-robot").append(el("option", {value: b.doc.robot, text: b.doc.robot}));
    $("app-robot").value = b.doc.robot;
    $("app-name").value = b.doc.name || "";
    $("app-cell").value = b.doc.cell || "";
    $("app-description").value = b.doc.description || "";
    const policy = b.doc.error_policy || {};
    $("policy-action").value = policy.action || "";
    $("policy-retries").value = policy.retries || "";
    $("policy-safe-pose").value = policy.safe_pose || "";
    $("robot-poses").replaceChildren(...(robot ? Object.keys(robot.joint_poses_deg) : []).map((p) => el("option", {value: p})));
  }
  function bindAppFields() {
    const text = (id, apply) => $(id).addEventListener("input", () => { apply($(id).value); edited(); });
    text("app-name", (v) => { b.doc.name = v; });
    text("app-cell", (v) => { b.doc.cell = v === "" ? null : v; loadCellNamesSoon(); });
    text("app-description", (v) => { b.doc.description = v === "" ? null : v; });
    $("app-robot").addEventListener("change", () => { b.doc.robot = $("app-robot").value; renderTable(); renderInspector(); loadCellNames(); edited(); });
    const policy = (id, key) => text(id, (v) => {
      const p = Object.assign({}, b.doc.error_policy || {});
      if (v === "") delete p[key]; else p[key] = v;
      b.doc.error_policy = Object.keys(p).length ? p : null;
    });
    policy("policy-retries", "retries"); policy("policy-safe-pose", "safe_pose");
    $("policy-action").addEventListener("change", () => {
      const p = Object.assign({}, b.doc.error_policy || {});
      if ($("policy-action").value === "") delete p.action; else p.action = $("policy-action").value;
      b.doc.error_policy = Object.keys(p).length ? p : null;
      edited();
    });
  }

  // ------------------------------------------------------------------------------ the table (virtual rows)
  const cellKey = (key, group) => `${key}|${group || ""}`;
  const rowOf = (key) => b.view.byKey.get(key);
  function renderTable() {
    const gs = groups();
    const columns = `40px 70px 140px repeat(${Math.max(gs.length, 1)}, minmax(180px, 1fr)) 112px`;
    $("ops-header").style.gridTemplateColumns = columns;
    $("ops-header").replaceChildren(el("div", {text: "#"}), el("div", {text: "id"}), el("div", {text: "name"}),
      ...gs.map((g) => el("div", {text: g, class: "group-head"})), el("div", {text: ""}));
    $("ops-spacer").style.height = `${b.view.rows.length * ROW_H}px`;
    const blocks = b.view.rows.filter((r) => r.kind === "block").length;
    $("op-count").textContent = `${b.view.leaves.length} operation(s)${blocks ? `, ${blocks} block(s)` : ""}`;
    b.columns = columns;
    renderRows();
  }
  function renderRows() {
    if (!b.doc) return;
    const scroll = $("ops-scroll");
    const first = Math.max(0, Math.floor(scroll.scrollTop / ROW_H) - 5);
    const count = Math.min(Math.ceil((scroll.clientHeight || 600) / ROW_H) + 10, 200);  // never the whole table
    const rows = [];
    const gs = groups();
    for (let i = first; i < Math.min(b.view.rows.length, first + count); i++) rows.push(renderRow(b.view.rows[i], gs));
    $("ops-rows").style.transform = `translateY(${first * ROW_H}px)`;
    $("ops-rows").replaceChildren(...rows);
  }
  function tools(row) {
    const button = (cls, title, text, act) => el("button", {class: cls, title, text, onclick: () => { if (act()) changed(); }});
    return el("div", {class: "row-tools"},
      button("op-up", "move up", "▲", () => Blocks.move(row, -1)),
      button("op-down", "move down", "▼", () => Blocks.move(row, 1)),
      button("op-in", "into the block above", "⇥", () => Blocks.indent(row)),
      button("op-out", "out of its block", "⇤", () => Blocks.outdent(row, b.view.rows)),
      button("op-del", row.kind === "block" ? "remove the block and what it holds" : "remove", "✕", () => remove(row)));
  }
  function renderRow(row, gs) {
    const depth = row.depth ? {style: `border-left: ${row.depth * 8}px solid #dbe8f6`} : {};
    if (row.kind === "end") {
      const end = el("div", {class: "ops-row blk-end", "data-step": row.key, ...depth}, el("div", {}),
        el("div", {class: "blk-end-label"}, `end ${Blocks.kind(row.step.type).label} `,
          el("button", {class: "blk-add-inside", text: "+ operation inside", onclick: () => addStep("operation", {list: row.step.body, at: row.step.body.length})})),
        el("div", {}));
      end.style.gridTemplateColumns = b.columns;
      end.lastChild.style.gridColumn = "-2 / -1";
      end.children[1].style.gridColumn = "2 / -2";
      return end;
    }
    if (row.kind === "block") {
      const messages = b.byCell.get(cellKey(row.key, null)) || [];
      const selected = b.selected && b.selected.key === row.key;
      const errors = messages.some((m) => m.severity === "error");
      const fields = el("div", {class: `blk-fields${errors ? " has-error" : messages.length ? " has-warning" : ""}`, title: messages.map((m) => m.message).join("\n")},
        ...Blocks.renderBlock(el, row, {cellNames: b.cellNames, messages, changed, redraw: renderRows, where: "row",
                                        edited: () => { edited(); if (selected) renderInspector(); }}));
      fields.style.gridColumn = "2 / -2";
      const line = el("div", {class: `ops-row blk-row blk-${row.step.type}${selected ? " selected" : ""}`, "data-step": row.key, "data-block": row.step.type, ...depth},
        el("div", {class: "op-index blk-select", text: "▸", title: "select the block", onclick: () => selectKey(row.key, null)}), fields, tools(row));
      line.style.gridTemplateColumns = b.columns;
      return line;
    }
    const op = row.step;
    const opMessages = b.byCell.get(cellKey(row.key, null)) || [];
    const id = el("input", {class: "op-id", value: op.id, "data-op": row.leaf});
    id.addEventListener("change", () => { op.id = id.value; edited(); });
    const name = el("input", {class: "op-name", value: op.name || "", "data-op": row.leaf});
    name.addEventListener("change", () => { op.name = name.value === "" ? null : name.value; edited(); });
    const idCell = el("div", {class: `op-idcell${opMessages.length ? " has-error" : ""}`, title: opMessages.map((m) => m.message).join("\n")}, id,
      opMessages.length ? el("div", {class: "cell-msg", text: opMessages[0].message}) : null);
    // The gutter toggles the operation's breakpoint (break="true" when saved): the run pauses before it.
    const gutter = el("div", {class: `op-index op-break${op.break ? " on" : ""}`, text: String(row.leaf + 1), "data-op": row.leaf,
      title: op.break ? "breakpoint: the run pauses before this operation (click to remove)" : "click to set a breakpoint: the run pauses before this operation",
      onclick: () => { if (op.break) delete op.break; else op.break = true; edited(); }});
    const line = el("div", {class: "ops-row", "data-op": row.leaf, "data-step": row.key, ...depth}, gutter, idCell, name);
    line.style.gridTemplateColumns = b.columns;
    for (const g of gs) line.append(renderCell(row, g));
    line.append(tools(row));
    return line;
  }
  function renderCell(row, g) {
    const op = row.step;
    const call = op.calls.find((c) => c.group === g);
    const messages = b.byCell.get(cellKey(row.key, g)) || [];
    const text = call ? `${call.function}(${call.params.map((p) => p.value).join(", ")})` : "— waits";
    const selected = b.selected && b.selected.key === row.key && b.selected.group === g;
    const errors = messages.filter((m) => m.severity === "error");
    const cell = el("div", {class: `op-cell${call ? "" : " empty"}${selected ? " selected" : ""}${errors.length ? " has-error" : messages.length ? " has-warning" : ""}`,
      "data-op": row.leaf, "data-step": row.key, "data-group": g, title: [text, ...messages.map((m) => m.message)].join("\n"), onclick: () => selectKey(row.key, g)},
      el("span", {class: "cell-call", text}), messages.length ? el("div", {class: "cell-msg", text: messages[0].message}) : null);
    return cell;
  }
  // After a change of the tree's shape: the rows again, the selection kept on its step where it still is.
  function changed() {
    const step = b.selected && rowOf(b.selected.key) ? rowOf(b.selected.key).step : null;
    b.view = Blocks.flatten(b.doc.body);
    if (step) {
      const row = b.view.rows.find((r) => r.step === step && r.kind !== "end");
      b.selected = row ? {key: row.key, group: b.selected.group} : null;
    }
    b.byCell = new Map();  // the messages' places are those of the old tree: the next validation places them again
    renderTable();
    renderInspector();
    edited();
  }
  function remove(row) {
    row.list.splice(row.index, 1);
    if (b.selected && (b.selected.key === row.key || b.selected.key.startsWith(`${row.key}.`))) b.selected = null;
    return true;
  }
  function freshId() {
    const ids = new Set(b.view.leaves.map((r) => r.step.id));
    let n = b.view.leaves.length + 1;
    while (ids.has(String(n)) || [...ids].some((id) => id.startsWith(`${n}_`))) n++;
    return String(n);
  }
  // Where a new step goes: inside the selected block (at its end), else just after the selected step, else at the end.
  function insertionPoint() {
    const row = b.selected && rowOf(b.selected.key);
    if (!row) return {list: b.doc.body, at: b.doc.body.length};
    if (row.kind === "block" && Blocks.kind(row.step.type).body && Array.isArray(row.step.body)) return {list: row.step.body, at: row.step.body.length};
    return {list: row.list, at: row.index + 1};
  }
  function addStep(type, where) {
    const {list, at} = where || insertionPoint();
    const fresh = freshId();
    const step = type === "operation" ? {type, id: fresh, name: null, calls: [], comments: []} : Blocks.newBlock(type, fresh, b.cellNames);
    if (type === "operation") {  // inside a loop, the id takes the loop's variable: one id per iteration
      const inside = b.view.rows.find((r) => r.kind === "block" && r.step.body === list);
      const vars = inside ? Blocks.scope([...inside.parents, inside.step]) : [];
      if (vars.length) step.id = `${fresh}_{${vars[vars.length - 1]}}`;
    }
    list.splice(at, 0, step);
    b.view = Blocks.flatten(b.doc.body);
    const row = b.view.rows.find((r) => r.step === step);
    b.selected = {key: row.key, group: type === "operation" ? groups()[0] : null};
    changed();
    scrollTo(row.key);
  }
  function addOperation() { addStep("operation"); }
  function select(op, group) {  // op: an operation's place among all of them (as data-op), or a row's key
    const key = typeof op === "number" ? (b.view.leaves[op] || {}).key : op;
    if (key !== undefined) selectKey(key, group);
  }
  function selectKey(key, group) {
    b.selected = {key, group};
    renderRows();
    renderInspector();
  }
  function scrollTo(key) {
    const at = b.view.rows.findIndex((r) => r.key === (typeof key === "number" ? (b.view.leaves[key] || {}).key : key));
    $("ops-scroll").scrollTop = Math.max(0, at * ROW_H - 60);
    renderRows();
  }

  // ------------------------------------------------------------------------------ the inspector: typed params
  function namesFor(param, scope) {
    const c = b.cellNames || {};
    const variables = scope.map((v) => `{${v}}`);  // inside a loop or a block: its variables first
    return [...variables, ...namesOfCell(param, c)];
  }
  function namesOfCell(param, c) {
    const kinds = param.kinds || [];
    const ofKind = (items) => items.filter((x) => kinds.length === 0 || kinds.includes(x.kind)).map((x) => x.name);
    switch (param.type) {
      case "frame": case "frames": case "target": return ofKind(c.frames || []);
      case "element": return ofKind(c.elements || []);
      case "joint_pose": return [...(c.robot_poses || []), ...(c.joint_poses || []).map((p) => p.name)];
      case "camera": return ["auto", ...(c.cameras || [])];
      case "group": return c.groups || groups();
      default: return [];
    }
  }
  // The unit check the page can do at once (the validator repeats it with the physical bounds).
  function unitProblem(param, value) {
    if (value.trim() === "" || !["number"].includes(param.type)) return null;
    const m = value.trim().match(/^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*([A-Za-z%]*)$/);
    if (!m) return `${param.name}: not a number`;
    const suffix = m[3];
    if (suffix && !(param.unit_suffixes || []).includes(suffix) && suffix !== "%") {
      return `${param.name}: unit '${suffix}' does not fit ${param.unit || "a plain number"} (use ${(param.unit_suffixes || []).join(", ") || "no unit"})`;
    }
    return null;
  }
  function paramValues(call, spec) {
    const values = spec.params.map(() => "");
    if (!call) return values;
    const named = call.params.some((p) => p.name);
    call.params.forEach((p, i) => {
      const index = named && p.name ? spec.params.findIndex((s) => s.name === p.name) : i;
      if (index >= 0 && index < values.length) values[index] = p.value;
    });
    return values;
  }
  function writeParams(call, spec, values) {
    const named = call.params.some((p) => p.name);
    let last = -1;
    values.forEach((v, i) => { if (v !== "" || spec.params[i].required) last = i; });
    call.params = values.slice(0, last + 1).map((v, i) => ({value: v === "" && spec.params[i].default !== undefined ? spec.params[i].default : v,
                                                          name: named ? spec.params[i].name : null}));
  }
  function renderInspector() {
    const box = $("inspector");
    const row = b.doc && b.selected ? rowOf(b.selected.key) : null;
    if (!row) {
      box.replaceChildren(el("p", {class: "hint", text: "Select a cell of the table (an operation and a group), then pick a function from the catalog or the list here. " +
        "+ for_each, + repeat, + call, + if and + else add a block after the selected row (inside a selected block)."}));
      return;
    }
    const scope = Blocks.scope(row.parents);
    const inScope = scope.length ? el("p", {class: "blk-scope", text: `inside ${row.parents.map((p) => Blocks.kind(p.type).label).join(" › ")}: ${scope.map((v) => `{${v}}`).join(" ")} may be used in ids, names and values`}) : null;
    if (row.kind === "block") {  // its fields again, with room for a call's many params
      const kind = Blocks.kind(row.step.type);
      const fields = el("div", {class: "blk-fields blk-inspector"}, ...Blocks.renderBlock(el, row, {cellNames: b.cellNames, messages: [], where: "inspector",
        edited, changed, redraw: renderInspector}));
      box.replaceChildren(el("h3", {text: kind.label}), fields, el("p", {class: "fn-doc", text: kind.help}), inScope, el("div", {id: "inspector-messages", class: "messages"}));
      renderInspectorMessages();
      return;
    }
    const {group} = b.selected;
    if (!group) { box.replaceChildren(el("h3", {text: `operation ${row.step.id}`}), inScope); return; }
    const operation = row.step;
    const call = operation.calls.find((c) => c.group === group);
    const select = el("select", {id: "fn-select"}, el("option", {value: "", text: "(none: the group waits)"}));
    for (const f of Store.catalog.functions) if (fits(f, group)) select.append(el("option", {value: f.name, text: f.name}));
    if (call && !fnSpec(call.function)) select.append(el("option", {value: call.function, text: `${call.function} (not in the catalog)`}));
    select.value = call ? call.function : "";
    select.addEventListener("change", () => assignFunction(select.value));
    const parts = [el("h3", {text: `operation ${operation.id} · ${group}`}), inScope, el("label", {}, "function ", select)];
    const spec = call && fnSpec(call.function);
    if (spec) {
      parts.push(el("p", {class: "fn-doc", text: spec.doc}));
      const values = paramValues(call, spec);
      spec.params.forEach((param, i) => {
        const listId = `param-list-${i}`;
        const options = param.type === "choice" ? param.choices : param.type === "boolean" ? ["true", "false"] : namesFor(param, scope);
        let input;
        if (param.type === "choice" || param.type === "boolean" || param.type === "group") {
          input = el("select", {id: `param-${i}`, class: "param-input", "data-param": i},
            el("option", {value: "", text: param.required ? "(choose)" : `(default ${param.default})`}), ...options.map((o) => el("option", {value: o, text: o})));
          if (values[i] && !options.includes(values[i])) input.append(el("option", {value: values[i], text: values[i]}));
        } else {
          input = el("input", {id: `param-${i}`, class: "param-input", "data-param": i, list: listId,
            placeholder: param.required ? "required" : `default ${param.default}`});
        }
        input.value = values[i];
        const problem = el("div", {class: "unit-problem", id: `param-problem-${i}`});
        const check = () => { const p = unitProblem(param, input.value); problem.textContent = p || ""; input.classList.toggle("bad", !!p); };
        input.addEventListener(input.tagName === "SELECT" ? "change" : "input", () => {
          values[i] = input.value;
          writeParams(call, spec, values);
          check();
          edited();
        });
        check();
        const unit = param.unit ? ` [${param.unit}; ${(param.unit_suffixes || []).join(" ")}]` : "";
        const range = param.minimum !== undefined || param.maximum !== undefined ? ` range ${param.minimum ?? ""}..${param.maximum ?? ""}` : "";
        parts.push(el("div", {class: "param"}, el("label", {for: `param-${i}`, text: `${param.name} (${param.type}${unit}${range})`}), input,
          el("datalist", {id: listId}, ...options.map((o) => el("option", {value: o}))), problem,
          el("div", {class: "param-doc", text: param.doc})));
      });
    }
    parts.push(el("div", {id: "inspector-messages", class: "messages"}));
    box.replaceChildren(...parts);
    renderInspectorMessages();
  }
  // Only the messages: a validation answer must not rebuild the inputs the user is typing into.
  function renderInspectorMessages() {
    const box = $("inspector-messages");
    if (!box || !b.selected) return;
    const messages = b.byCell.get(cellKey(b.selected.key, b.selected.group)) || [];
    box.replaceChildren(...messages.map((m) => el("div", {class: `msg ${m.severity}`, text: `line ${m.line}: ${m.message}`})));
  }
  function assignFunction(name) {
    const row = b.selected && rowOf(b.selected.key);
    if (!row || row.kind !== "op" || !b.selected.group) return;
    const {group} = b.selected;
    const operation = row.step;
    const index = operation.calls.findIndex((c) => c.group === group);
    if (!name) { if (index >= 0) operation.calls.splice(index, 1); }
    else {
      const spec = fnSpec(name);
      if (spec && !fits(spec, group)) { $("validation-summary").textContent = `${name} is not for ${group} (groups: ${spec.groups.join(", ")})`; return; }
      const params = spec ? spec.params.filter((p) => p.required).map(() => ({value: "", name: null})) : [];
      const call = {group, function: name, params};
      if (index >= 0) operation.calls[index] = call;
      else {  // keep the robot's group order for new calls
        const order = groups();
        let at = operation.calls.findIndex((c) => order.indexOf(c.group) > order.indexOf(group));
        if (at < 0) at = operation.calls.length;
        operation.calls.splice(at, 0, call);
      }
    }
    renderInspector();
    edited();
  }

  // ------------------------------------------------------------------------------ validation, cell, open, save
  let timer = null;
  function edited() { renderRows(); validateSoon(250); }
  function validateSoon(delay) { clearTimeout(timer); timer = setTimeout(validate, delay); }
  async function validateNow() { clearTimeout(timer); await validate(); }  // before an edit is applied to the paused run (paused_edit.js)
  function current() { return {path: $("doc-path").value.trim() || "untitled.xml", document: b.doc}; }
  async function validate() {
    if (!b.doc) return;
    const ticket = ++b.validating;
    $("validation-summary").textContent = "validating…";
    const started = performance.now();
    const answer = await Store.post("/api/validate", current());
    if (ticket !== b.validating) return;  // a newer edit is being validated
    b.lastValidationMs = performance.now() - started;
    if (b.firstValidatedAt === undefined) b.firstValidatedAt = performance.now();  // since navigation (bench/studio_page.py)
    if (answer.error) { $("validation-summary").textContent = answer.error; return; }
    showMessages(answer.messages || [], answer.ok);
  }
  function showMessages(messages, ok) {
    b.messages = messages;
    b.valid = ok;
    b.byCell = new Map();
    const keyOf = (m) => Array.isArray(m.step) ? m.step.join(".") : (m.operation !== null && m.operation !== undefined && b.view.leaves[m.operation] ? b.view.leaves[m.operation].key : null);
    for (const m of messages) {
      const at = keyOf(m);
      if (at === null) continue;
      const key = cellKey(at, m.group);
      if (!b.byCell.has(key)) b.byCell.set(key, []);
      b.byCell.get(key).push(m);
    }
    const errors = messages.filter((m) => m.severity === "error").length;
    const unheld = (b.doc && b.doc.unheld) || [];  // what the file holds that the builder does not: the server refuses edits
    const summary = $("validation-summary");
    summary.textContent = ok ? (messages.length ? `valid (${messages.length} warning(s))` : "valid") : `${errors} error(s)`;
    summary.className = `summary ${ok ? "ok" : "bad"}`;
    $("app-messages").replaceChildren(...(unheld.length ? [el("div", {class: "msg warning unheld", text: `this file holds ${unheld.join(", ")}, which the builder does not hold: it is shown without them, and checked, run and saved only unchanged; edit it as text`})] : []), ...messages.map((m) => {
      const at = keyOf(m), row = at !== null ? rowOf(at) : null;
      const where = row ? (row.kind === "op" ? `operation ${row.step.id}${m.group ? ` · ${m.group}` : ""}` : `${Blocks.kind(row.step.type).label} (step ${at.split(".").map((i) => Number(i) + 1).join(".")})`) : m.file;
      return el("div", {class: `msg ${m.severity}`, onclick: () => { if (row) { scrollTo(at); selectKey(at, m.group); } }},
        `${where} (line ${m.line}): ${m.message}`);
    }));
    renderRows();
    renderInspectorMessages();
    document.body.dataset.validated = String(b.validating);
  }
  let cellTimer = null;
  function loadCellNamesSoon() { clearTimeout(cellTimer); cellTimer = setTimeout(loadCellNames, 400); }
  async function loadCellNames() {
    if (!b.doc) return;
    const {path, document: doc} = current();  // the cell's names need the robot and the cell only, not the operations
    const answer = await Store.post("/api/cell", {path, document: {...doc, body: []}});
    b.cellNames = answer.ok ? answer : null;
    if (!$("inspector").contains(document.activeElement)) renderInspector();  // never under the user's typing
  }
  async function open() {
    const answer = await Store.post("/api/open", {path: $("doc-path").value});
    if (!answer.ok) { $("validation-summary").textContent = answer.error; $("validation-summary").className = "summary bad"; return; }
    setDocument(answer.document, answer.path);
  }
  async function save() {
    clearTimeout(timer);  // the save's answer carries the validation: an edit's validation still to come would overwrite "saved"
    b.validating++;
    const answer = await Store.post("/api/save", current());
    if (answer.error) { $("validation-summary").textContent = answer.error; $("validation-summary").className = "summary bad"; return; }
    showMessages(answer.messages || [], answer.ok);
    const summary = $("validation-summary");
    summary.textContent = answer.ok ? `saved ${answer.path}` : `not saved: ${summary.textContent}`;
    summary.className = `summary ${answer.ok ? "ok" : "bad"}`;
  }
  function fresh() {
    const robot = b.doc ? b.doc.robot : Object.keys(Store.catalog.robots)[0];
    setDocument({name: "new_application", robot, cell: b.doc ? b.doc.cell : null, version: null, description: null, error_policy: null,
                 body: [{type: "operation", id: "1", name: null, calls: [], comments: []}], header: [], trailer: []}, $("doc-path").value);
  }

  Store.on("catalog", async () => {
    renderCatalog();
    bindAppFields();
    $("ops-scroll").addEventListener("scroll", renderRows);
    $("add-op").addEventListener("click", addOperation);
    $("add-for-each").addEventListener("click", () => addStep("for_each"));
    $("add-repeat").addEventListener("click", () => addStep("repeat"));
    $("add-call").addEventListener("click", () => addStep("call"));
    $("add-if").addEventListener("click", () => addStep("if"));
    $("add-else").addEventListener("click", () => addStep("else"));
    $("open-btn").addEventListener("click", open);
    $("save-btn").addEventListener("click", save);
    $("new-btn").addEventListener("click", fresh);
    const start = await Store.get("/api/document");
    if (start.document) setDocument(start.document, start.path);
    else { $("doc-path").value = start.path || ""; fresh(); if (start.error) $("validation-summary").textContent = start.error; }
    requestAnimationFrame(() => setTimeout(() => {  // after the frame that paints the table (bench/studio_page.py)
      b.shownAt = performance.now();
      document.body.dataset.ready = "true";
    }));
  });
  Store.on("view", (view) => { if (view === "builder") renderRows(); });
  return {current, showMessages, select, scrollTo, validateNow, state: b};
})();
