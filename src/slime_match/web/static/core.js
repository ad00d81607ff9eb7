// slime web: the page's core. Plain JavaScript, no dependencies, in classic scripts that share the page's
// global scope (core.js, viewer.js, jobs.js, tools.js, annotation-store.js, annotate.js, app.js, loaded in that
// order): one canvas shows the two images side by side, each with its own zoom and pan; matches, Slime's
// stage layers and annotations are drawn over them. This file: the state, requests and messages, the pair
// view and the drawing helpers.
"use strict";
const $ = (id) => document.getElementById(id);
const PALETTE = ["#e6194b", "#3cb44b", "#ffe119", "#4363d8", "#f58231", "#911eb4", "#46f0f0", "#f032e6",
  "#bcf60c", "#fabebe", "#008080", "#e6beff", "#9a6324", "#fffac8", "#800000", "#aaffc3", "#808000",
  "#ffd8b1", "#6b8cff", "#808080"];
const SCALE_COLORS = ["#60a5fa", "#f59e0b", "#ef4444", "#22c55e", "#a855f7"];
const LAYER_COLORS = { blocks: "#60a5fa", tiles: "#f59e0b", planes: "#ef4444", superset: "#a855f7",
  fbar: "#22d3ee", ftheta: "#22c55e", tile_matches: "#f472b6", final: "#facc15" };

const S = {
  info: null, tab: "match",
  images: [null, null],          // {root, path} of each image
  imgs: [null, null],            // the loaded HTMLImageElements
  matches: null, selected: null, // the shown matches; the selected keypoint's match indices
  source: null,                  // where the matches came from: {job} or {run, index}
  stages: null, layers: {}, hover: null,  // hover: {layer, label} of the plane or set under the pointer
  job: null, polling: null,
  annotations: new Map(),        // each image pair's annotation, by pairKey (annotation-store.js)
  annot: null,                   // the shown pair's annotation
  fitting: 0,                    // annotation fits asked and not answered yet
  frameTimes: [],
};

// ---------------------------------------------------------------- requests and messages

async function api(url, options = {}) {
  const init = { ...options, headers: { ...(options.headers || {}) } };
  if (init.method && init.method !== "GET") init.headers["X-Slime-Web"] = "1";
  if (init.json !== undefined) {
    init.body = JSON.stringify(init.json);
    init.headers["Content-Type"] = "application/json";
    delete init.json;
  }
  const response = await fetch(url, init);
  const type = response.headers.get("content-type") || "";
  if (!response.ok) {
    let message = `${response.status} ${response.statusText}`;
    if (type.includes("json")) message = (await response.json()).error || message;
    throw new Error(message);
  }
  if (options.raw) return response;
  return type.includes("json") ? response.json() : response.text();
}

function showError(error) {
  const box = $("error");
  box.textContent = String(error && error.message ? error.message : error);
  box.hidden = false;
  clearTimeout(showError.timer);
  showError.timer = setTimeout(() => { box.hidden = true; }, 8000);
}
$("error").addEventListener("click", () => { $("error").hidden = true; });
const guarded = (fn) => (...args) => Promise.resolve().then(() => fn(...args)).catch(showError);
const fmt = (v, d = 1) => (v === null || v === undefined ? "–" : Number(v).toFixed(d));

// ---------------------------------------------------------------- the pair view

