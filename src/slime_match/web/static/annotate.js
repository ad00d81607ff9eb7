// slime web: the annotation tool (ground-truth correspondences).
"use strict";

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

// ---------------------------------------------------------------- the annotation's life cycle

const snapshot = () => JSON.stringify({ pairs: S.annot.pairs, pending: S.annot.pending, set: S.annot.set });
function remember() {
  S.annot.history.push(snapshot());
  if (S.annot.history.length > 200) S.annot.history.shift();
}

// after every change: the table, the draft and, a moment later, the fit; `edited` marks the pair unsaved
function annotationsChanged({ edited = true } = {}) {
  const A = S.annot;
  if (edited) { A.dirty = true; A.saved = ""; }  // a save's message stands until the annotations change
  keepDraft(A);
  $("ann-set").textContent = String(A.set);
  renderPairsTable();
  renderAnnotationStatus();
  view.redraw();
  clearTimeout(annotationsChanged.timer);
  if (!annotationsChanged.timer) S.fitting += 1;  // one fit counted while its timer waits
  annotationsChanged.timer = setTimeout(() => { annotationsChanged.timer = null; guarded(refit)(); }, 60);
}

async function refit() {
  const A = S.annot;
  try {
    A.fit = await api("/api/annotate/fit", { method: "POST", json: { pairs: A.pairs } });
  } finally {
    S.fitting = Math.max(0, S.fitting - 1);
  }
  if (A !== S.annot) return;  // the pair changed meanwhile
  renderPairsTable();
  renderAnnotationStatus();
  view.redraw();
}

function renderAnnotationStatus() {
  const A = S.annot, fit = A.fit;
  if (!pairKey(A.images)) { $("ann-status").textContent = "choose two images to annotate them"; return; }
  const visible = A.pairs.filter((p) => !p.occluded).length;
  const parts = [`${A.pairs.length} pairs (${visible} visible), set ${A.set}` + (A.dirty && A.pairs.length
    ? " · unsaved (kept as a draft in this browser)" : "")];
  if (fit) {
    parts.push(fit.H ? "H: fitted" : fit.why.H);
    parts.push(fit.F ? "F: fitted" : fit.why.F);
    const res = (A.model === "H" ? fit.residual_H : fit.residual_F).filter((r) => r !== null && r !== undefined);
    if (res.length) parts.push(`mean residual to ${A.model}: ${fmt(res.reduce((a, b) => a + b, 0) / res.length, 2)} px`);
  }
  if (A.saved) parts.push(A.saved);
  $("ann-status").textContent = parts.join("\n");
}

function renderPairsTable() {
  const A = S.annot, tbody = $("ann-pairs").querySelector("tbody");
  tbody.innerHTML = "";
  const same = A.fit && A.fit.residual_H.length === A.pairs.length;  // a fit of these pairs, not of earlier ones
  const resH = same ? A.fit.residual_H : [], resF = same ? A.fit.residual_F : [];
  A.pairs.forEach((p, k) => {
    const tr = document.createElement("tr");
    if (k === A.selected) tr.className = "selected";
    const pt = (x, y) => (x === null ? "occluded" : `${fmt(x)}, ${fmt(y)}`);
    for (const text of [String(k + 1), String(p.set), pt(p.x0, p.y0), pt(p.x1, p.y1), fmt(resH[k], 2),
      fmt(resF[k], 2)]) {
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
    if (!insideImage(pane, x, y)) return undefined;
    if (!pairKey(A.images)) { showError("choose two images first"); return undefined; }
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
    return () => { if (S.annot === A) undo(); };
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
  const A = S.annot;  // saved with its own images, whatever is shown when the answer comes
  if (!pairKey(A.images)) throw new Error("choose two images first");
  A.name = $("ann-name").value.trim();
  const body = { name: A.name, model: A.model, image0: A.images[0], image1: A.images[1], pairs: A.pairs,
    overwrite: $("ann-overwrite").checked };
  const out = await api("/api/annotate/save", { method: "POST", json: body });
  A.saved = `saved (${out.kind}): ${out.files.join(", ")} in the annotation folder`;
  A.dirty = false;
  keepDraft(A);
  if (A === S.annot) renderAnnotationStatus();
  await listSaved();
}
async function downloadAnnotation() {
  const A = S.annot;
  const response = await api("/api/annotate/export", { method: "POST", json: { pairs: A.pairs, model: A.model }, raw: true });
  const blob = await response.blob();
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = A.model === "F" ? "corrs.txt" : `${$("ann-name").value.trim() || "pair"}_H12.txt`;
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
// a pair name for a ground-truth file: its folder for a corrs.txt, the scene of a planar file, the sequence and
// pair of an Oxford H1to<k>p, the pair of an EVD h/<name>.txt
function annotationName(path) {
  const parts = path.split("/"), file = parts[parts.length - 1], folder = parts[parts.length - 2] || "pair";
  const oxford = file.match(/^H1to(\d+)p$/);
  const name = file === "corrs.txt" ? folder : oxford ? `${folder}-1to${oxford[1]}`
    : file.replace(/_H1\d+\.txt$/, "").replace(/\.txt$/, "");
  return name.replace(/[^A-Za-z0-9_-]/g, "_").replace(/^[_-]+/, "").slice(0, 64) || "pair";
}
async function openAnnotation(value) {
  const at = value.indexOf("/");
  if (at < 1) throw new Error("write the file as FOLDER/path (a served folder's name, then the path in it)");
  const root = value.slice(0, at), path = value.slice(at + 1);
  const opened = await api(`/api/annotate/open?root=${encodeURIComponent(root)}&path=${encodeURIComponent(path)}`);
  if (!opened.image0 || !opened.image1) throw new Error("the annotation's images are not under the served folders");
  if (!mayLeavePair([opened.image0, opened.image1])) return;
  await setImage(0, opened.image0);
  await setImage(1, opened.image1);
  const A = S.annot;
  if (A.dirty && A.pairs.length && !window.confirm(`This pair has ${A.pairs.length} unsaved annotated pairs: `
    + "replace them with the file's? (Undo brings them back.)")) return;
  remember();
  Object.assign(A, { pairs: opened.pairs, pending: null, selected: -1, fixedH: opened.H, saved: "",
    set: Math.max(0, ...opened.pairs.map((p) => p.set)), model: opened.kind === "planar" ? "H" : "F",
    name: annotationName(path) });
  $(`model-${A.model}`).checked = true;
  $("ann-name").value = A.name;
  annotationsChanged();
  A.dirty = false;
  keepDraft(A);
  renderAnnotationStatus();
}
