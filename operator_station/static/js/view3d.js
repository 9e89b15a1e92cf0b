// The 3D view: the robot from the URDF its bridge publishes, moving with the joint states, the cell from the
// cell model, frames on demand, each group's current goal and path, the frames vision located beside the
// nominal ones, and the dry run's findings placed on the robot (a collision's two bodies highlighted, an
// unreachable target marked), each at its moment: the finding list beside the view puts the robot where the dry run
// had it at that finding's instant (its joints, kept by the dry run) or a run's fault at its time on the slider.  Everything is drawn at the store's cursor (Store.now()) from the store's joint
// samples and records and the scene's goals (GET /api/scene3d/events), so the time slider of a replay moves it
// as it moves the other views.  The scene is kept light: one geometry and material per kind of thing, shared;
// objects made once and moved; rendering only when something changed, in requestAnimationFrame.
"use strict";

const View3D = (() => {
  const {THREE} = Vendor3D;
  const Geo = View3DGeometry;
  const $ = (id) => document.getElementById(id);
  const state = {
    scene: null, run: -1, robots: [], cell: null, events: [], eventRun: -1, fetching: false, fetchAgain: false,
    findings: [], selected: null, highlighted: [], showFrames: false, tcpFrames: [], dirty: true, visible: false, ready: false,
    ends: {}, recorded: null, recordedRun: -1, tcpCache: new Map(), renderMs: [], intervals: [], lastFrame: null, frameCount: 0, error: null,
  };
  let renderer = null, camera = null, controls = null, world = null, robotsRoot = null, cellRoot = null, marks = null, frameRoot = null;
  const UP = new THREE.Vector3(0, 0, 1);

  // ------------------------------------------------------------------ set-up
  function init() {
    const box = $("view3d-canvas");
    try {
      renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
    } catch (error) {
      state.error = `the 3D view needs WebGL: ${error.message}`;
      box.textContent = state.error;
      return;
    }
    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    box.append(renderer.domElement);
    world = new THREE.Scene();
    world.background = new THREE.Color(0xf4f5f7);
    camera = new THREE.PerspectiveCamera(45, 1, 0.01, 50);
    camera.up.set(0, 0, 1);  // the cell's world: z up (REP 103)
    camera.position.set(1.7, -1.3, 1.1);
    controls = new Vendor3D.OrbitControls(camera, renderer.domElement);
    controls.target.set(0.3, 0, 0.1);
    controls.addEventListener("change", () => { state.dirty = true; });
    world.add(new THREE.HemisphereLight(0xffffff, 0x8d8d99, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(1, -2, 3);
    world.add(sun);
    const grid = new THREE.GridHelper(3, 30, 0xb0b4bb, 0xd5d8dd);
    grid.rotation.x = Math.PI / 2;
    grid.name = "floor grid";
    world.add(grid);
    robotsRoot = new THREE.Group(); cellRoot = new THREE.Group(); marks = new THREE.Group(); frameRoot = new THREE.Group();
    frameRoot.visible = false;
    world.add(robotsRoot, cellRoot, marks, frameRoot);
    Geo.init(marks);
    new ResizeObserver(resize).observe(box);
    $("view3d-frames").addEventListener("change", (e) => {
      state.showFrames = frameRoot.visible = e.target.checked;
      for (const f of state.tcpFrames) f.visible = state.showFrames;
      state.dirty = true;
    });
    $("view3d-fit").addEventListener("click", fit);
    $("view3d-slider").addEventListener("input", (e) => { state.selected = null; Store.setCursor(Number(e.target.value)); });
    $("view3d-live").addEventListener("click", () => { state.selected = null; Store.setCursor(null); });
    requestAnimationFrame(tick);
  }

  function resize() {
    const box = $("view3d-canvas");
    const w = box.clientWidth, h = box.clientHeight;
    if (!renderer || !w || !h) return;
    renderer.setSize(w, h, false);
    renderer.domElement.style.width = "100%";
    renderer.domElement.style.height = "100%";
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    state.dirty = true;
  }

  // Frame the robots and the cell: the camera in front of the robot, to its left and above, looking at the
  // middle between the robot and the cell's things (where the work is).
  function fit() {
    const robots = new THREE.Box3().setFromObject(robotsRoot), cell = new THREE.Box3().setFromObject(cellRoot);
    const bounds = robots.clone().union(cell);
    if (bounds.isEmpty()) return;
    const centre = bounds.getCenter(new THREE.Vector3());
    if (!cell.isEmpty()) centre.lerp(cell.getCenter(new THREE.Vector3()), 0.5);
    const size = Math.max(0.4, bounds.getSize(new THREE.Vector3()).length());
    controls.target.copy(centre);
    camera.position.copy(centre).add(new THREE.Vector3(0.85, 0.5, 0.8).normalize().multiplyScalar(0.85 * size));
    controls.update();
    const floor = world.getObjectByName("floor grid");
    floor.position.set(centre.x, centre.y, bounds.min.z);  // the floor under the lowest solid, not through the cell
    state.dirty = true;
  }

  // ------------------------------------------------------------------ the scene of the run
  async function loadScene() {
    if (!Store.connected) return;  // the station is gone (or not yet there): its feed's snapshot asks again
    let answer;
    try { answer = await Store.get("/api/scene3d"); } catch (e) { return; }
    if (!answer || !answer.ok) return;
    state.scene = answer;
    if (answer.run !== state.run) {
      state.run = answer.run;
      buildRobots(answer.robots);
      state.cell = answer.cell;
      buildCell(answer.cell);
      state.events = []; state.eventRun = answer.run; state.tcpCache.clear();
      fit();
    } else if (answer.cell && (!state.cell || JSON.stringify(answer.cell) !== JSON.stringify(state.cell))) {
      state.cell = answer.cell;
      buildCell(answer.cell);
    }
    if (answer.recorded_joints && (!state.recorded || state.recordedRun !== answer.run)) await loadJoints(answer.run);
    else if (!answer.recorded_joints) state.recorded = null;
    const before = state.selected !== null ? state.findings[state.selected] : null;
    state.findings = answer.findings || [];
    state.selected = pickFinding(before);
    $("view3d-notes").textContent = (answer.notes || []).join(" · ");
    state.ready = true;
    await loadEvents();
    update();
  }

  async function loadJoints(run) {
    const recorded = {names: [], samples: []};
    for (let guard = 0; guard < 10000; guard++) {
      const answer = await Store.get(`/api/scene3d/joints?from=${recorded.samples.length}`);
      if (!answer || !answer.ok || answer.run !== run) return;
      recorded.names = answer.names;
      for (const row of answer.samples) recorded.samples.push(row);
      if (recorded.samples.length >= answer.total || !answer.samples.length) break;
    }
    state.recorded = recorded; state.recordedRun = run;
  }

  async function loadEvents() {
    if (!Store.connected) return;
    if (state.fetching) { state.fetchAgain = true; return; }
    state.fetching = true;
    try {
      for (let guard = 0; guard < 1000; guard++) {  // a batch at a time, until the page has them all
        const answer = await Store.get(`/api/scene3d/events?from=${state.events.length}`);
        if (!answer || !answer.ok) break;
        if (answer.run !== state.eventRun) { state.events = []; state.eventRun = answer.run; state.tcpCache.clear(); if (answer.from !== 0) continue; }
        for (const e of answer.events) state.events.push(e);
        if (state.events.length >= answer.total || !answer.events.length) break;
      }
    } finally {
      state.fetching = false;
    }
    if (state.fetchAgain) { state.fetchAgain = false; await loadEvents(); }
  }

  function buildRobots(robots) {
    for (const r of state.robots) robotsRoot.remove(r.holder);
    state.robots = [];
    const loader = new Vendor3D.URDFLoader();
    loader.parseCollision = false;
    for (const info of robots || []) {
      const model = loader.parse(info.urdf);
      const holder = new THREE.Group();
      Geo.place(holder, info.base);
      holder.add(model);
      holder.name = `robot ${info.name}`;
      robotsRoot.add(holder);
      const materials = new Map();
      model.traverse((node) => {
        if (!node.isMesh) return;
        const colour = node.material && node.material.color ? node.material.color.getHex() : 0xbfc4cc;
        if (!materials.has(colour)) materials.set(colour, new THREE.MeshStandardMaterial({color: colour, roughness: 0.6, metalness: 0.1}));
        if (node.material) node.material.dispose();
        node.material = materials.get(colour);  // one material per colour, shared by every link of that colour
        node.userData.own = node.material;
      });
      state.robots.push({info, model, holder});
    }
    state.tcpFrames = Geo.robotFrames(frameRoot, state.robots);
    state.dirty = true;
  }

  function buildCell(cell) {
    Geo.buildCell(cellRoot, frameRoot, cell, state.robots);
    state.dirty = true;
  }

  // ------------------------------------------------------------------ at the cursor
  // The joints at ``t``: a replayed recording's joint states (every one it has), else the feed's samples.
  const joints = () => state.recorded || Store.joints;
  function sampleAt(t) {
    const samples = joints().samples;
    if (!samples.length) return null;
    if (Store.cursor === null && !state.recorded) return samples[samples.length - 1];
    let lo = 0, hi = samples.length - 1;
    if (samples[0][0] > t) return null;
    while (lo < hi) { const mid = (lo + hi + 1) >> 1; if (samples[mid][0] <= t) lo = mid; else hi = mid - 1; }
    return samples[lo];
  }

  // A robot's URDF joint of a name /joint_states carries: the cell's name (its prefix="..." before the URDF's).
  function urdfJoint(r, name) {
    const jp = r.info.joint_prefix || "";
    if (jp && !name.startsWith(jp)) return null;
    return r.model.joints[name.slice(jp.length)] || null;
  }

  // The joints the records report (a replayed trace has no joint states: the motions' results).
  function setJoints(names, values) {
    for (const r of state.robots) {
      for (let i = 0; i < names.length; i++) {
        const joint = urdfJoint(r, names[i]);
        const value = values[i];
        if (joint && typeof value === "number" && value === value && joint.jointType !== "fixed") joint.setJointValue(value);
      }
    }
  }

  // A finding's joints (the collision model's names: ``member/joint`` in a cell of several robots) on each robot.
  function setFindingJoints(joints) {
    for (const r of state.robots) {
      const prefix = r.info.prefix || "";
      const names = [], values = [];
      for (const [name, value] of Object.entries(joints)) {
        if (prefix && !name.startsWith(prefix)) continue;
        names.push(name.slice(prefix.length)); values.push(value);
      }
      for (let i = 0; i < names.length; i++) {
        const joint = r.model.joints[names[i]] || urdfJoint(r, names[i]);
        if (joint && typeof values[i] === "number" && values[i] === values[i] && joint.jointType !== "fixed") joint.setJointValue(values[i]);
      }
    }
  }

  // The finding shown at its moment after the findings were read again: the same one as before if it is still there;
  // else, for a refused run (nothing moved: no joint state), the dry run's first collision, then its first with joints.
  function pickFinding(before) {
    const same = (f) => before && f.source === before.source && f.kind === before.kind && f.t === before.t && f.group === before.group;
    const kept = state.findings.findIndex(same);
    if (kept >= 0) return kept;
    if (joints().samples.length) return null;
    const dry = state.findings.map((f, i) => [f, i]).filter(([f]) => f.source === "dry run" && f.joints);
    const first = dry.find(([f]) => f.kind === "collision") || dry[0];
    return first ? first[1] : null;
  }

  // Click on a finding: the view at its moment (a dry run's: the robot at its joints; a run's: the slider at its
  // time, every view with it); on the one shown: back to the robot as it is.
  function select(i) {
    if (i === state.selected || i === null || !state.findings[i]) { state.selected = null; update(); return; }
    state.selected = i;
    const f = state.findings[i];
    if (f.source === "run" && f.t !== null) Store.setCursor(f.t); else update();
  }

  const shown = () => (state.selected !== null ? state.findings[state.selected] || null : null);

  // Before any joint state: where a refused run's dry run started the robot (where it is: nothing moved), else
  // each robot's initial pose (its simulator's start).
  function restPose() {
    const dry = state.scene && state.scene.dry_run;
    if (dry && Object.keys(dry.joints).length) { setJoints(Object.keys(dry.joints), Object.values(dry.joints)); return; }
    for (const r of state.robots) setJoints(Object.keys(r.info.rest || {}), Object.values(r.info.rest || {}));
  }

  function noteEnds(records) {
    for (const r of records) if (r.event === "primitive_end" && typeof r.group === "string") (state.ends[r.group] = state.ends[r.group] || []).push(r.t);
  }

  // Each group's goal at ``t``: its latest goal sent by then whose primitive has not ended by then.
  function goalsAt(t) {
    const latest = {};
    for (let i = 0; i < state.events.length; i++) {
      const e = state.events[i];
      if (e.t > t + 1e-6) break;
      if (e.event === "goal") latest[e.group] = i;
    }
    const out = [];
    for (const [group, i] of Object.entries(latest)) {
      const goal = state.events[i];
      // the primitive before it may end at the very instant the goal is sent (its time rounded through a message
      // stamp: within a microsecond): only a later end ends this one
      if (!(state.ends[group] || []).some((x) => x > goal.t + 1e-6 && x <= t)) out.push([i, goal]);
    }
    return out;
  }

  function locatedAt(t) {
    const byGroup = {};
    for (const e of state.events) { if (e.t > t + 1e-6) break; if (e.event === "located") byGroup[e.group] = e.frames; }
    const out = {};
    for (const frames of Object.values(byGroup)) Object.assign(out, frames);
    return out;
  }

  // Where a refused run's collisions would happen: the cell frames their calls work at, one mark per frame.
  function collisionPlaces(found) {
    const places = (state.scene && state.scene.dry_run && state.scene.dry_run.places) || {};
    const marks = new Map();
    for (const f of found) {
      if (f.source !== "dry run" || f.kind !== "collision") continue;
      for (const p of places[`${f.operation}/${f.group}`] || []) if (!marks.has(p.name)) marks.set(p.name, {kind: "collision", label: `at ${p.name}, ${f.t !== null ? f.t.toFixed(2) + " s" : ""}`, target: p.pose});
    }
    return [...marks.values()];
  }

  function activeFindings(t) {
    return state.findings.filter((f) => f.source === "dry run" || (f.t !== null && f.t <= t));
  }

  function update() {
    if (!world || !state.ready) return;
    const t = Store.now();
    const sample = sampleAt(t);
    const at = shown();
    const moment = at && at.source === "dry run" && at.joints ? at : null;  // the robot where the dry run had it then
    if (moment) { restPose(); setFindingJoints(moment.joints); }
    else if (sample) setJoints(joints().names, sample.slice(1));
    else restPose();
    for (const r of state.robots) r.holder.updateMatrixWorld(true);
    const goals = goalsAt(t).map(([i, goal]) => [goal, Geo.goalPath(i, goal, state, sampleAt(goal.t))]);
    Geo.drawGoals(goals, state);
    Geo.drawLocated(locatedAt(t), state.cell);
    const found = activeFindings(t);
    state.highlighted = Geo.highlight(at && found.includes(at) ? [at] : found, state.robots, cellRoot);
    Geo.drawFindings([...found.filter((f) => f.target), ...collisionPlaces(found)]);
    const dry = state.scene && state.scene.dry_run;
    const note = moment
      ? `Not run: nothing moved. The robot is drawn as the dry run had it ${moment.t.toFixed(2)} s into the run, at this finding; in red the bodies it names, the red mark where their calls work. Click it again for the robot as it is.`
      : dry && !sample && found.some((f) => f.source === "dry run")
        ? "Not run: nothing moved. The robot is drawn where the run would start; click a finding to see the robot at its moment." : "";
    const rows = found.map((f) => {
      const row = Object.assign(document.createElement("div"), {className: "finding" + (f === at ? " shown" : ""), title: f.message || "",
        textContent: `${f.source === "dry run" ? "dry run" : "run"}${f.t !== null ? ` at ${f.t.toFixed(2)} s` : ""}: ${f.kind}: ${f.group} ${f.function}${f.bodies ? ` -- ${f.bodies.map((b) => b.label).join(" and ")}` : f.label ? ` -- ${f.label}` : ""}`});
      row.addEventListener("click", () => select(state.findings.indexOf(f)));
      return row;
    });
    $("view3d-findings").replaceChildren(...(note ? [Object.assign(document.createElement("div"), {className: "finding-note", textContent: note})] : []), ...rows);
    const slider = $("view3d-slider");
    const samples = joints().samples;
    const end = Math.max(Store.records.length ? Store.records[Store.records.length - 1].t : 0, samples.length ? samples[samples.length - 1][0] : 0);
    slider.max = String(end);
    if (Store.cursor !== null) slider.value = String(Store.cursor); else slider.value = String(end);
    $("view3d-time").textContent = moment ? `dry run ${moment.t.toFixed(2)} s` : `${Store.cursor === null ? "live" : "replay"} ${t.toFixed(2)} s`;
    state.dirty = true;
  }

  // ------------------------------------------------------------------ the frame loop
  function tick(now) {
    requestAnimationFrame(tick);
    if (!state.visible || !renderer) { state.lastFrame = null; return; }
    if (state.lastFrame !== null) { state.intervals.push(now - state.lastFrame); if (state.intervals.length > 240) state.intervals.shift(); }
    state.lastFrame = now;
    if (!state.dirty) return;
    state.dirty = false;
    const start = performance.now();
    renderer.render(world, camera);
    state.renderMs.push(performance.now() - start);
    if (state.renderMs.length > 240) state.renderMs.shift();
    state.frameCount++;
    if (state.frameCount % 30 === 0) { const s = stats(); $("view3d-fps").textContent = `${s.render_ms_mean.toFixed(1)} ms/frame`; }
  }

  // The frame times kept (the last 240 frames) and what a frame draws: draw calls, triangles, and the geometries and
  // textures the renderer holds (constant while the scene only moves: nothing is made per frame).
  function stats() {
    const mean = (xs) => xs.length ? xs.reduce((a, x) => a + x, 0) / xs.length : 0;
    const max = (xs) => xs.length ? Math.max(...xs) : 0;
    const info = renderer ? renderer.info : {render: {}, memory: {}};
    return {frames: state.frameCount, render_ms_mean: mean(state.renderMs), render_ms_max: max(state.renderMs),
            interval_ms_mean: mean(state.intervals), fps: state.intervals.length ? 1000 / mean(state.intervals) : 0,
            calls: info.render.calls || 0, triangles: info.render.triangles || 0, geometries: info.memory.geometries || 0, textures: info.memory.textures || 0};
  }

  // Render ``n`` frames back to back (every frame redrawn, the camera turning) and measure them: what the bench reads.
  // ``bare``: with the floor alone (robots, cell and marks hidden), the renderer's own cost, as the bench's baseline.
  function measure(n, bare = false) {
    const shown = [robotsRoot, cellRoot, marks, frameRoot].map((o) => o.visible);
    if (bare) for (const o of [robotsRoot, cellRoot, marks, frameRoot]) o.visible = false;
    const done = (resolve) => { [robotsRoot, cellRoot, marks, frameRoot].forEach((o, i) => { o.visible = shown[i]; }); state.dirty = true; resolve(stats()); };
    return new Promise((resolve) => {
      state.renderMs = []; state.intervals = [];
      let left = n;
      const angle = 2 * Math.PI / Math.max(1, n);
      const step = () => {
        camera.position.applyAxisAngle(UP, angle);
        camera.lookAt(controls.target);
        state.dirty = true;
        if (--left > 0) requestAnimationFrame(step); else requestAnimationFrame(() => done(resolve));
      };
      requestAnimationFrame(step);
    });
  }

  // ------------------------------------------------------------------ wiring
  let pending = null;
  const soon = () => { if (pending === null) pending = requestAnimationFrame(() => { pending = null; update(); }); };
  let reload = null;
  const reloadSoon = () => { if (reload === null) reload = setTimeout(() => { reload = null; loadScene(); }, 200); };
  let lastMessages = "";
  Store.on("snapshot", () => { state.ends = {}; state.run = -1; state.selected = null; reloadSoon(); });  // each (re)connection sends one
  Store.on("records", (records) => {
    noteEnds(records);
    if (records.some((r) => r.event === "error")) reloadSoon();
    loadEvents().then(soon);
  });
  Store.on("state", (snap) => {
    const messages = JSON.stringify((snap && snap.messages) || []);
    if (messages !== lastMessages) { lastMessages = messages; reloadSoon(); }
  });
  Store.on("joints", soon);
  Store.on("cursor", soon);
  Store.on("view", (view) => { state.visible = view === "view3d"; if (state.visible) { resize(); state.dirty = true; } });
  document.addEventListener("DOMContentLoaded", init);

  // What the tests and the benchmark read of the view.
  const api = {
    ready: () => state.ready && state.robots.length > 0,
    run: () => state.run,
    jointValues: () => {
      const out = {};
      for (const r of state.robots) for (const [name, joint] of Object.entries(r.model.joints)) if (joint.jointType !== "fixed") out[name] = joint.angle;
      return out;
    },
    linkPosition: (name) => Geo.linkPosition(state.robots, name),
    tcp: (group) => Geo.tcpPose(state.robots, group),
    colour: (name) => Geo.bodyColour(state.robots, name),
    highlighted: () => state.highlighted.slice(),
    shown: () => { const f = shown(); return f ? {kind: f.kind, source: f.source, t: f.t, bodies: (f.bodies || []).map((b) => b.name), joints: f.joints || null} : null; },
    select: (i) => select(i),
    findings: () => activeFindings(Store.now()).map((f) => ({kind: f.kind, source: f.source, t: f.t, bodies: (f.bodies || []).map((b) => b.name), target: f.target || null})),
    goals: () => goalsAt(Store.now()).map(([, g]) => ({group: g.group, kind: g.kind, label: g.label || "", t: g.t})),
    located: () => Object.keys(locatedAt(Store.now())),
    places: () => collisionPlaces(activeFindings(Store.now())).map((p) => p.label),
    cellObjects: () => Geo.cellNames(),
    look: (eye, target) => { camera.position.set(...eye); controls.target.set(...target); controls.update(); state.dirty = true; },
    frameStats: stats,
    measure,
    error: () => state.error,
    update,
  };
  window.view3d = api;
  return api;
})();