class PairView {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.views = [{ s: 1, tx: 0, ty: 0 }, { s: 1, tx: 0, ty: 0 }];
    this.gap = 8;
    this.painters = [];
    this.handler = null;          // {grab, drag, drop, click, hover, leave}
    this.pending = false;
    this.drag = null;
    this.clickUndo = null;        // {time, undo} of the last click: a double-click takes it back
    new ResizeObserver(() => this.resize()).observe(canvas);
    canvas.addEventListener("wheel", (e) => this.onWheel(e), { passive: false });
    canvas.addEventListener("mousedown", (e) => this.onDown(e));
    window.addEventListener("mousemove", (e) => this.onMove(e));
    window.addEventListener("mouseup", (e) => this.onUp(e));
    canvas.addEventListener("mouseleave", () => this.handler && this.handler.leave && this.handler.leave());
    canvas.addEventListener("dblclick", (e) => {  // fits the pane, and takes back the first click's effect
      const pane = this.paneAt(this.local(e)[0]);
      if (this.clickUndo && performance.now() - this.clickUndo.time < 1000) this.clickUndo.undo();
      this.clickUndo = null;
      if (pane >= 0) { this.fit(pane); this.redraw(); }
    });
  }
  get width() { return this.canvas.clientWidth; }
  get height() { return this.canvas.clientHeight; }
  paneWidth() { return (this.width - this.gap) / 2; }
  paneLeft(i) { return i * (this.paneWidth() + this.gap); }
  paneAt(x) {
    if (x >= 0 && x < this.paneWidth()) return 0;
    if (x >= this.paneLeft(1) && x <= this.width) return 1;
    return -1;
  }
  local(e) {
    const r = this.canvas.getBoundingClientRect();
    return [e.clientX - r.left, e.clientY - r.top];
  }
  resize() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(this.width * dpr)), h = Math.max(1, Math.round(this.height * dpr));
    if (this.canvas.width !== w || this.canvas.height !== h) {
      const first = this.canvas.width <= 300;
      this.canvas.width = w; this.canvas.height = h;
      if (first) { this.fit(0); this.fit(1); }
      this.redraw();
    }
  }
  fit(i) {
    const img = S.imgs[i];
    if (!img) return;
    const pw = this.paneWidth(), ph = this.height;
    const s = Math.min(pw / img.naturalWidth, ph / img.naturalHeight) * 0.98;
    // (tx, ty): where the centre of the top-left pixel goes, the origin of the library's coordinates
    this.views[i] = { s, tx: (pw - img.naturalWidth * s + s) / 2, ty: (ph - img.naturalHeight * s + s) / 2 };
  }
  toScreen(i, x, y) {
    const v = this.views[i];
    return [this.paneLeft(i) + x * v.s + v.tx, y * v.s + v.ty];
  }
  toImage(i, sx, sy) {
    const v = this.views[i];
    return [(sx - this.paneLeft(i) - v.tx) / v.s, (sy - v.ty) / v.s];
  }
  zoom(i, factor, sx, sy) {
    const v = this.views[i];
    const s = Math.min(64, Math.max(0.02, v.s * factor));
    const px = sx - this.paneLeft(i);
    v.tx = px - (px - v.tx) * (s / v.s);
    v.ty = sy - (sy - v.ty) * (s / v.s);
    v.s = s;
  }
  onWheel(e) {
    e.preventDefault();
    const [sx, sy] = this.local(e);
    const pane = this.paneAt(sx);
    if (pane < 0) return;
    this.zoom(pane, Math.pow(1.2, -Math.sign(e.deltaY) * Math.min(3, Math.abs(e.deltaY) / 60 || 1)), sx, sy);
    this.redraw();
  }
  onDown(e) {
    if (e.button !== 0) return;
    const [sx, sy] = this.local(e);
    const pane = this.paneAt(sx);
    if (pane < 0) return;
    this.canvas.focus();
    const [x, y] = this.toImage(pane, sx, sy);
    const grabbed = this.handler && this.handler.grab && this.handler.grab(pane, x, y, sx, sy);
    this.drag = { pane, sx, sy, moved: false, grabbed: !!grabbed, tx: this.views[pane].tx, ty: this.views[pane].ty };
    e.preventDefault();
  }
  onMove(e) {
    const [sx, sy] = this.local(e);
    if (this.drag) {
      const d = this.drag;
      if (Math.hypot(sx - d.sx, sy - d.sy) > 3) d.moved = true;
      if (!d.moved) return;
      if (d.grabbed) {
        const [x, y] = this.toImage(d.pane, sx, sy);
        this.handler.drag(d.pane, x, y);
      } else {
        this.views[d.pane].tx = d.tx + sx - d.sx;
        this.views[d.pane].ty = d.ty + sy - d.sy;
      }
      this.redraw();
      return;
    }
    if (e.target !== this.canvas) return;
    const pane = this.paneAt(sx);
    if (pane >= 0 && this.handler && this.handler.hover) {
      const [x, y] = this.toImage(pane, sx, sy);
      this.handler.hover(pane, x, y, sx, sy);
    }
  }
  onUp(e) {
    const d = this.drag;
    this.drag = null;
    if (!d) return;
    const [sx, sy] = this.local(e);
    if (d.grabbed) { if (this.handler.drop) this.handler.drop(d.moved); this.redraw(); return; }
    if (!d.moved && this.handler && this.handler.click && e.detail <= 1) {  // a double-click's second: no click
      const [x, y] = this.toImage(d.pane, sx, sy);
      const undo = this.handler.click(d.pane, x, y, sx, sy, e);
      this.clickUndo = typeof undo === "function" ? { time: performance.now(), undo } : null;
    }
  }
  redraw() {
    if (this.pending) return;
    this.pending = true;
    requestAnimationFrame(() => { this.pending = false; this.draw(); });
  }
  draw() {
    const t0 = performance.now();
    const ctx = this.ctx, dpr = window.devicePixelRatio || 1;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, this.width, this.height);
    for (let i = 0; i < 2; i++) {
      this.inPane(i, () => {
        ctx.fillStyle = "#0b1220";
        ctx.fillRect(this.paneLeft(i), 0, this.paneWidth(), this.height);
        const img = S.imgs[i];
        if (!img) {
          ctx.fillStyle = "#6b7280"; ctx.font = "14px system-ui";
          ctx.fillText(`image ${i}: choose one on the left`, this.paneLeft(i) + 16, 28);
          return;
        }
        const v = this.views[i];
        ctx.imageSmoothingEnabled = v.s < 2;
        ctx.drawImage(img, this.paneLeft(i) + v.tx - v.s / 2, v.ty - v.s / 2, img.naturalWidth * v.s,
          img.naturalHeight * v.s);
      });
    }
    for (const paint of this.painters) paint(ctx, this);
    const ms = performance.now() - t0;
    S.frameTimes.push(ms);
    if (S.frameTimes.length > 200) S.frameTimes.shift();
  }
  inPane(i, fn) {
    const ctx = this.ctx;
    ctx.save();
    ctx.beginPath();
    ctx.rect(this.paneLeft(i), 0, this.paneWidth(), this.height);
    ctx.clip();
    fn();
    ctx.restore();
  }
}

