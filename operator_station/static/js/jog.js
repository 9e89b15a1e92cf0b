// Jog and teach (docs/studio.md, "Jog and teach"): hold a button to move one group, release it to stop;
// teach the TCP's pose as a frame of the cell, shown as a diff, saved only when confirmed.
// The station moves the arm only while this page keeps beating on /ws/jog: a release sends stop, and a page
// that closes, hides or loses its connection stops beating -- the station stops the arm within its lease.
const Jog = (() => {
  const $ = (id) => document.getElementById(id);
  const AXES = ["x", "y", "z", "rx", "ry", "rz"];
  const BEAT_MS = 100;
  const jog = {info: null, socket: null, beat: null, held: null, state: null, plan: null};

  function say(text, bad) {
    const line = $("jog-status");
    line.textContent = text || "";
    line.classList.toggle("bad", !!bad);
  }

  function connect() {
    if (jog.socket && jog.socket.readyState <= 1) return jog.socket;
    const socket = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws/jog`);
    socket.onmessage = (event) => {
      const message = JSON.parse(event.data);
      if (message.type === "answer" && !message.ok) { release(false); say(message.answer, true); }
      if (message.type === "state") {
        jog.state = message.state;
        if (!message.state.moving && message.state.reason) say(message.state.reason, message.state.refused);
        else if (message.state.moving) say("jogging: hold the button; release it to stop");
        showJoints(message.state.joints || {});
        showTcp(message.state.tcp);
      }
    };
    socket.onclose = () => { if (jog.held) { release(false); say("jog stopped: the connection to the station closed", true); } };
    jog.socket = socket;
    return socket;
  }

  function send(message) {
    const socket = connect();
    if (socket.readyState === 1) socket.send(JSON.stringify(message));
    else socket.addEventListener("open", () => socket.send(JSON.stringify(message)), {once: true});
  }

  function press(axis, direction) {
    if (!jog.info) { say("open the jog panel first", true); return; }
    const mode = $("jog-mode").value;
    const speed = Number($("jog-speed").value);
    jog.held = {axis, direction};
    send({type: "start", group: $("jog-group").value, mode, axis, direction, frame: $("jog-frame").value, speed});
    clearInterval(jog.beat);
    jog.beat = setInterval(() => send({type: "beat"}), BEAT_MS);
  }

  function release(tell = true) {
    clearInterval(jog.beat);
    jog.beat = null;
    if (jog.held && tell) send({type: "stop"});
    jog.held = null;
  }

  function button(label, axis, direction) {
    const b = document.createElement("button");
    b.className = "jog-button";
    b.textContent = label;
    b.dataset.axis = axis;
    b.dataset.direction = String(direction);
    b.addEventListener("pointerdown", (event) => { event.preventDefault(); b.setPointerCapture && b.setPointerCapture(event.pointerId); press(axis, direction); });
    for (const end of ["pointerup", "pointercancel", "lostpointercapture"]) b.addEventListener(end, () => release());
    return b;
  }

  function showJoints(joints) {
    for (const [name, value] of Object.entries(joints)) {
      const cell = document.querySelector(`[data-joint-value="${CSS.escape(name)}"]`);
      if (cell) cell.textContent = `${(value * 180 / Math.PI).toFixed(2)}°`;
    }
  }

  function showTcp(tcp) {
    let line = $("jog-tcp");
    if (!line) {  // under the status line: where the TCP is, which is what a teach writes
      line = document.createElement("p");
      line.id = "jog-tcp";
      line.className = "hint";
      $("jog-status").after(line);
    }
    line.textContent = tcp ? `TCP in the world: x ${(tcp[0] * 1000).toFixed(1)} y ${(tcp[1] * 1000).toFixed(1)} z ${(tcp[2] * 1000).toFixed(1)} mm, ` +
      `roll ${(tcp[3] * 180 / Math.PI).toFixed(2)} pitch ${(tcp[4] * 180 / Math.PI).toFixed(2)} yaw ${(tcp[5] * 180 / Math.PI).toFixed(2)}°` : "";
  }

  function render() {
    const pad = $("jog-pad");
    pad.replaceChildren();
    if (!jog.info) return;
    const group = jog.info.groups[$("jog-group").value];
    const cartesian = $("jog-mode").value === "cartesian";
    $("jog-frame").disabled = !cartesian;
    const rows = cartesian ? AXES : group.joints;
    for (const axis of rows) {
      const row = document.createElement("div");
      row.className = "jog-row";
      const name = document.createElement("span");
      name.className = "jog-axis";
      name.textContent = axis;
      const value = document.createElement("span");
      value.className = "jog-value";
      if (!cartesian) value.dataset.jointValue = axis;
      row.append(button("−", axis, -1), name, button("+", axis, 1), value);
      pad.append(row);
    }
    if (jog.state) { showJoints(jog.state.joints || {}); showTcp(jog.state.tcp); }
  }

  async function open() {
    const refused = typeof Audit === "undefined" ? "" : Audit.refuses("engineer");  // an operator: said here, not asked of the station
    if (refused) { jog.info = null; render(); say(`jog: ${refused}`, true); return; }
    const answer = await Store.post("/api/jog/open", Builder.current());
    if (!answer.ok) { jog.info = null; render(); say(answer.error, true); return; }
    jog.info = answer;
    const groups = $("jog-group");
    const chosen = groups.value;
    groups.replaceChildren(...Object.keys(answer.groups).map((g) => new Option(g, g)));
    if (chosen in answer.groups) groups.value = chosen;
    const frames = ["world", "tool", ...answer.frames];
    $("jog-frame").replaceChildren(...frames.map((f) => new Option(f, f)));
    $("teach-parent").replaceChildren(...["world", ...answer.frames].map((f) => new Option(f, f)));
    $("jog-speed").max = String(answer.speed);
    if (Number($("jog-speed").value) > answer.speed || !$("jog-speed").value) $("jog-speed").value = String(answer.speed);
    $("jog-caps").textContent = `at most ${answer.speed} % of the joint limits and ${answer.cartesian_speed} mm/s; ` +
      `stops on release or ${Math.round(answer.lease * 1000)} ms without a heartbeat (${answer.backend}, control period ${answer.period * 1000} ms)`;
    jog.state = answer.state;
    render();
    say(answer.state.reason || "ready: hold a button to move", answer.state.refused);
    connect();
  }

  async function teach() {
    const body = {...Builder.current(), group: $("jog-group").value, name: $("teach-name").value.trim(), parent: $("teach-parent").value};
    const answer = await Store.post("/api/teach", body);
    const diff = $("teach-diff");
    jog.plan = null;
    $("teach-save").disabled = true;
    if (answer.error) { diff.textContent = ""; $("teach-answer").textContent = answer.error; return; }
    diff.replaceChildren(...answer.diff.map((line) => {
      const span = document.createElement("span");
      span.className = line.startsWith("+") && !line.startsWith("+++") ? "add" : line.startsWith("-") && !line.startsWith("---") ? "del" : "";
      span.textContent = line + "\n";
      return span;
    }));
    const moved = answer.moved.length ? ` (${answer.moved.length} frame(s) below it move with it: ${answer.moved.join(", ")})` : "";
    $("teach-answer").textContent = answer.ok ? `${answer.created ? "new" : "updated"} frame ${answer.frame} under ${answer.parent}${moved}: save to write it into ${answer.cell}`
      : `would not validate: ${answer.problems.join("; ")}`;
    if (answer.ok) { jog.plan = answer; $("teach-save").disabled = false; }
  }

  async function save() {
    if (!jog.plan) return;
    const answer = await Store.post("/api/teach/save", {id: jog.plan.id, confirm: true});
    $("teach-save").disabled = true;
    $("teach-answer").textContent = answer.ok ? `saved: ${answer.answer}` : answer.error;
    if (answer.ok) { jog.plan = null; document.body.dataset.taught = answer.frame; open(); }
  }

  document.addEventListener("DOMContentLoaded", () => {
    $("jog-group").addEventListener("change", render);
    $("jog-mode").addEventListener("change", render);
    $("jog-open").addEventListener("click", open);
    $("teach-btn").addEventListener("click", teach);
    $("teach-save").addEventListener("click", save);
    $("teach-cancel").addEventListener("click", () => { jog.plan = null; $("teach-save").disabled = true; $("teach-diff").textContent = ""; $("teach-answer").textContent = "not saved"; });
    // The dead man's other half: a page that is hidden, loses focus or goes away stops beating and says stop.
    document.addEventListener("visibilitychange", () => { if (document.hidden) release(); });
    window.addEventListener("blur", () => release());
    window.addEventListener("pagehide", () => release());
    Store.on("view", (view) => { if (view === "jog") open(); else release(); });
  });
  return {open, press, release, state: jog};
})();
