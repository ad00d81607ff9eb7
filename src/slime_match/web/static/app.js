// slime web: the page. Plain JavaScript, no dependencies: one canvas shows the two images side by side, each
// with its own zoom and pan; matches, Slime's stage layers and annotations are drawn over them.
"use strict";
(() => {
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
    annot: { pairs: [], pending: null, set: 0, selected: -1, history: [], fit: null, fixedH: null,
      cursor: null, model: "H", epiline: null, reprojected: null, fitting: 0, saved: "" },
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
      new ResizeObserver(() => this.resize()).observe(canvas);
      canvas.addEventListener("wheel", (e) => this.onWheel(e), { passive: false });
      canvas.addEventListener("mousedown", (e) => this.onDown(e));
      window.addEventListener("mousemove", (e) => this.onMove(e));
      window.addEventListener("mouseup", (e) => this.onUp(e));
      canvas.addEventListener("mouseleave", () => this.handler && this.handler.leave && this.handler.leave());
      canvas.addEventListener("dblclick", (e) => {
        const pane = this.paneAt(this.local(e)[0]);
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
      if (!d.moved && this.handler && this.handler.click) {
        const [x, y] = this.toImage(d.pane, sx, sy);
        this.handler.click(d.pane, x, y, sx, sy, e);
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

  // ---------------------------------------------------------------- painters

  function paintMatches(ctx, v) {
    if (S.tab === "annotate") return;
    const m = S.matches;
    if (m && $("show-matches").checked && m.count) {
      const hasInliers = Array.isArray(m.inliers);
      const showOut = $("show-outliers").checked;
      const colorOf = hasInliers ? (k) => (m.inliers[k] ? "#22c55e" : "#ef4444")
        : (k) => PALETTE[Math.floor(m.keypoints0[k][1] / 24) % PALETTE.length];
      paintPairs(ctx, v, m.keypoints0, m.keypoints1, colorOf,
        { keep: hasInliers && !showOut ? (k) => m.inliers[k] : undefined, record: true });
    }
    if (m && S.selected && S.selected.length && $("show-matches").checked) {
      const ks = S.selected;
      paintPairs(ctx, v, ks.map((k) => m.keypoints0[k]), ks.map((k) => m.keypoints1[k]), () => "#fde047",
        { size: 7, lineWidth: 2.5, alpha: 1, all: true });
      if (m.model) {
        for (const k of ks.slice(0, 1)) {
          const [x0, y0] = m.keypoints0[k], [x1, y1] = m.keypoints1[k];
          if (m.kind === "fundamental") {
            paintLine(ctx, v, 1, epipolar(m.model, 0, x0, y0), "#38bdf8");
            paintLine(ctx, v, 0, epipolar(m.model, 1, x1, y1), "#38bdf8");
          } else if (m.kind === "homography") {
            paintCross(ctx, v, 1, transfer(m.model, 0, x0, y0), "#38bdf8");
          }
        }
      }
    }
  }

  function paintLayers(ctx, v) {
    if (!S.stages || S.tab === "annotate") return;
    const L = S.stages.layers;
    for (const name of Object.keys(L)) {
      if (!S.layers[name]) continue;
      const layer = L[name];
      if (layer.boxes0) {
        const scaleOf = (boxes) => (k) => SCALE_COLORS[boxes[k][4] % SCALE_COLORS.length];
        paintBoxes(ctx, v, 0, layer.boxes0, name === "tiles" ? () => LAYER_COLORS.tiles : scaleOf(layer.boxes0));
        paintBoxes(ctx, v, 1, layer.boxes1, name === "tiles" ? () => LAYER_COLORS.tiles : scaleOf(layer.boxes1));
      } else if (S.hover && S.hover.layer === name) {
        const p = S.hover.label, ks = [];
        layer.label.forEach((l, k) => { if (l === p) ks.push(k); });
        paintPairs(ctx, v, layer.xy0, layer.xy1, () => "#d4d4d8", { noLines: true, size: 2 });
        paintPairs(ctx, v, ks.map((k) => layer.xy0[k]), ks.map((k) => layer.xy1[k]),
          () => PALETTE[p % PALETTE.length], { size: 5, lineWidth: 1.5, alpha: 0.9, all: true });
        // the block pair of a plane (image 0's block as its outline: a simulated view's is turned and
        // stretched), the tile pair of a set
        const pair = name === "planes" ? layer.block_pairs[p] : (layer.set_tiles || [])[p];
        const boxes = name === "planes" ? L.blocks : L.tiles;
        if (name === "planes" && layer.corners0) paintPolygon(ctx, v, 0, layer.corners0[p], "#fef08a");
        else if (pair && boxes && boxes.boxes0[pair[0]]) paintBoxes(ctx, v, 0, [boxes.boxes0[pair[0]]], () => "#fef08a", 3);
        if (pair && boxes && boxes.boxes1[pair[1]]) paintBoxes(ctx, v, 1, [boxes.boxes1[pair[1]]], () => "#fef08a", 3);
      } else if (layer.label) {
        paintPairs(ctx, v, layer.xy0, layer.xy1, (k) => PALETTE[layer.label[k] % PALETTE.length]);
      } else {
        paintPairs(ctx, v, layer.xy0, layer.xy1, () => LAYER_COLORS[name] || "#facc15");
      }
    }
  }

  function setColor(g) { return PALETTE[(g * 3 + 1) % PALETTE.length]; }

  function paintAnnotations(ctx, v) {
    if (S.tab !== "annotate") return;
    const A = S.annot;
    for (let i = 0; i < 2; i++) {
      v.inPane(i, () => {
        ctx.font = "bold 11px system-ui";
        A.pairs.forEach((p, k) => {
          const x = i === 0 ? p.x0 : p.x1, y = i === 0 ? p.y0 : p.y1;
          if (x === null || x === undefined) return;
          const [sx, sy] = v.toScreen(i, x, y), selected = k === A.selected;
          ctx.strokeStyle = selected ? "#fde047" : setColor(p.set);
          ctx.lineWidth = selected ? 3 : 2;
          ctx.beginPath(); ctx.arc(sx, sy, 5, 0, 2 * Math.PI); ctx.stroke();
          if (p.occluded) { ctx.beginPath(); ctx.moveTo(sx - 6, sy - 6); ctx.lineTo(sx + 6, sy + 6); ctx.stroke(); }
          ctx.fillStyle = "#000"; ctx.fillText(String(k + 1), sx + 7, sy - 5);
          ctx.fillStyle = selected ? "#fde047" : "#fff"; ctx.fillText(String(k + 1), sx + 6, sy - 6);
        });
        if (A.pending && A.pending.pane === i) {
          const [sx, sy] = v.toScreen(i, A.pending.x, A.pending.y);
          ctx.strokeStyle = "#fff"; ctx.setLineDash([3, 3]); ctx.lineWidth = 2;
          ctx.beginPath(); ctx.arc(sx, sy, 8, 0, 2 * Math.PI); ctx.stroke(); ctx.setLineDash([]);
        }
      });
    }
    A.epiline = null; A.reprojected = null;
    const c = A.cursor;
    if (!c) return;
    const other = 1 - c.pane, fit = A.fit || {};
    paintCross(ctx, v, c.pane, [c.x, c.y], "#ffffff", 6);
    const H = (fit.set_H && fit.set_H[String(A.set)]) || fit.H || A.fixedH;
    if (H) {
      A.reprojected = { pane: other, point: transfer(H, c.pane, c.x, c.y) };
      paintCross(ctx, v, other, A.reprojected.point, "#ff3df5", 12);
    }
    if (fit.F) {
      A.epiline = { pane: other, line: epipolar(fit.F, c.pane, c.x, c.y) };
      paintLine(ctx, v, other, A.epiline.line, "#22d3ee");
    }
  }

  view.painters.push(paintLayers, paintMatches, paintAnnotations);

  // ---------------------------------------------------------------- images

  function imageUrl(ref) {
    return `/api/image?root=${encodeURIComponent(ref.root)}&path=${encodeURIComponent(ref.path)}`;
  }

  function loadImage(side, ref) {
    return new Promise((resolve, reject) => {
      const img = new Image();
      img.onload = () => {
        S.imgs[side] = img; S.images[side] = ref;
        view.fit(side); view.redraw(); resolve(img);
      };
      img.onerror = async () => {
        try { await api(imageUrl(ref)); } catch (error) { reject(error); return; }
        reject(new Error(`cannot show ${ref.path}`));
      };
      img.src = imageUrl(ref);
    });
  }

  async function listImages(side, root, selected) {
    const sel = $(`img${side}-path`);
    const data = await api(`/api/images?root=${encodeURIComponent(root)}`);
    sel.innerHTML = "";
    sel.append(new Option("— choose —", ""));
    for (const name of data.images) sel.append(new Option(name, name));
    if (data.truncated) sel.append(new Option(`(first ${data.images.length} only)`, "", false, false));
    if (selected) sel.value = selected;
  }

  async function setImage(side, ref, keepResults = false) {
    if ($(`img${side}-root`).value !== ref.root) {
      $(`img${side}-root`).value = ref.root;
      await listImages(side, ref.root, ref.path);
    }
    $(`img${side}-path`).value = ref.path;
    await loadImage(side, ref);
    if (!keepResults) clearResults();
  }

  function clearResults() {
    S.matches = null; S.selected = null; S.stages = null; S.layers = {}; S.hover = null; S.source = null;
    $("result").hidden = true; renderLayers(); renderInfo("");
    view.redraw();
  }

  function setupPickers() {
    for (const side of [0, 1]) {
      const rootSel = $(`img${side}-root`);
      for (const f of S.info.folders) if (f.kind !== "annotations") rootSel.append(new Option(f.name, f.name));
      if (S.info.annotations) rootSel.append(new Option("annotations", "annotations"));
      rootSel.addEventListener("change", guarded(() => listImages(side, rootSel.value)));
      $(`img${side}-path`).addEventListener("change", guarded(async () => {
        const path = $(`img${side}-path`).value;
        if (path) { await loadImage(side, { root: rootSel.value, path }); clearResults(); resetAnnotations(); }
      }));
      $(`img${side}-upload`).addEventListener("change", guarded(async (e) => {
        const file = e.target.files[0];
        if (!file) return;
        const form = new FormData();
        form.append("file", file);
        const ref = await api("/api/upload", { method: "POST", body: form });
        e.target.value = "";
        await setImage(side, { root: ref.root, path: ref.path });
        resetAnnotations();
      }));
      if (rootSel.options.length) listImages(side, rootSel.value).catch(showError);
    }
  }

  // ---------------------------------------------------------------- match

  function matchRequest() {
    if (!S.images[0] || !S.images[1]) throw new Error("choose two images first");
    const options = {};
    const put = (key, id) => { const value = $(id).value.trim(); if (value) options[key] = value; };
    put("ransac", "opt-ransac"); put("threshold", "opt-threshold"); put("max_side", "opt-max-side");
    put("scales", "opt-scales"); put("descriptor", "opt-descriptor");
    const settings = {};
    for (const line of $("opt-settings").value.split("\n")) {
      if (!line.trim()) continue;
      const at = line.indexOf("=");
      if (at < 1) throw new Error(`'${line.trim()}': write OPTION=VALUE, e.g. slime.tiles.t_xi=12`);
      settings[line.slice(0, at).trim()] = line.slice(at + 1).trim();
    }
    return { image0: S.images[0], image1: S.images[1], preset: $("preset").value, options, settings,
      save_stages: $("opt-stages").checked };
  }

  async function runMatch() {
    const body = matchRequest();
    clearResults();
    const job = await api("/api/match", { method: "POST", json: body });
    S.job = job.id;
    $("run").disabled = true; $("cancel").disabled = false;
    renderJob(job);
    poll(job.id);
  }

  function poll(id) {
    clearTimeout(S.polling);
    S.polling = setTimeout(async () => {
      if (S.job !== id) return;
      try {
        const job = await api(`/api/jobs/${id}`);
        renderJob(job);
        if (job.status === "queued" || job.status === "running") { poll(id); return; }
        $("run").disabled = false; $("cancel").disabled = true;
        if (job.status === "done") await showJobResult(job);
        else if (job.status === "failed") showError(`match failed: ${job.error}`);
      } catch (error) {
        $("run").disabled = false; $("cancel").disabled = true;
        showError(error);
      }
    }, 250);
  }

  function renderJob(job) {
    const list = $("progress");
    list.innerHTML = "";
    for (const st of job.stages) {
      const li = document.createElement("li");
      li.textContent = st.seconds === null ? st.name : `${st.name}: ${fmt(st.seconds, 2)} s`;
      if (st.seconds === null && job.status === "running") li.className = "running";
      list.append(li);
    }
    const elapsed = job.elapsed === null ? "" : ` (${fmt(job.elapsed, 1)} s)`;
    const starting = job.status === "running" && !job.stages.length ? ": starting the matching worker" : "";
    $("status").textContent = `${job.status}${elapsed}${starting}${job.error ? ": " + job.error : ""}`;
  }

  async function showJobResult(job) {
    const m = await api(`/api/jobs/${job.id}/matches`);
    for (const side of [0, 1]) {  // the images may have been changed while it ran: show the matched ones
      const ref = job.images[side], now = S.images[side];
      if (!now || now.root !== ref.root || now.path !== ref.path) await setImage(side, ref, true);
    }
    showMatches(m, { job: job.id }, `/api/jobs/${job.id}/files/`);
    if (m.has_stages) await loadStages(`/api/jobs/${job.id}/stages`);
  }

  function showMatches(m, source, filesUrl) {
    S.matches = m; S.source = source; S.selected = null;
    $("result").hidden = false;
    $("match-count").textContent = `${m.count} matches`;
    $("inlier-count").textContent = Array.isArray(m.inliers)
      ? `· ${m.inliers.reduce((a, b) => a + b, 0)} inliers (${m.kind})` : "";
    $("match-seconds").textContent = m.seconds && m.seconds.total !== undefined ? `· ${fmt(m.seconds.total, 2)} s` : "";
    $("dl-npz").href = filesUrl + "matches.npz";
    $("dl-summary").href = filesUrl + "summary.json";
    const warn = (m.warnings || []).length ? `\nwarnings: ${m.warnings.join("; ")}` : "";
    renderInfo(`${m.count} matches${warn}\nclick a keypoint to see its match`);
    renderStageTable();
    view.redraw();
  }

  async function loadStages(url) {
    S.stages = await api(url);
    S.layers = {};
    renderLayers();
    renderStageTable();
    view.redraw();
  }

  function renderLayers() {
    const box = $("layers");
    box.innerHTML = "";
    if (!S.stages) return;
    const head = document.createElement("h2");
    head.textContent = "Slime's stages";
    box.append(head);
    for (const [name, title] of Object.entries(S.stages.titles)) {
      const layer = S.stages.layers[name];
      const count = layer.boxes0 ? `${layer.boxes0.length} / ${layer.boxes1.length}`
        : `${layer.xy0.length}${layer.sets !== undefined ? `, ${layer.sets} sets` : ""}${layer.H ? `, ${layer.H.length} planes` : ""}`;
      const label = document.createElement("label");
      const box2 = document.createElement("input");
      box2.type = "checkbox"; box2.id = `layer-${name}`; box2.checked = !!S.layers[name];
      box2.addEventListener("change", () => { S.layers[name] = box2.checked; S.hover = null; view.redraw(); });
      const swatch = document.createElement("span");
      swatch.className = "swatch"; swatch.style.background = LAYER_COLORS[name];
      label.append(box2, " ", swatch, `${name}: ${title} (${count})`);
      box.append(label);
    }
  }

  function renderStageTable() {
    const table = $("stage-table");
    table.innerHTML = "";
    const seconds = (S.stages && S.stages.seconds) || (S.matches && S.matches.seconds) || {};
    const counts = (S.stages && S.stages.counts) || (S.matches && S.matches.counts) || {};
    if (!Object.keys(seconds).length && !Object.keys(counts).length) return;
    const row = (a, b, cls) => {
      const tr = document.createElement("tr");
      const td1 = document.createElement("td"), td2 = document.createElement("td");
      td1.textContent = a; td2.textContent = b; td2.className = "num";
      if (cls) tr.className = cls;
      tr.append(td1, td2); table.append(tr);
    };
    for (const [k, v] of Object.entries(seconds)) row(`${k} (s)`, fmt(v, 2));
    for (const [k, v] of Object.entries(counts)) row(k, String(v));
  }

  function renderInfo(text) { $("info").textContent = text; }

  function nearest(points, x, y, radiusPx, s) {
    let best = -1, bestD = (radiusPx / s) ** 2;
    for (let k = 0; k < points.length; k++) {
      const dx = points[k][0] - x, dy = points[k][1] - y, d = dx * dx + dy * dy;
      if (d < bestD) { bestD = d; best = k; }
    }
    return best;
  }

  const matchHandler = {
    click(pane, x, y) {
      const m = S.matches;
      if (!m || !m.count) return;
      const pts = pane === 0 ? m.keypoints0 : m.keypoints1;
      const k = nearest(pts, x, y, 10, view.views[pane].s);
      if (k < 0) { S.selected = null; renderInfo(`${m.count} matches`); view.redraw(); return; }
      const [px, py] = pts[k];
      S.selected = [];
      pts.forEach((p, j) => { if (p[0] === px && p[1] === py) S.selected.push(j); });
      const lines = S.selected.slice(0, 6).map((j) => {
        const inl = Array.isArray(m.inliers) ? (m.inliers[j] ? " inlier" : " outlier") : "";
        return `#${j}: (${fmt(m.keypoints0[j][0])}, ${fmt(m.keypoints0[j][1])}) -> ` +
          `(${fmt(m.keypoints1[j][0])}, ${fmt(m.keypoints1[j][1])})  score ${fmt(m.scores[j], 4)}${inl}`;
      });
      const more = S.selected.length > 6 ? `\n… ${S.selected.length - 6} more` : "";
      renderInfo(`keypoint (${fmt(px)}, ${fmt(py)}) of image ${pane}: ${S.selected.length} match(es)\n` +
        lines.join("\n") + more);
      view.redraw();
    },
    // over a match of the most refined labelled layer shown: its plane (or set) alone, with its homography
    hover(pane, x, y) {
      if (!S.stages) return;
      const L = S.stages.layers;
      const name = ["ftheta", "fbar", "superset", "planes"].find((n) => S.layers[n] && L[n]);
      if (!name) return;
      const layer = L[name];
      const k = nearest(pane === 0 ? layer.xy0 : layer.xy1, x, y, 8, view.views[pane].s);
      const label = k < 0 ? null : layer.label[k];
      if (label === (S.hover ? S.hover.label : null) && (!S.hover || S.hover.layer === name)) return;
      S.hover = label === null ? null : { layer: name, label };
      if (label !== null) {
        const count = layer.label.filter((l) => l === label).length;
        const plane = name === "planes" ? label : (layer.set_plane || [])[label];
        const H = L.planes && plane !== undefined ? L.planes.H[plane] : null;
        const matrix = H ? H.map((r) => r.map((v) => v.toPrecision(5).padStart(12)).join(" ")).join("\n") : "";
        const view = name === "planes" && layer.views ? layer.views[label] : null;
        const where = name === "planes" ? `block pair ${layer.block_pairs[label].join(" / ")}`
          + (view && view[0] > 1 ? ` (image 0's block in its simulated view of tilt ${+view[0].toFixed(2)} at ${+view[1].toFixed(1)} deg)` : "")
          : `set ${label} of ${name}, tile pair ${(layer.set_tiles || [])[label]}`;
        renderInfo(`plane ${plane}: ${count} matches, ${where}` + (H ? `, H (image 0 -> 1):\n${matrix}` : ""));
      }
      view.redraw();
    },
    leave() { if (S.hover) { S.hover = null; view.redraw(); } },
  };

  // ---------------------------------------------------------------- runs

  async function loadRun(name) {
    const tbody = $("run-pairs").querySelector("tbody");
    tbody.innerHTML = "";
    if (!name) return;
    const run = await api(`/api/runs/${encodeURIComponent(name)}`);
    $("run-summary").textContent = `${run.pairs.length} pairs` + (run.method ? `, method ${run.method}` : "");
    for (const p of run.pairs) {
      const tr = document.createElement("tr");
      if (p.status === "failed") tr.className = "failed";
      const cells = [String(p.index), `${p.image0}  ${p.image1}`, p.status + (p.error ? `: ${p.error}` : ""),
        p.matches === null || p.matches === undefined ? "–" : String(p.matches), fmt(p.seconds, 1)];
      cells.forEach((text, j) => {
        const td = document.createElement("td");
        td.textContent = text;
        if (j === 0 || j >= 3) td.className = "num";
        tr.append(td);
      });
      const td = document.createElement("td");
      if (p.status !== "failed") {
        const b = document.createElement("button");
        b.textContent = "open"; b.id = `open-pair-${p.index}`;
        b.addEventListener("click", guarded(() => openRunPair(name, p.index, tr)));
        td.append(b);
      }
      tr.append(td);
      tbody.append(tr);
    }
  }

  async function openRunPair(name, index, tr) {
    const base = `/api/runs/${encodeURIComponent(name)}/pairs/${index}`;
    const m = await api(base);
    for (const row of $("run-pairs").querySelectorAll("tr.selected")) row.classList.remove("selected");
    if (tr) tr.classList.add("selected");
    clearResults();
    if (m.images_missing) showError(m.images_missing);
    for (const side of [0, 1]) {
      if (m.images[side]) await setImage(side, m.images[side], true);
      else { S.imgs[side] = null; S.images[side] = null; }
    }
    showMatches(m, { run: name, index }, `${base}/files/`);
    if (m.has_stages) await loadStages(`${base}/stages`);
  }

  // ---------------------------------------------------------------- annotate

  const snapshot = () => JSON.stringify({ pairs: S.annot.pairs, pending: S.annot.pending, set: S.annot.set });
  function remember() {
    S.annot.history.push(snapshot());
    if (S.annot.history.length > 200) S.annot.history.shift();
  }
  function resetAnnotations() {
    Object.assign(S.annot, { pairs: [], pending: null, set: 0, selected: -1, history: [], fit: null, fixedH: null });
    annotationsChanged();
  }

  function annotationsChanged() {
    S.annot.saved = "";  // a save's message stands until the annotations change
    $("ann-set").textContent = String(S.annot.set);
    renderPairsTable();
    view.redraw();
    clearTimeout(annotationsChanged.timer);
    S.annot.fitting += 1;
    annotationsChanged.timer = setTimeout(guarded(refit), 60);
  }

  async function refit() {
    const A = S.annot;
    try {
      A.fit = await api("/api/annotate/fit", { method: "POST", json: { pairs: A.pairs } });
    } finally {
      A.fitting = Math.max(0, A.fitting - 1);
    }
    renderPairsTable();
    const visible = A.fit.visible;
    const parts = [`${A.pairs.length} pairs (${visible} visible), set ${A.set}`];
    parts.push(A.fit.H ? "H: fitted" : `H: needs ${A.fit.min_pairs.H} pairs`);
    parts.push(A.fit.F ? "F: fitted" : `F: needs ${A.fit.min_pairs.F} pairs`);
    const res = (A.model === "H" ? A.fit.residual_H : A.fit.residual_F).filter((r) => r !== null);
    if (res.length) parts.push(`mean residual ${fmt(res.reduce((a, b) => a + b, 0) / res.length, 2)} px`);
    if (A.saved) parts.push(A.saved);  // a fit that answers after a save keeps its message
    $("ann-status").textContent = parts.join("\n");
    view.redraw();
  }

  function renderPairsTable() {
    const A = S.annot, tbody = $("ann-pairs").querySelector("tbody");
    tbody.innerHTML = "";
    const res = A.fit ? (A.model === "H" ? A.fit.residual_H : A.fit.residual_F) : [];
    A.pairs.forEach((p, k) => {
      const tr = document.createElement("tr");
      if (k === A.selected) tr.className = "selected";
      const pt = (x, y) => (x === null ? "occluded" : `${fmt(x)}, ${fmt(y)}`);
      for (const text of [String(k + 1), String(p.set), pt(p.x0, p.y0), pt(p.x1, p.y1), fmt(res[k], 2)]) {
        const td = document.createElement("td"); td.textContent = text; tr.append(td);
      }
      tr.addEventListener("click", () => { A.selected = k; renderPairsTable(); view.redraw(); });
      tbody.append(tr);
    });
  }

  function insideImage(pane, x, y) {
    const img = S.imgs[pane];
    return img && x >= -0.5 && y >= -0.5 && x <= img.naturalWidth - 0.5 && y <= img.naturalHeight - 0.5;
  }

  const annotateHandler = {
    grabbed: null, movedOnce: false,
    grab(pane, x, y) {
      const A = S.annot, s = view.views[pane].s;
      if (A.pending && A.pending.pane === pane && Math.hypot(A.pending.x - x, A.pending.y - y) * s < 8) {
        this.grabbed = { pending: true }; this.movedOnce = false; return true;
      }
      const pts = A.pairs.map((p) => (pane === 0 ? [p.x0, p.y0] : [p.x1, p.y1]))
        .map((p) => (p[0] === null ? [Infinity, Infinity] : p));
      const k = nearest(pts, x, y, 8, s);
      if (k < 0) return false;
      A.selected = k; A.lastPane = pane;
      this.grabbed = { k, pane }; this.movedOnce = false;
      renderPairsTable(); view.redraw();
      return true;
    },
    drag(pane, x, y) {
      const A = S.annot, g = this.grabbed;
      if (!g) return;
      if (!this.movedOnce) { remember(); this.movedOnce = true; }
      if (g.pending) { A.pending.x = x; A.pending.y = y; return; }
      const p = A.pairs[g.k];
      if (g.pane === 0) { p.x0 = x; p.y0 = y; } else { p.x1 = x; p.y1 = y; }
    },
    drop(moved) {
      this.grabbed = null;
      if (moved) annotationsChanged();
    },
    click(pane, x, y) {
      const A = S.annot;
      if (!insideImage(pane, x, y)) return;
      if (A.pending && A.pending.pane !== pane) {
        remember();
        const p0 = A.pending.pane === 0 ? A.pending : { x, y }, p1 = A.pending.pane === 0 ? { x, y } : A.pending;
        A.pairs.push({ x0: p0.x, y0: p0.y, x1: p1.x, y1: p1.y, set: A.set, occluded: false });
        A.pending = null; A.selected = A.pairs.length - 1; A.lastPane = pane;
      } else {
        remember();
        A.pending = { pane, x, y };
      }
      annotationsChanged();
    },
    hover(pane, x, y) {
      S.annot.cursor = { pane, x, y };
      view.redraw();
    },
    leave() { S.annot.cursor = null; view.redraw(); },
  };

  function markOccluded() {
    const A = S.annot;
    if (A.pending) {
      remember();
      const p = A.pending;
      A.pairs.push(p.pane === 0 ? { x0: p.x, y0: p.y, x1: null, y1: null, set: A.set, occluded: true }
        : { x0: null, y0: null, x1: p.x, y1: p.y, set: A.set, occluded: true });
      A.pending = null;
    } else if (A.selected >= 0) {
      remember();
      const p = A.pairs[A.selected];
      p.occluded = !p.occluded;
      if (!p.occluded && (p.x0 === null || p.x1 === null)) { A.history.pop(); p.occluded = true; return showError("this point has no match to restore: delete it instead"); }
    } else return;
    annotationsChanged();
  }
  // the arrow keys move the selected pair's point in the image last touched by one screen pixel (ten with Shift)
  function nudge(dx, dy, far) {
    const A = S.annot;
    if (A.selected < 0 || A.lastPane === undefined) return;
    const p = A.pairs[A.selected], pane = A.lastPane, step = (far ? 10 : 1) / view.views[pane].s;
    if ((pane === 0 ? p.x0 : p.x1) === null) return;
    remember();
    if (pane === 0) { p.x0 += dx * step; p.y0 += dy * step; } else { p.x1 += dx * step; p.y1 += dy * step; }
    annotationsChanged();
  }
  function deleteSelected() {
    const A = S.annot;
    if (A.pending) { remember(); A.pending = null; } else if (A.selected >= 0) {
      remember(); A.pairs.splice(A.selected, 1); A.selected = -1;
    } else return;
    annotationsChanged();
  }
  function undo() {
    const A = S.annot;
    const last = A.history.pop();
    if (!last) return;
    Object.assign(A, JSON.parse(last));
    if (A.selected >= A.pairs.length) A.selected = -1;
    annotationsChanged();
  }
  function newSet() {
    const A = S.annot;
    remember();
    A.set = Math.max(A.set, ...A.pairs.map((p) => p.set)) + 1;
    annotationsChanged();
  }

  async function saveAnnotation() {
    if (!S.images[0] || !S.images[1]) throw new Error("choose two images first");
    const body = { name: $("ann-name").value.trim(), model: S.annot.model, image0: S.images[0], image1: S.images[1],
      pairs: S.annot.pairs, overwrite: $("ann-overwrite").checked };
    const out = await api("/api/annotate/save", { method: "POST", json: body });
    S.annot.saved = `saved (${out.kind}): ${out.files.join(", ")} in the annotation folder`;
    $("ann-status").textContent = S.annot.saved;
    await listSaved();
  }
  async function downloadAnnotation() {
    const response = await api("/api/annotate/export", { method: "POST", json: { pairs: S.annot.pairs, model: S.annot.model }, raw: true });
    const blob = await response.blob();
    const a = document.createElement("a");
    a.href = URL.createObjectURL(blob);
    a.download = S.annot.model === "F" ? "corrs.txt" : `${$("ann-name").value.trim() || "pair"}_H12.txt`;
    document.body.append(a); a.click(); a.remove();
  }
  async function listSaved() {
    const sel = $("ann-saved");
    sel.innerHTML = "";
    const data = await api("/api/annotate/saved");
    if (!data.folder) { sel.append(new Option("(start with --annotations DIR to save)", "")); return; }
    sel.append(new Option(data.annotations.length ? "— saved pairs —" : "(none saved yet)", ""));
    for (const a of data.annotations) sel.append(new Option(`${a.kind}: ${a.name}`, `annotations/${a.path}`));
  }
  async function openAnnotation(value) {
    const at = value.indexOf("/");
    if (at < 1) throw new Error("write the file as FOLDER/path (a served folder's name, then the path in it)");
    const root = value.slice(0, at), path = value.slice(at + 1);
    const opened = await api(`/api/annotate/open?root=${encodeURIComponent(root)}&path=${encodeURIComponent(path)}`);
    if (!opened.image0 || !opened.image1) throw new Error("the annotation's images are not under the served folders");
    await setImage(0, opened.image0);
    await setImage(1, opened.image1);
    resetAnnotations();
    S.annot.pairs = opened.pairs;
    S.annot.set = Math.max(0, ...opened.pairs.map((p) => p.set));
    S.annot.fixedH = opened.H;
    const model = opened.kind === "planar" ? "H" : "F";
    $(`model-${model}`).checked = true; S.annot.model = model;
    $("ann-name").value = opened.kind === "planar" ? path.split("/").pop().replace(/_H1\d+\.txt$/, "") : path.split("/").slice(-2)[0];
    annotationsChanged();
  }

  // ---------------------------------------------------------------- tabs, keys, start

  function setTab(tab) {
    S.tab = tab;
    for (const b of document.querySelectorAll(".tab")) b.classList.toggle("active", b.dataset.tab === tab);
    for (const name of ["match", "runs", "annotate"]) $(`panel-${name}`).hidden = name !== tab;
    view.handler = tab === "annotate" ? annotateHandler : matchHandler;
    $("result-section").hidden = tab === "annotate";
    if (tab === "annotate") annotationsChanged();
    view.redraw();
  }

  document.addEventListener("keydown", (e) => {
    if (S.tab !== "annotate" || ["INPUT", "TEXTAREA", "SELECT"].includes(e.target.tagName)) return;
    if ((e.ctrlKey || e.metaKey) && e.key.toLowerCase() === "z") { e.preventDefault(); undo(); } else if (e.key === "Delete" || e.key === "Backspace") { e.preventDefault(); deleteSelected(); } else if (e.key.toLowerCase() === "o") markOccluded();
    else if (e.key.toLowerCase() === "n") newSet();
    else if (e.key.startsWith("Arrow")) {
      e.preventDefault();
      const [dx, dy] = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, -1], ArrowDown: [0, 1] }[e.key];
      nudge(dx, dy, e.shiftKey);
    }
  });

  async function start() {
    S.info = await api("/api/info");
    $("version").textContent = `slime-match ${S.info.version}`;
    for (const p of S.info.presets) $("preset").append(new Option(p, p));
    $("preset").value = "slime";
    $("opt-ransac").append(new Option("(preset: none)", ""));
    for (const r of S.info.choices.ransac) if (r !== "none") $("opt-ransac").append(new Option(r, r));
    $("opt-descriptor").append(new Option("(preset)", ""));
    for (const d of S.info.choices.descriptor) $("opt-descriptor").append(new Option(d, d));
    setupPickers();
    for (const r of S.info.runs) $("run-select").append(new Option(r, r));
    $("run-select").addEventListener("change", guarded(() => loadRun($("run-select").value)));
    if (S.info.runs.length) loadRun(S.info.runs[0]).catch(showError);
    for (const b of document.querySelectorAll(".tab")) b.addEventListener("click", () => setTab(b.dataset.tab));
    $("run").addEventListener("click", guarded(runMatch));
    $("cancel").addEventListener("click", guarded(async () => { if (S.job) renderJob(await api(`/api/jobs/${S.job}/cancel`, { method: "POST" })); }));
    for (const id of ["max-lines", "show-matches", "show-outliers"]) $(id).addEventListener("input", () => view.redraw());
    $("ann-undo").addEventListener("click", undo);
    $("ann-delete").addEventListener("click", deleteSelected);
    $("ann-occluded").addEventListener("click", markOccluded);
    $("ann-new-set").addEventListener("click", newSet);
    $("ann-clear").addEventListener("click", () => { remember(); S.annot.pairs = []; S.annot.pending = null; annotationsChanged(); });
    for (const m of ["H", "F"]) $(`model-${m}`).addEventListener("change", () => { S.annot.model = m; annotationsChanged(); });
    $("ann-save").addEventListener("click", guarded(saveAnnotation));
    $("ann-download").addEventListener("click", guarded(downloadAnnotation));
    $("ann-open").addEventListener("click", guarded(() => openAnnotation($("ann-saved").value)));
    $("ann-open-file").addEventListener("click", guarded(() => openAnnotation($("ann-open-path").value.trim())));
    listSaved().catch(showError);
    setTab("match");
    document.body.dataset.ready = "1";
  }

  // for the browser tests and the console: the state, the view and a frame-time probe
  window.slimeWeb = {
    S, view,
    screenOf(pane, x, y) { return view.toScreen(pane, x, y); },
    busy() { return S.annot.fitting > 0 || view.pending; },
    measureFrames(n) {
      const times = [], saved = view.views.map((v) => ({ ...v }));
      for (let k = 0; k < n; k++) {
        const pane = k % 2, f = k % 4 < 2 ? 1.15 : 1 / 1.15;
        view.zoom(pane, f, view.paneLeft(pane) + view.paneWidth() / 2, view.height / 2);
        view.views[pane].tx += k % 3 - 1;
        const t0 = performance.now();
        view.draw();
        times.push(performance.now() - t0);
      }
      view.views = saved;
      view.redraw();
      times.sort((a, b) => a - b);
      return { mean: times.reduce((a, b) => a + b, 0) / n, median: times[Math.floor(n / 2)], max: times[n - 1] };
    },
  };

  start().catch(showError);
})();