const view = new PairView($("view"));

// ---------------------------------------------------------------- drawing helpers

// how many lines are drawn at most (0: points only): the matches in view are thinned by a stride over their
// index (stable while panning), so that zooming into a region shows all of its matches; points get a budget
// of 4x as many (4000 at least)
function budget() {
  return Math.max(0, parseInt($("max-lines").value, 10) || 0);
}

// matches given as xy0, xy1 arrays of [x, y]; `colorOf(k)` gives the colour of match k
function paintPairs(ctx, v, xy0, xy1, colorOf, options = {}) {
  const n = xy0.length, keep = options.keep;
  const v0 = v.views[0], v1 = v.views[1], left1 = v.paneLeft(1), pw = v.paneWidth(), h = v.height;
  const inView = (x, y) => x >= -4 && x <= pw + 4 && y >= -4 && y <= h + 4;
  const visible = [];
  for (let k = 0; k < n; k++) {
    if (keep && !keep(k)) continue;
    if (inView(xy0[k][0] * v0.s + v0.tx, xy0[k][1] * v0.s + v0.ty)
      || inView(xy1[k][0] * v1.s + v1.tx, xy1[k][1] * v1.s + v1.ty)) visible.push(k);
  }
  const most = options.all ? Infinity : budget();
  let lineStride = most === Infinity ? 1 : Math.max(1, Math.ceil(visible.length / Math.max(most, 1)));
  const pointStride = most === Infinity ? 1 : Math.max(1, Math.ceil(visible.length / (4 * Math.max(most, 1000))));
  lineStride = pointStride * Math.ceil(lineStride / pointStride);  // the lines' matches have their points
  const groups = new Map();
  for (const k of visible) {
    if (k % pointStride !== 0) continue;
    const c = colorOf(k);
    if (!groups.has(c)) groups.set(c, []);
    groups.get(c).push(k);
  }
  if (options.record) S.drawn = { visible: visible.length, lineStride, pointStride };
  const size = options.size || 2.5;
  for (let i = 0; i < 2; i++) {
    const pts = i === 0 ? xy0 : xy1, vi = v.views[i], left = v.paneLeft(i);
    v.inPane(i, () => {
      for (const [c, ks] of groups) {
        ctx.fillStyle = c;
        for (const k of ks) {
          const x = pts[k][0] * vi.s + vi.tx, y = pts[k][1] * vi.s + vi.ty;
          if (inView(x, y)) ctx.fillRect(left + x - size / 2, y - size / 2, size, size);
        }
      }
    });
  }
  if (most === 0 || options.noLines) return;
  ctx.lineWidth = options.lineWidth || 1;
  ctx.globalAlpha = options.alpha || 0.7;
  for (const [c, ks] of groups) {
    ctx.strokeStyle = c;
    ctx.beginPath();
    for (const k of ks) {
      if (k % lineStride !== 0) continue;
      ctx.moveTo(xy0[k][0] * v0.s + v0.tx, xy0[k][1] * v0.s + v0.ty);
      ctx.lineTo(left1 + xy1[k][0] * v1.s + v1.tx, xy1[k][1] * v1.s + v1.ty);
    }
    ctx.stroke();
  }
  ctx.globalAlpha = 1;
}

function paintBoxes(ctx, v, i, boxes, colorOf, width = 1.2) {
  const vi = v.views[i], left = v.paneLeft(i);
  v.inPane(i, () => {
    ctx.lineWidth = width;
    for (let k = 0; k < boxes.length; k++) {
      const [x0, y0, x1, y1] = boxes[k];
      ctx.strokeStyle = colorOf(k);
      ctx.strokeRect(left + x0 * vi.s + vi.tx, y0 * vi.s + vi.ty, (x1 - x0) * vi.s, (y1 - y0) * vi.s);
    }
  });
}

