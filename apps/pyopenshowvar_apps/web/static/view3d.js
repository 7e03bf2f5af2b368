// kvp web: a small 3D view of the arm on a 2D canvas (perspective projection, painter's order).
//
// The server sends the frame of every joint from the kinematics (D-H frames 0..5, the flange
// and the TCP), each as x axis, y axis, z axis and origin in mm. A D-H step runs along the
// previous z axis (d) and then along the new x axis (a), so the arm's skeleton is the chain
// o0, foot of o1 on z0, o1, foot of o2 on z1, ... and needs no robot-specific geometry here.
// Every size here is the KR 6 R900 sixx's; setArm scales them to the arm the server draws (its
// reach), so a KR 560 fills the view as a KR 6 does.
// Drag to orbit, wheel or pinch to zoom, double-click to reset.
"use strict";

const V = {
  add: (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]],
  sub: (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]],
  mul: (a, s) => [a[0] * s, a[1] * s, a[2] * s],
  dot: (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2],
  cross: (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]],
  norm: (a) => { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; },
};

// Link radii (mm) from the base outwards; the last ones repeat.
const RADII = [75, 60, 55, 45, 40, 32, 28, 22];
const HOME_VIEW = { yaw: -0.9, pitch: 0.38, dist: 2000 };
// The KR 6's reach (mm, A2 to the wrist centre) that the sizes above were chosen for.
const KR6_REACH = 876.5;

