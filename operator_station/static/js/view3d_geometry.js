// What the 3D view draws besides the robots' links: the cell's solids and frames, the goals and their paths,
// the located frames and the findings -- each from a handful of geometries and materials made once and
// shared, each object made once and then moved (no allocation per frame).
"use strict";

const View3DGeometry = (() => {
  const {THREE} = Vendor3D;
  const MAX_PATH = 202;  // a trajectory goal's points (the server keeps 200) and its start
  const GROUP_COLOURS = [0x1f77b4, 0xff7f0e, 0x2ca02c, 0x9467bd, 0x8c564b, 0xe377c2];
  const KIND_COLOURS = {fixture: 0x8a8f98, tray: 0x4f7cac, zone: 0xf0a030, hole: 0x222222, camera: 0x2a9d8f};
  const unitBox = new THREE.BoxGeometry(1, 1, 1);
  const unitSphere = new THREE.SphereGeometry(1, 16, 12);
  const disc = new THREE.CylinderGeometry(1, 1, 1, 24).rotateX(Math.PI / 2);  // axis along z, as a hole's
  const cone = new THREE.ConeGeometry(0.5, 1, 4).rotateX(-Math.PI / 2).translate(0, 0, 0.5);  // a camera looking along +z
  const axesGeometry = new THREE.BufferGeometry();
  axesGeometry.setAttribute("position", new THREE.Float32BufferAttribute([0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 1], 3));
  axesGeometry.setAttribute("color", new THREE.Float32BufferAttribute([1, 0, 0, 1, 0, 0, 0, 0.7, 0, 0, 0.7, 0, 0, 0, 1, 0, 0, 1], 3));
  const axesMaterial = new THREE.LineBasicMaterial({vertexColors: true, depthTest: false, transparent: true});
  const materials = {};
  const material = (key, make) => materials[key] || (materials[key] = make());
  const solid = (colour, opacity = 1) => material(`solid ${colour} ${opacity}`, () => new THREE.MeshStandardMaterial({color: colour, roughness: 0.7, transparent: opacity < 1, opacity, depthWrite: opacity >= 1}));
  const flat = (colour) => material(`flat ${colour}`, () => new THREE.MeshBasicMaterial({color: colour, depthTest: false, transparent: true}));
  const line = (colour) => material(`line ${colour}`, () => new THREE.LineBasicMaterial({color: colour, depthTest: false, transparent: true}));
  const HIGHLIGHT = new THREE.MeshStandardMaterial({color: 0xe0201b, emissive: 0x901010, roughness: 0.5});
  let marks = null;
  const goalMarks = {};  // group -> {marker, path, label, key}
  const locatedPool = [];
  const findingPool = [];
  let cellObjects = new Map();  // frame name -> its solid
  // A group's colour, the same in every view and run: the Nextage's and a single arm's fixed, any other by its name.
  const FIXED = {left_arm: 0x1f77b4, right_arm: 0xff7f0e, torso_head: 0x2ca02c, arm: 0x9467bd};
  const colourOf = (group) => FIXED[group] ?? GROUP_COLOURS[[...group].reduce((h, c) => (h * 31 + c.charCodeAt(0)) >>> 0, 7) % GROUP_COLOURS.length];

  function init(root) { marks = root; }

  function place(object, pose) {
    object.position.set(pose[0], pose[1], pose[2]);
    object.quaternion.set(pose[3], pose[4], pose[5], pose[6]);
  }

  function axes(size) {
    const a = new THREE.LineSegments(axesGeometry, axesMaterial);
    a.scale.setScalar(size);
    a.renderOrder = 2;
    return a;
  }

  // A name as a sprite: made when a frame or a mark is made, never per frame.
  function label(text, colour = "#1d2330", height = 0.022) {
    const canvas = document.createElement("canvas");
    const ctx = canvas.getContext("2d");
    ctx.font = "28px sans-serif";
    canvas.width = Math.ceil(ctx.measureText(text).width) + 12;
    canvas.height = 38;
    ctx.font = "28px sans-serif";
    ctx.fillStyle = "rgba(255,255,255,0.78)";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    ctx.fillStyle = colour;
    ctx.fillText(text, 6, 29);
    const texture = new THREE.CanvasTexture(canvas);
    texture.colorSpace = THREE.SRGBColorSpace;
    const sprite = new THREE.Sprite(new THREE.SpriteMaterial({map: texture, depthTest: false, transparent: true}));
    sprite.scale.set(height * canvas.width / canvas.height, height, 1);
    sprite.center.set(0, 0);
    sprite.renderOrder = 3;
    sprite.userData.text = text;
    return sprite;
  }

  function dispose(object) {
    object.traverse((n) => { if (n.isSprite) { n.material.map.dispose(); n.material.dispose(); } });
  }

  function clear(group) { for (const child of [...group.children]) { dispose(child); group.remove(child); } }

  const numbers = (text) => (text || "").trim().split(/\s+/).map(Number).filter((x) => Number.isFinite(x));

  // ------------------------------------------------------------------ the cell
  function buildCell(cellRoot, frameRoot, cell, robots) {
    clear(cellRoot);
    for (const child of [...frameRoot.children]) if (child.userData.cell) { dispose(child); frameRoot.remove(child); }
    cellObjects = new Map();
    if (!cell) return;
    let labels = 0;
    for (const f of cell.frames) {
      const holder = new THREE.Group();
      holder.name = f.name;
      place(holder, f.pose);
      const a = f.attributes || {};
      const box = numbers(a.box), offset = numbers(a.box_xyz), size = numbers(a.size);
      let body = null;
      if (f.kind === "zone" && size.length === 3) {
        body = new THREE.Mesh(unitBox, solid(KIND_COLOURS.zone, 0.16));
        body.scale.set(...size);
      } else if (box.length === 3) {
        body = new THREE.Mesh(unitBox, solid(KIND_COLOURS[f.kind] || KIND_COLOURS.fixture));
        body.scale.set(...box);
        if (offset.length === 3) body.position.set(...offset);
      } else if (f.kind === "hole") {
        const d = Number(a.diameter) || 0.005;
        body = new THREE.Mesh(disc, solid(KIND_COLOURS.hole));
        body.scale.set(d / 2, d / 2, 0.002);
      } else if (f.kind === "camera") {
        body = new THREE.Mesh(cone, solid(KIND_COLOURS.camera));
        body.scale.set(0.04, 0.04, 0.05);
      } else {
        body = new THREE.Mesh(unitSphere, solid(0x6b7280));
        body.scale.setScalar(0.004);
      }
      body.name = f.name;
      body.userData.own = body.material;
      holder.add(body);
      cellRoot.add(holder);
      cellObjects.set(f.name, body);
      const frame = new THREE.Group();
      frame.userData.cell = true;
      place(frame, f.pose);
      frame.add(axes(f.kind === "zone" ? 0.03 : 0.025));
      if (labels++ < 400) { const l = label(`${f.name} (${f.kind})`); l.position.set(0.004, 0.004, 0.004); frame.add(l); }
      frameRoot.add(frame);
    }
  }

  // Each robot's base and each arm's TCP among the frames (the TCPs follow the arms: they hang on their links).
  function robotFrames(frameRoot, robots) {
    for (const child of [...frameRoot.children]) if (child.userData.robot) { dispose(child); frameRoot.remove(child); }
    const onLinks = [];
    for (const r of robots) {
      const base = new THREE.Group();
      base.userData.robot = true;
      place(base, r.info.base);
      base.add(axes(0.1), label(`${r.info.name} base`));
      frameRoot.add(base);
      for (const [group, tcp] of Object.entries(r.info.tcps)) {
        const link = r.model.links[tcp.link];
        if (!link) continue;
        const frame = new THREE.Group();
        frame.userData.robot = true;
        place(frame, tcp.tool);
        frame.add(axes(0.05), label(`${group} TCP`));
        frame.visible = frameRoot.visible;
        link.add(frame);  // rides on its link; shown and hidden with the other frames
        onLinks.push(frame);
      }
    }
    return onLinks;
  }

  // ------------------------------------------------------------------ the TCP of a group, for any joint values
  const scratch = new THREE.Matrix4(), scratchTool = new THREE.Matrix4(), scratchQ = new THREE.Quaternion(), scratchV = new THREE.Vector3(), unit = new THREE.Vector3(1, 1, 1);
  function tcpOf(robots, group) {
    for (const r of robots) {
      const tcp = r.info.tcps[group];
      if (!tcp || !r.model.links[tcp.link]) continue;
      return {robot: r, link: r.model.links[tcp.link], tool: tcp.tool};
    }
    return null;
  }
  function tcpMatrix(found, out) {
    found.robot.holder.updateMatrixWorld(true);
    const t = found.tool;
    scratchTool.compose(scratchV.set(t[0], t[1], t[2]), scratchQ.set(t[3], t[4], t[5], t[6]), unit);
    return out.multiplyMatrices(found.link.matrixWorld, scratchTool);
  }
  // The TCP (world) with the robot's joints set to ``names``/``values`` for the moment; the joints are put back.
  // (``names`` as /joint_states carries them: a cell's prefix="..." before the URDF's joint names.)
  function tcpWith(found, names, values) {
    const all = found.robot.model.joints, jp = found.robot.info.joint_prefix || "";
    const joints = names.map((n) => (jp ? (n.startsWith(jp) ? all[n.slice(jp.length)] : null) : all[n]) || null);
    const saved = joints.map((j) => j ? j.angle : null);
    joints.forEach((j, i) => { if (j && typeof values[i] === "number" && values[i] === values[i]) j.setJointValue(values[i]); });
    const m = tcpMatrix(found, new THREE.Matrix4());
    joints.forEach((j, i) => { if (j && saved[i] !== null) j.setJointValue(saved[i]); });
    found.robot.holder.updateMatrixWorld(true);
    return m;
  }
  const poseOf = (m) => { const p = new THREE.Vector3(), q = new THREE.Quaternion(); m.decompose(p, q, new THREE.Vector3()); return [p.x, p.y, p.z, q.x, q.y, q.z, q.w]; };

  // A goal's target pose and its path (world points), worked out once per goal: from where the TCP was when it
  // was sent (the joint sample then) to the target; a trajectory's own points where the goal carries them.
  function goalPath(index, goal, state, startSample) {
    const cached = state.tcpCache.get(index);
    if (cached) return cached;
    const found = tcpOf(state.robots, goal.group);
    const names = state.recorded ? state.recorded.names : Store.joints.names;
    const startValues = startSample ? startSample.slice(1) : [];
    const start = found && startSample ? poseOf(tcpWith(found, names, startValues)) : null;
    let target = null, points = [];
    if (goal.kind === "pose") target = goal.target;
    else if (goal.kind === "joints" && found) {
      const values = goal.relative ? goal.names.map((n, i) => (startValues[names.indexOf(n)] || 0) + goal.positions[i]) : goal.positions;
      target = poseOf(tcpWith(found, goal.names, values));
    } else if (goal.kind === "trajectory" && found) {
      points = goal.points.map((p) => poseOf(tcpWith(found, goal.names, p)));
      target = points[points.length - 1] || null;
    } else if (goal.kind === "waypoints") { points = goal.poses; target = points[points.length - 1] || null; }
    else if (goal.kind === "relative" && start) target = relative(start, goal);
    if (!points.length && start && target) points = [start, target];
    else if (start && points.length) points = [start, ...points];
    const out = {target, points: points.slice(0, MAX_PATH)};
    state.tcpCache.set(index, out);
    return out;
  }

  function relative(start, goal) {
    const s = new THREE.Matrix4().compose(new THREE.Vector3(start[0], start[1], start[2]), new THREE.Quaternion(start[3], start[4], start[5], start[6]), unit);
    const d = goal.delta;
    const dq = new THREE.Quaternion(d[3], d[4], d[5], d[6]);
    if (goal.reference === "tool") return poseOf(s.multiply(new THREE.Matrix4().compose(new THREE.Vector3(d[0], d[1], d[2]), dq, unit)));
    const q = dq.multiply(new THREE.Quaternion(start[3], start[4], start[5], start[6]));
    return [start[0] + d[0], start[1] + d[1], start[2] + d[2], q.x, q.y, q.z, q.w];
  }

  // ------------------------------------------------------------------ goals, located frames, findings
  function goalMark(group) {
    if (goalMarks[group]) return goalMarks[group];
    const colour = colourOf(group);
    const marker = new THREE.Group();
    const ball = new THREE.Mesh(unitSphere, flat(colour));
    ball.scale.setScalar(0.008);
    marker.add(ball, axes(0.04));
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(MAX_PATH * 3), 3));
    const path = new THREE.Line(geometry, line(colour));
    path.frustumCulled = false;
    path.renderOrder = 2;
    marks.add(marker, path);
    return (goalMarks[group] = {marker, path, label: null, key: null});
  }

  function drawGoals(goals, state) {
    const shown = new Set();
    for (const [goal, where] of goals) {
      if (!where.target) continue;
      const mark = goalMark(goal.group);
      shown.add(goal.group);
      place(mark.marker, where.target);
      const positions = mark.path.geometry.attributes.position;
      where.points.forEach((p, i) => positions.setXYZ(i, p[0], p[1], p[2]));
      positions.needsUpdate = true;
      mark.path.geometry.setDrawRange(0, where.points.length);
      const text = `${goal.group}: ${goal.primitive}${goal.label ? ` ${goal.label}` : ""}`;
      if (mark.key !== text) {
        if (mark.label) { dispose(mark.label); mark.marker.remove(mark.label); }
        mark.label = label(text, "#" + colourOf(goal.group).toString(16).padStart(6, "0"));
        mark.label.position.set(0.01, 0.01, 0.01);
        mark.marker.add(mark.label);
        mark.key = text;
      }
      mark.marker.visible = mark.path.visible = true;
    }
    for (const [group, mark] of Object.entries(goalMarks)) if (!shown.has(group)) mark.marker.visible = mark.path.visible = false;
  }

  function pooled(pool, make, n) {
    while (pool.length < n) { const o = make(); marks.add(o); pool.push(o); }
    pool.forEach((o, i) => { o.visible = i < n; });
    return pool;
  }

  // A ball with axes, labelled: a located frame, an unreachable target.  Made once per pool slot.
  function markMaker(material, radius, size) {
    return () => {
      const g = new THREE.Group();
      const ball = new THREE.Mesh(unitSphere, material);
      ball.scale.setScalar(radius);
      g.add(ball, axes(size));
      g.userData.key = null;
      return g;
    };
  }

  // The label of a mark, made again only when its text changes.
  function relabel(g, text, colour, height, offset) {
    if (g.userData.key === text) return;
    if (g.userData.label) { dispose(g.userData.label); g.remove(g.userData.label); }
    g.userData.label = label(text, colour, height);
    g.userData.label.position.set(...offset);
    g.add(g.userData.label);
    g.userData.key = text;
  }

  function drawLocated(frames, cell) {
    const nominal = new Map(((cell && cell.frames) || []).map((f) => [f.name, f.pose]));
    const names = Object.keys(frames);
    pooled(locatedPool, markMaker(flat(0xc026d3), 0.003, 0.03), names.length);
    names.forEach((name, i) => {
      const g = locatedPool[i], pose = frames[name], was = nominal.get(name);
      place(g, pose);
      const mm = was ? ` ${((pose[0] - was[0]) * 1000).toFixed(1)}, ${((pose[1] - was[1]) * 1000).toFixed(1)}, ${((pose[2] - was[2]) * 1000).toFixed(1)} mm` : "";
      relabel(g, `${name} located${mm}`, "#a21caf", 0.016, [0.004, -0.012, 0.0]);
    });
  }

  function drawFindings(found) {
    const targets = found.filter((f) => f.target);
    pooled(findingPool, markMaker(solid(0xe0201b, 0.55), 0.02, 0.05), targets.length);
    targets.forEach((f, i) => {
      place(findingPool[i], f.target);
      relabel(findingPool[i], `${f.kind}: ${f.label || f.group}`, "#b91c1c", 0.022, [0.025, 0, 0.02]);
    });
  }

  // The meshes of one link only (not of the links it carries).
  function linkMeshes(link) {
    const out = [];
    for (const child of link.children) if (!child.isURDFJoint && !child.isURDFLink) child.traverse((n) => { if (n.isMesh) out.push(n); });
    return out;
  }

  function findLink(robots, name) {
    const slash = name.indexOf("/");
    for (const r of robots) {
      if (slash >= 0 && r.info.prefix && name.startsWith(r.info.prefix)) return r.model.links[name.slice(r.info.prefix.length)] || null;
      if (slash < 0 && r.model.links[name]) return r.model.links[name];
    }
    return null;
  }

  // The bodies of every collision found colour red; the others their own colour again.  The names highlighted.
  function highlight(found, robots, cellRoot) {
    const wanted = new Map();
    for (const f of found) for (const b of f.bodies || []) {
      const meshes = b.owner === "cell" ? (cellObjects.has(b.name) ? [cellObjects.get(b.name)] : []) : (() => { const l = findLink(robots, b.name); return l ? linkMeshes(l) : []; })();
      if (meshes.length) wanted.set(b.name, meshes);
    }
    const hot = new Set([...wanted.values()].flat());
    for (const r of robots) r.model.traverse((n) => { if (n.isMesh && n.userData.own) n.material = hot.has(n) ? HIGHLIGHT : n.userData.own; });
    for (const body of cellObjects.values()) body.material = hot.has(body) ? HIGHLIGHT : body.userData.own;
    return [...wanted.keys()];
  }

  // The colour a body is drawn in now (a link's first mesh, a cell object): what the highlight changed.
  function bodyColour(robots, name) {
    const link = findLink(robots, name);
    const mesh = link ? linkMeshes(link)[0] : cellObjects.get(name);
    return mesh ? "#" + mesh.material.color.getHexString() : null;
  }

  function linkPosition(robots, name) {
    const link = findLink(robots, name);
    if (!link) return null;
    link.updateMatrixWorld(true);
    const p = new THREE.Vector3().setFromMatrixPosition(link.matrixWorld);
    return [p.x, p.y, p.z];
  }

  return {init, place, buildCell, robotFrames, goalPath, drawGoals, drawLocated, drawFindings, highlight, linkPosition, bodyColour,
          tcpOf, tcpPose: (robots, group) => { const f = tcpOf(robots, group); return f ? poseOf(tcpMatrix(f, new THREE.Matrix4())) : null; },
          cellNames: () => [...cellObjects.keys()]};
})();