function paintPolygon(ctx, v, i, corners, color, width = 3) {
  const vi = v.views[i], left = v.paneLeft(i);
  v.inPane(i, () => {
    ctx.lineWidth = width;
    ctx.strokeStyle = color;
    ctx.beginPath();
    corners.forEach(([x, y], k) => {
      const sx = left + x * vi.s + vi.tx, sy = y * vi.s + vi.ty;
      if (k === 0) ctx.moveTo(sx, sy); else ctx.lineTo(sx, sy);
    });
    ctx.closePath();
    ctx.stroke();
  });
}

// the segment of the line a x + b y + c = 0 inside a w x h image (pixel centres at integers: its edges are
// at -0.5 and w - 0.5)
function clipLine(l, w, h) {
  const [a, b, c] = l, pts = [], lo = -0.5, hx = w - 0.5, hy = h - 0.5;
  if (Math.abs(b) > 1e-12) for (const x of [lo, hx]) { const y = -(a * x + c) / b; if (y >= lo && y <= hy) pts.push([x, y]); }
  if (Math.abs(a) > 1e-12) for (const y of [lo, hy]) { const x = -(b * y + c) / a; if (x >= lo && x <= hx) pts.push([x, y]); }
  return pts.length >= 2 ? [pts[0], pts[pts.length - 1]] : null;
}
const mul = (M, x, y) => [M[0][0] * x + M[0][1] * y + M[0][2], M[1][0] * x + M[1][1] * y + M[1][2],
  M[2][0] * x + M[2][1] * y + M[2][2]];
const mulT = (M, x, y) => [M[0][0] * x + M[1][0] * y + M[2][0], M[0][1] * x + M[1][1] * y + M[2][1],
  M[0][2] * x + M[1][2] * y + M[2][2]];
function inverse3(M) {
  const [a, b, c] = M[0], [d, e, f] = M[1], [g, h, i] = M[2];
  const A = e * i - f * h, B = -(d * i - f * g), C = d * h - e * g, det = a * A + b * B + c * C;
  if (Math.abs(det) < 1e-15) return null;
  return [[A / det, -(b * i - c * h) / det, (b * f - c * e) / det],
    [B / det, (a * i - c * g) / det, -(a * f - c * d) / det],
    [C / det, -(a * h - b * g) / det, (a * e - b * d) / det]];
}
// where point (x, y) of pane `from` goes in the other pane under H (image 0 -> 1)
function transfer(H, from, x, y) {
  const M = from === 0 ? H : inverse3(H);
  if (!M) return null;
  const p = mul(M, x, y);
  return Math.abs(p[2]) < 1e-12 ? null : [p[0] / p[2], p[1] / p[2]];
}
// the epipolar line in the other pane of point (x, y) of pane `from` (x1^T F x0 = 0)
const epipolar = (F, from, x, y) => (from === 0 ? mul(F, x, y) : mulT(F, x, y));

function paintLine(ctx, v, pane, line, color) {
  const img = S.imgs[pane];
  if (!img || !line) return;
  const seg = clipLine(line, img.naturalWidth, img.naturalHeight);
  if (!seg) return;
  v.inPane(pane, () => {
    const a = v.toScreen(pane, ...seg[0]), b = v.toScreen(pane, ...seg[1]);
    ctx.strokeStyle = color; ctx.lineWidth = 1.5;
    ctx.beginPath(); ctx.moveTo(...a); ctx.lineTo(...b); ctx.stroke();
  });
}
function paintCross(ctx, v, pane, p, color, r = 9) {
  if (!p) return;
  v.inPane(pane, () => {
    const [x, y] = v.toScreen(pane, p[0], p[1]);
    ctx.strokeStyle = color; ctx.lineWidth = 2;
    ctx.beginPath(); ctx.moveTo(x - r, y); ctx.lineTo(x + r, y); ctx.moveTo(x, y - r); ctx.lineTo(x, y + r); ctx.stroke();
    ctx.beginPath(); ctx.arc(x, y, r * 0.55, 0, 2 * Math.PI); ctx.stroke();
  });
}

function nearest(points, x, y, radiusPx, s) {
  let best = -1, bestD = (radiusPx / s) ** 2;
  for (let k = 0; k < points.length; k++) {
    const dx = points[k][0] - x, dy = points[k][1] - y, d = dx * dx + dy * dy;
    if (d < bestD) { bestD = d; best = k; }
  }
  return best;
}
