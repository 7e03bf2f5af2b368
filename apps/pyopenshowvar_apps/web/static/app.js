// kvp web: the live state, the hold-to-move jog pad and the watch list.
//
// Jogging works like a teach pendant's enabling switch: a button held down sends "jog" at
// once and repeats it every 25 ms as a keep-alive; the robot moves only while those arrive.
// Letting go, the pointer leaving the button, the window losing focus, the tab being hidden
// or the page going away all send "release" (and the server stops on its own when the
// keep-alives stop or the connection drops).
"use strict";

const $ = (id) => document.getElementById(id);
const KEEPALIVE_MS = 25;
const AXES = ["A1", "A2", "A3", "A4", "A5", "A6"];
const CART = ["X", "Y", "Z", "A", "B", "C"];
const token = new URLSearchParams(location.hash.slice(1)).get("token")
  || sessionStorage.getItem("kvp-token") || "";
if (token) sessionStorage.setItem("kvp-token", token);
// A token pasted into the address bar changes only the fragment: start again with it.
window.addEventListener("hashchange", () => location.reload());

const ui = { frame: "axis", step: 0, ov: Number(localStorage.getItem("kvp-jog-ov") || 50) };
const stats = { t0: performance.now(), firstState: null, times: [], rate: 0, states: 0 };
window.kvpStats = stats;  // read by the browser test
let ws = null, hello = null, last = null, press = 0, held = null, keepalive = null, reqId = 0;
const view = new ArmView($("view"));