class ArmView {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.frames = null;
    this.k = 1;  // the arm's size over the KR 6's
    this.arm = "";
    Object.assign(this, HOME_VIEW);
    this.target = [220, 0, 420];
    this.pointers = new Map();
    this.dirty = true;
    this._bind();
    const loop = () => { if (this.dirty) this.draw(); requestAnimationFrame(loop); };
    requestAnimationFrame(loop);
  }

  setFrames(frames) { this.frames = frames; this.dirty = true; }

  // The arm drawn changed (model name and reach in mm): rescale the view to it.
  setArm(name, reach) {
    if (name === this.arm || !(reach > 0)) return;
    this.arm = name;
    this.k = reach / KR6_REACH;
    Object.assign(this, HOME_VIEW);
    this.dist = HOME_VIEW.dist * this.k;
    this.target = [220 * this.k, 0, 420 * this.k];
    this.dirty = true;
  }

  _bind() {
    const c = this.canvas;
    c.addEventListener("pointerdown", (e) => { c.setPointerCapture(e.pointerId); this.pointers.set(e.pointerId, [e.clientX, e.clientY]); });
    const end = (e) => this.pointers.delete(e.pointerId);
    c.addEventListener("pointerup", end);
    c.addEventListener("pointercancel", end);
    c.addEventListener("pointermove", (e) => {
      const old = this.pointers.get(e.pointerId);
      if (!old) return;
      if (this.pointers.size === 1) {
        this.yaw -= (e.clientX - old[0]) * 0.01;
        this.pitch = Math.max(-0.2, Math.min(1.5, this.pitch + (e.clientY - old[1]) * 0.01));
      } else if (this.pointers.size === 2) {
        const other = [...this.pointers.entries()].find(([id]) => id !== e.pointerId)[1];
        const before = Math.hypot(old[0] - other[0], old[1] - other[1]);
        const after = Math.hypot(e.clientX - other[0], e.clientY - other[1]);
        if (before > 0 && after > 0) this._zoom(before / after);
      }
      this.pointers.set(e.pointerId, [e.clientX, e.clientY]);
      this.dirty = true;
    });
    c.addEventListener("wheel", (e) => { e.preventDefault(); this._zoom(Math.exp(e.deltaY * 0.001)); }, { passive: false });
    c.addEventListener("dblclick", () => { Object.assign(this, HOME_VIEW); this.dist *= this.k; this.dirty = true; });
  }

  _zoom(f) { this.dist = Math.max(800 * this.k, Math.min(8000 * this.k, this.dist * f)); this.dirty = true; }

  _camera(w, h) {
    const cp = Math.cos(this.pitch);
    const eye = V.add(this.target, V.mul([cp * Math.cos(this.yaw), cp * Math.sin(this.yaw), Math.sin(this.pitch)], this.dist));
    const fwd = V.norm(V.sub(this.target, eye));
    const right = V.norm(V.cross(fwd, [0, 0, 1]));
    const up = V.cross(right, fwd);
    const f = 0.9 * Math.min(w, h * 1.3);
    return (p) => {
      const d = V.sub(p, eye);
      const z = Math.max(V.dot(d, fwd), 1);
      return { x: w / 2 + (f * V.dot(d, right)) / z, y: h * 0.52 - (f * V.dot(d, up)) / z, z, s: f / z };
    };
  }

  _skeleton() {
    const fr = this.frames.map((f) => ({ x: f.slice(0, 3), y: f.slice(3, 6), z: f.slice(6, 9), o: f.slice(9, 12) }));
    const pts = [fr[0].o];
    for (let i = 1; i < fr.length; i++) {
      const prev = fr[i - 1];
      const foot = V.add(prev.o, V.mul(prev.z, V.dot(V.sub(fr[i].o, prev.o), prev.z)));
      pts.push(foot, fr[i].o);
    }
    return { fr, pts };
  }

  draw() {
    this.dirty = false;
    const c = this.canvas, dpr = window.devicePixelRatio || 1;
    const w = c.clientWidth, h = c.clientHeight;
    if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
      c.width = Math.round(w * dpr); c.height = Math.round(h * dpr);
    }
    const g = this.ctx;
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, w, h);
    const P = this._camera(w, h);
    this._floor(g, P);
    if (!this.frames) return;
    const { fr, pts } = this._skeleton();
    // Links as capsules, far ones first; shade by depth so overlapping links read in 3D.
    const items = [];
    let k = 0;
    for (let i = 1; i < pts.length; i++) {
      if (Math.hypot(...V.sub(pts[i], pts[i - 1])) < 1) continue;
      const a = P(pts[i - 1]), b = P(pts[i]);
      items.push({ z: (a.z + b.z) / 2, a, b, r: this.k * RADII[Math.min(k++, RADII.length - 1)] });
    }
    for (let j = 0; j < 6; j++) {  // the joint housings, along their axes
      const o = fr[j].o, ax = fr[j].z, r = this.k * RADII[Math.min(j + 1, RADII.length - 1)] * 1.15;
      const a = P(V.add(o, V.mul(ax, -r))), b = P(V.add(o, V.mul(ax, r)));
      items.push({ z: (a.z + b.z) / 2 - 1, a, b, r, joint: true });
    }
    const zs = items.map((it) => it.z), zmin = Math.min(...zs), zmax = Math.max(...zs);
    items.sort((p, q) => q.z - p.z);
    g.lineCap = "round";
    for (const it of items) {
      const t = zmax > zmin ? (it.z - zmin) / (zmax - zmin) : 0;
      const light = 62 - 22 * t;
      g.strokeStyle = it.joint ? `hsl(210 8% ${light - 18}%)` : `hsl(26 100% ${light - 8}%)`;
      g.lineWidth = Math.max(2, 2 * it.r * ((it.a.s + it.b.s) / 2));
      g.beginPath(); g.moveTo(it.a.x, it.a.y); g.lineTo(it.b.x, it.b.y); g.stroke();
    }
    this._triad(g, P, fr[fr.length - 1], 120 * this.k, 2.5);
    this._triad(g, P, { o: [0, 0, 0], x: [1, 0, 0], y: [0, 1, 0], z: [0, 0, 1] }, 200 * this.k, 1.5);
    const tcp = P(fr[fr.length - 1].o);
    g.fillStyle = "#fff";
    g.beginPath(); g.arc(tcp.x, tcp.y, 3.5, 0, 2 * Math.PI); g.fill();
  }

  _floor(g, P) {
    g.lineWidth = 1;
    g.strokeStyle = "rgba(255,255,255,0.09)";
    const e = 1200 * this.k;
    for (let i = -6; i <= 6; i++) {
      const v = (i * e) / 6;
      for (const [a, b] of [[[v, -e, 0], [v, e, 0]], [[-e, v, 0], [e, v, 0]]]) {
        const pa = P(a), pb = P(b);
        g.beginPath(); g.moveTo(pa.x, pa.y); g.lineTo(pb.x, pb.y); g.stroke();
      }
    }
    g.fillStyle = "rgba(120,130,140,0.55)";
    g.beginPath();
    for (let i = 0; i <= 32; i++) {
      const t = (i / 32) * 2 * Math.PI, r = 160 * this.k, p = P([r * Math.cos(t), r * Math.sin(t), 0]);
      if (i === 0) g.moveTo(p.x, p.y); else g.lineTo(p.x, p.y);
    }
    g.fill();
  }

  _triad(g, P, f, len, width) {
    const o = P(f.o);
    g.lineWidth = width;
    for (const [axis, color] of [[f.x, "#ff5555"], [f.y, "#55dd55"], [f.z, "#5599ff"]]) {
      const e = P(V.add(f.o, V.mul(axis, len)));
      g.strokeStyle = color;
      g.beginPath(); g.moveTo(o.x, o.y); g.lineTo(e.x, e.y); g.stroke();
    }
  }
}

window.ArmView = ArmView;
