// kvp universal: the jog pad as the universal input device, and the 3D view of any arm.
//
// The same rules as kvp web's pad: a held button sends "jog" at once and every 25 ms; letting
// go, the pointer leaving, the window losing focus or the tab being hidden send "release".
// Every open page also sends "alive" every 100 ms: the server stops the arm when no page is
// there (a frozen tab, a lost network), in position mode too.
"use strict";

const $ = (id) => document.getElementById(id);
const KEEPALIVE_MS = 25, ALIVE_MS = 100, REF_SCALE = 1963;  // the KR 6's box: the view's scale
const token = new URLSearchParams(location.hash.slice(1)).get("token")
  || sessionStorage.getItem("kvp-token") || "";
if (token) sessionStorage.setItem("kvp-token", token);
window.addEventListener("hashchange", () => location.reload());

// The pad's view, drawing any arm: frames scaled so every arm fills the view like a KR 6,
// and the target as a ring.
class UniversalView extends ArmView {
  setScene(frames, target, scale) {
    const k = REF_SCALE / scale;
    const sc = (f) => f.slice(0, 9).concat(f.slice(9, 12).map((v) => v * k));
    const fr = frames.map(sc);
    while (fr.length < 8) fr.push(fr[fr.length - 1]);  // the view draws at least 6 joints
    this.targetPoint = target ? target.map((v) => v * k) : null;
    this.setFrames(fr);
  }
  draw() {
    super.draw();
    if (!this.targetPoint) return;
    const c = this.canvas, P = this._camera(c.clientWidth, c.clientHeight), p = P(this.targetPoint);
    const g = this.ctx;
    g.strokeStyle = "#58a6ff"; g.lineWidth = 2;
    g.beginPath(); g.arc(p.x, p.y, 7, 0, 2 * Math.PI); g.stroke();
  }
}

let ws = null, hello = null, last = null, held = null, keepalive = null, press = 0;
const ui = { level: 50 };
const view = new UniversalView($("view"));
window.kvpUniversal = { states: 0 };  // read by tests

function connect() {
  const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws` +
    (token ? `?token=${encodeURIComponent(token)}` : "");
  ws = new WebSocket(url);
  ws.onopen = () => { $("conn").className = "dot on"; };
  ws.onmessage = (ev) => onMessage(JSON.parse(ev.data));
  ws.onclose = () => {
    $("conn").className = "dot";
    stopHold();
    banner("connection lost, reconnecting…", true);
    hello = null;
    setTimeout(connect, 1000);
  };
}
function send(msg) { if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(msg)); }
function banner(text, bad) { const b = $("banner"); b.hidden = !text; b.textContent = text || ""; b.className = bad ? "bad" : ""; }
setInterval(() => { if (document.visibilityState === "visible") send({ t: "alive" }); }, ALIVE_MS);

function onMessage(m) {
  if (m.t === "hello") { hello = m; banner(m.input ? "" : "view only: the input is another device"); buildRows(); }
  else if (m.t === "state") onState(m);
  else if (m.t === "refused") { stopHold(); $("padstate").textContent = "Refused: " + m.reason; }
  else if (m.t === "error") $("padstate").textContent = "Error: " + m.message;
}

function fill(select, names, current) {
  if (select.dataset.names !== names.join()) {
    select.innerHTML = names.map((n) => `<option>${n}</option>`).join("");
    select.dataset.names = names.join();
  }
  select.value = current;
}

function onState(s) {
  last = s;
  window.kvpUniversal.states++;
  $("robot").textContent = s.title || s.arm;
  $("backend").textContent = s.backend;
  $("rate").textContent = `${s.rate_hz} Hz`;
  $("solve").textContent = s.solve_ms == null ? "stopped" : `${s.solver} ${s.solve_ms} ms, ${s.error_mm} mm`;
  fill($("arm"), s.arms.length ? s.arms : [s.arm], s.arm);
  $("arm").disabled = !s.switchable;
  fill($("solver"), s.solvers, s.solver);
  for (const b of $("modes").querySelectorAll("button")) b.classList.toggle("on", b.dataset.mode === s.mode);
  if (s.message) banner(s.message, true);
  if (s.frames) view.setScene(s.frames, s.target, s.scale_mm);
  if (s.tip) $("pose").textContent = `tip X ${s.tip[0]}  Y ${s.tip[1]}  Z ${s.tip[2]} mm` +
    (s.target ? `\ntarget X ${s.target[0]}  Y ${s.target[1]}  Z ${s.target[2]}` : "\nstopped");
}

function buildRows() {
  $("rows").innerHTML = ["X", "Y", "Z"].map((k) => `
    <div class="row" data-key="${k}">
      <button type="button" class="jog" data-key="${k}" data-dir="-1" aria-label="${k} minus">−</button>
      <div class="mid"><span class="name">${k}</span></div>
      <button type="button" class="jog" data-key="${k}" data-dir="1" aria-label="${k} plus">+</button>
    </div>`).join("");
  for (const b of document.querySelectorAll(".jog")) {
    b.disabled = !(hello && hello.input);
    b.addEventListener("pointerdown", (e) => {
      if (b.disabled || e.button > 0) return;
      e.preventDefault(); b.setPointerCapture(e.pointerId); startHold(b);
    });
    for (const ev of ["pointerup", "pointercancel", "lostpointercapture", "pointerleave"]) {
      b.addEventListener(ev, () => { if (held && held.button === b) stopHold(); });
    }
    b.addEventListener("contextmenu", (e) => e.preventDefault());
  }
}

function startHold(b) {
  stopHold();
  held = { button: b, msg: { t: "jog", press: ++press, key: b.dataset.key, dir: Number(b.dataset.dir), level: ui.level / 100 } };
  b.classList.add("held");
  send(held.msg);
  keepalive = setInterval(() => { if (held) { held.msg.level = ui.level / 100; send(held.msg); } }, KEEPALIVE_MS);
}
function stopHold() {
  if (keepalive) { clearInterval(keepalive); keepalive = null; }
  if (!held) return;
  held.button.classList.remove("held");
  held = null;
  send({ t: "release" });
}
document.addEventListener("visibilitychange", () => { if (document.visibilityState !== "visible") stopHold(); });
window.addEventListener("blur", stopHold);
window.addEventListener("pagehide", stopHold);

for (const id of ["arm", "solver"]) {
  $(id).addEventListener("change", () => send({ t: "switch", key: id, value: $(id).value }));
}
for (const b of $("modes").querySelectorAll("button")) {
  b.addEventListener("click", () => send({ t: "switch", key: "mode", value: b.dataset.mode }));
}
$("level").addEventListener("input", () => { ui.level = Number($("level").value); $("levelout").textContent = ui.level + " %"; });
buildRows();
connect();