// ---------------------------------------------------------------- connection
function connect() {
  const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws` +
    (token ? `?token=${encodeURIComponent(token)}` : "");
  ws = new WebSocket(url);
  ws.onopen = () => { setConn(true); sendWatch(); };
  ws.onmessage = (ev) => onMessage(JSON.parse(ev.data));
  ws.onclose = (ev) => {
    setConn(false);
    stopHold();
    banner(ev.code === 1006 && !hello ? "refused: open the address printed by kvp web (with its token)"
      : "connection lost, reconnecting…", true);
    hello = null;
    setTimeout(connect, 1000);
  };
}
function send(msg) { if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(msg)); }
function setConn(on) { $("conn").className = "dot" + (on ? " on" : ""); }
function banner(text, bad) {
  const b = $("banner");
  b.hidden = !text; b.textContent = text || ""; b.className = bad ? "bad" : "";
}

function onMessage(m) {
  if (m.t === "hello") { hello = m; banner(""); buildRows(); }
  else if (m.t === "state") onState(m);
  else if (m.t === "refused") { if (held && held.press === m.press) stopHold(); $("jogstate").textContent = "Refused: " + m.reason; }
  else if (m.t === "result") onResult(m);
  else if (m.t === "error") $("jogstate").textContent = "Error: " + m.message;
}

// ---------------------------------------------------------------- live state
function onState(s) {
  const now = performance.now();
  if (stats.firstState === null) stats.firstState = now - stats.t0;
  stats.states++;
  stats.times.push(now);
  while (stats.times.length && now - stats.times[0] > 2000) stats.times.shift();
  stats.rate = stats.times.length > 1 ? (stats.times.length - 1) / ((now - stats.times[0]) / 1000) : 0;
  $("rate").textContent = stats.rate.toFixed(1) + " Hz";
  last = s;
  const link = s.link || {};
  setConn(!!link.connected && ws.readyState === WebSocket.OPEN);
  if (!link.connected) { banner("robot: " + (link.error || "not connected"), true); return; }
  $("access").textContent = link.ewma_ms == null ? "– ms" : `${link.ewma_ms.toFixed(1)} / ${link.max_ms.toFixed(0)} ms`;
  $("robot").textContent = (s.robot || "robot") + (s.model ? " · " + s.model.name : "")
    + (hello && hello.emulated ? " (emulated)" : "");
  const p = s.program || {};
  const prog = $("prog");
  prog.textContent = `${p.name || "no program"} ${(p.state || "").replace("#P_", "")}`;
  prog.className = "chip " + (p.state === "#P_ACTIVE" ? "good" : p.state === "#P_STOP" ? "bad" : "");
  $("mode").textContent = (s.mode_op || "–").replace("#", "");
  const ov = $("ovpro");
  ov.textContent = `OV ${s.ov == null ? "–" : s.ov} %`;
  ov.className = "chip" + (s.ov != null && s.ov < 100 ? " warn" : "");
  $("restart").hidden = !(hello && hello.emulated && p.state === "#P_STOP");
  const warn = p.message ? "robot: " + p.message
    : p.jog_ready ? "jog unavailable: " + p.jog_ready
    : s.ov != null && s.ov < 100 ? `$OV_PRO is ${s.ov} %: the jog runs slower and stops later (100 ms needs 100 %)` : "";
  banner(warn, !!p.message);
  if (s.model) view.setArm(s.model.name, s.model.reach);
  if (s.arm) view.setFrames(s.arm);
  updateRows(s);
  updatePose(s.pose);
  updateTorques(s.torques);
  updateWatch(s.watch || {});
  const j = s.jog || {};
  $("jogstate").textContent = j.active ? (j.mine ? `Jogging ${j.label} at ${j.speed} ${j.unit}` : "Another page is jogging")
    : j.stopped ? "Stopped: " + j.stopped : "Hold a button to move; release to stop.";
  const disabled = !!p.jog_ready || (j.active && !j.mine);
  for (const b of document.querySelectorAll(".jog")) b.disabled = disabled && !b.classList.contains("held");
}

function updatePose(pose) {
  if (!pose) return;
  const f = (k) => (pose[k] == null ? "–" : Number(pose[k]).toFixed("XYZ".includes(k) ? 1 : 2));
  $("pose").textContent = `X ${f("X")}  Y ${f("Y")}  Z ${f("Z")}\nA ${f("A")}  B ${f("B")}  C ${f("C")}  S ${pose.S ?? "–"} T ${pose.T ?? "–"}`;
}

function updateTorques(t) {
  const box = $("torques");
  if (!t) return;
  if (!box.children.length) {
    box.innerHTML = AXES.map((a) => `<span>${a}</span><div class="bar"><b></b></div><span class="mono"></span>`).join("");
  }
  const bars = box.querySelectorAll(".bar b"), vals = box.querySelectorAll("span.mono");
  t.forEach((v, i) => {
    const frac = Math.min(1, Math.abs(v) / 100) * 50;
    bars[i].style.left = (v < 0 ? 50 - frac : 50) + "%";
    bars[i].style.width = frac + "%";
    vals[i].textContent = v.toFixed(1);
  });
}

// ---------------------------------------------------------------- jog pad
function buildRows() {
  const keys = ui.frame === "axis" ? AXES : CART;
  $("rows").innerHTML = keys.map((k) => `
    <div class="row" data-key="${k}">
      <button type="button" class="jog" data-key="${k}" data-dir="-1" aria-label="${k} minus">−</button>
      <div class="mid"><span class="name">${k}</span> <span class="val">–</span>
        <div class="range"><i></i></div></div>
      <button type="button" class="jog" data-key="${k}" data-dir="1" aria-label="${k} plus">+</button>
    </div>`).join("");
  for (const b of document.querySelectorAll(".jog")) bindJog(b);
  if (last) updateRows(last);
}

function updateRows(s) {
  const keys = ui.frame === "axis" ? AXES : CART;
  for (const row of document.querySelectorAll("#rows .row")) {
    const k = row.dataset.key, i = keys.indexOf(k);
    const val = row.querySelector(".val"), range = row.querySelector(".range");
    if (ui.frame === "axis" && s.axes) {
      const q = s.axes[i], lo = s.limits.lo[i], hi = s.limits.hi[i];
      val.textContent = q.toFixed(2) + "°";
      const frac = (q - lo) / (hi - lo);
      range.firstElementChild.style.left = (100 * Math.max(0, Math.min(1, frac))) + "%";
      range.className = "range" + (frac < 0.03 || frac > 0.97 ? " near" : "");
      range.hidden = false;
    } else if (s.pose) {
      const v = s.pose[k];
      val.textContent = v == null ? "–" : Number(v).toFixed(i < 3 ? 1 : 2) + (i < 3 ? " mm" : "°");
      range.hidden = true;
    }
  }
}

function bindJog(b) {
  b.addEventListener("pointerdown", (e) => {
    if (b.disabled || e.button > 0) return;
    e.preventDefault();
    b.setPointerCapture(e.pointerId);
    startHold(b);
  });
  for (const ev of ["pointerup", "pointercancel", "lostpointercapture"]) {
    b.addEventListener(ev, () => { if (held && held.button === b) stopHold("released"); });
  }
  b.addEventListener("pointerleave", () => { if (held && held.button === b) stopHold("pointer left the button"); });
  b.addEventListener("contextmenu", (e) => e.preventDefault());
}

function startHold(b) {
  stopHold("new press");
  press++;
  held = { button: b, press, msg: {
    t: "jog", press, frame: ui.frame, key: b.dataset.key, dir: Number(b.dataset.dir),
    step: ui.step || null, ov: ui.ov } };
  b.classList.add("held");
  send(held.msg);
  keepalive = setInterval(() => { if (held) { held.msg.ov = ui.ov; send(held.msg); } }, KEEPALIVE_MS);
}

function stopHold(why) {
  if (keepalive) { clearInterval(keepalive); keepalive = null; }
  if (!held) return;
  held.button.classList.remove("held");
  held = null;
  if (why) send({ t: "release", why });
}

document.addEventListener("visibilitychange", () => { if (document.visibilityState !== "visible") stopHold("tab hidden"); });
window.addEventListener("blur", () => stopHold("window lost focus"));
window.addEventListener("pagehide", () => stopHold("page closed"));

function segmented(id, attr, apply) {
  for (const b of $(id).querySelectorAll("button")) {
    b.addEventListener("click", () => {
      for (const o of $(id).querySelectorAll("button")) o.classList.toggle("on", o === b);
      apply(b.dataset[attr]);
    });
  }
}
segmented("frames", "frame", (v) => { ui.frame = v; stopHold("frame changed"); buildRows(); });
segmented("steps", "step", (v) => { ui.step = Number(v); });
const ovInput = $("jogov");
ovInput.value = ui.ov;
const showOv = () => { $("jogovout").textContent = ui.ov + " %"; };
ovInput.addEventListener("input", () => { ui.ov = Number(ovInput.value); localStorage.setItem("kvp-jog-ov", ui.ov); showOv(); });
showOv();
$("restart").addEventListener("click", () => send({ t: "restart", id: ++reqId }));

// ---------------------------------------------------------------- watch list
let watch = JSON.parse(localStorage.getItem("kvp-watch") || '["$OV_PRO", "$POS_ACT.X"]');
function saveWatch() { localStorage.setItem("kvp-watch", JSON.stringify(watch)); sendWatch(); renderWatch(); }
function sendWatch() { send({ t: "watch", names: watch }); }
function renderWatch() {
  const body = $("watch").tBodies[0];
  body.innerHTML = "";
  for (const name of watch) {
    const tr = body.insertRow();
    tr.dataset.name = name;
    tr.innerHTML = `<td class="mono"></td><td class="v"></td><td><form><input placeholder="new value" maxlength="1024">` +
      `<button type="submit">Write</button><button type="button" class="x" aria-label="remove">×</button></form></td>`;
    tr.cells[0].textContent = name;
    tr.querySelector("form").addEventListener("submit", (e) => {
      e.preventDefault();
      const input = tr.querySelector("input");
      send({ t: "write", id: ++reqId, name, value: input.value });
    });
    tr.querySelector(".x").addEventListener("click", () => { watch = watch.filter((n) => n !== name); saveWatch(); });
  }
}
function updateWatch(values) {
  for (const tr of $("watch").tBodies[0].rows) {
    const v = values[tr.dataset.name];
    if (!v) continue;
    tr.cells[1].textContent = v.error ? v.error : v.text;
    tr.cells[1].className = "v" + (v.error ? " err" : "");
  }
}
function onResult(m) {
  const stop = m.stop ? ` (the program stopped: ${m.stop})` : "";
  const where = m.error ? `Error: ${m.error}` : `${m.name} = ${m.text}${stop}`;
  $("jogstate").textContent = where;
}
$("watchadd").addEventListener("submit", (e) => {
  e.preventDefault();
  const name = $("watchname").value.trim();
  const max = hello ? hello.max_watch : 16;
  if (name && !watch.includes(name) && watch.length < max) { watch.push(name); saveWatch(); }
  $("watchname").value = "";
});
renderWatch();
buildRows();
connect();
