// slime web: tools over the shown matches, as users of other matching apps know them: a confidence floor,
// RANSAC run again on the current matches, image 0 warped by a homography over image 1 (blend or
// checkerboard), the matches coloured by their error to the pair's ground truth, and exports (the view as PNG,
// the matches as JSON or CSV).
"use strict";

const GT_COLORS = [[1, "#22c55e"], [3, "#a3e635"], [10, "#f59e0b"], [Infinity, "#ef4444"]];  // px: colour

// ---------------------------------------------------------------- confidence floor

function minConfidence() { return Number($("min-confidence").value) || 0; }

// keep(k) for the matches at or above the confidence floor; null when the floor keeps them all
function confidenceFilter(m) {
  const floor = minConfidence();
  return floor > 0 && m.confidence ? (k) => m.confidence[k] >= floor : null;
}

// ---------------------------------------------------------------- RANSAC again

async function rerunRansac() {
  const m = S.matches;
  if (!m || !S.source) throw new Error("show a match first");
  const body = { source: S.source, method: $("rr-method").value, threshold: $("rr-threshold").value.trim() || null,
    min_confidence: minConfidence() };
  const answer = await api("/api/ransac", { method: "POST", json: body });
  if (S.matches !== m) return;
  Object.assign(m, { inliers: answer.inliers, model: answer.model, kind: answer.kind });
  const count = answer.inliers.reduce((a, b) => a + b, 0);
  $("inlier-count").textContent = `· ${count} inliers (${answer.kind}, ${body.method}, ${fmt(answer.threshold, 1)} px`
    + `, of ${answer.used})`;
  refreshOverlay().catch(showError);
  view.redraw();
}

// ---------------------------------------------------------------- the pair's ground truth

// the shown pair's ground truth: the homography of an opened ground-truth file, else the model of its
// annotation (F when the annotation's model is F and determined, else H); null without one
function groundTruth() {
  const A = S.annot;
  if (!A || !pairKey(S.images) || pairKey(A.images) !== pairKey(S.images)) return null;
  if (A.fixedH) return { kind: "H", M: A.fixedH, from: "the opened ground-truth file" };
  const fit = A.fit || {};
  if (fit.F && (A.model === "F" || !fit.H)) return { kind: "F", M: fit.F, from: "the annotation's F" };
  return fit.H ? { kind: "H", M: fit.H, from: "the annotation's H" } : null;
}

// each match's error in px to the ground truth: |H x0 - x1|, or the distance of x1 to F x0
function groundTruthErrors(m, gt) {
  return m.keypoints0.map(([x0, y0], k) => {
    const [x1, y1] = m.keypoints1[k];
    if (gt.kind === "H") {
      const p = transfer(gt.M, 0, x0, y0);
      return p ? Math.hypot(p[0] - x1, p[1] - y1) : Infinity;
    }
    const [a, b, c] = epipolar(gt.M, 0, x0, y0);
    return Math.abs(a * x1 + b * y1 + c) / Math.max(Math.hypot(a, b), 1e-12);
  });
}

function groundTruthColorOf(m) {
  if (!$("gt-color").checked || !S.gtErrors || S.gtErrors.matches !== m) return null;
  const errors = S.gtErrors.values;
  return (k) => GT_COLORS.find(([bound]) => errors[k] < bound)[1];
}

function colourByGroundTruth() {
  const m = S.matches, gt = groundTruth();
  S.gtErrors = null;
  if ($("gt-color").checked) {
    if (!m) throw new Error("show a match first");
    if (!gt) {
      $("gt-color").checked = false;
      throw new Error("this pair has no ground truth: annotate it (Annotate tab) or open its ground-truth file");
    }
    const values = groundTruthErrors(m, gt);
    S.gtErrors = { matches: m, values };
    const within = values.filter((e) => e < 3).length;
    $("gt-summary").textContent = `${within} of ${m.count} within 3 px of ${gt.from} (${gt.kind})`;
  } else {
    $("gt-summary").textContent = "";
  }
  view.redraw();
}

// ---------------------------------------------------------------- overlay

// the homography of the overlay: the shown match's when it is one, else the pair's ground truth's
function overlayHomography() {
  const m = S.matches;
  if (m && m.kind === "homography" && m.model) return m.model;
  const gt = groundTruth();
  return gt && gt.kind === "H" ? gt.M : null;
}

async function refreshOverlay() {
  S.overlay = null;
  view.redraw();
  if (!$("overlay").value) return;
  const H = overlayHomography();
  if (!H || !S.images[0] || !S.images[1]) {
    $("overlay").value = "";
    throw new Error("the overlay needs a homography: a match with RANSAC homography, or the pair's H");
  }
  const response = await api("/api/warp", { method: "POST", json: { image0: S.images[0], image1: S.images[1], H },
    raw: true });
  const img = new Image();
  img.src = URL.createObjectURL(await response.blob());
  await img.decode();
  S.overlay = { img };
  view.redraw();
}

// image 0 warped into image 1's frame, over image 1: blended, or in every other square of a checkerboard
function paintOverlay(ctx, v) {
  const mode = $("overlay").value;
  if (!S.overlay || !mode || S.tab === "annotate") return;
  const img = S.overlay.img, vi = v.views[1], left = v.paneLeft(1), square = 32;
  v.inPane(1, () => {
    if (mode === "checker") {
      ctx.beginPath();
      for (let y = 0; y * square < img.naturalHeight; y++) {
        for (let x = (y % 2); x * square < img.naturalWidth; x += 2) {
          ctx.rect(left + (x * square - 0.5) * vi.s + vi.tx, (y * square - 0.5) * vi.s + vi.ty, square * vi.s, square * vi.s);
        }
      }
      ctx.clip();
    } else {
      ctx.globalAlpha = Number($("overlay-alpha").value);
    }
    ctx.imageSmoothingEnabled = vi.s < 2;
    ctx.drawImage(img, left + vi.tx - vi.s / 2, vi.ty - vi.s / 2, img.naturalWidth * vi.s, img.naturalHeight * vi.s);
    ctx.globalAlpha = 1;
  });
}

// ---------------------------------------------------------------- exports

function download(blob, name) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = name;
  document.body.append(a); a.click(); a.remove();
}

function matchesRecord() {
  const m = S.matches;
  if (!m) throw new Error("show a match first");
  return { image0: S.images[0], image1: S.images[1], count: m.count, kind: m.kind, model: m.model,
    keypoints0: m.keypoints0, keypoints1: m.keypoints1, scores: m.scores, confidence: m.confidence,
    inliers: m.inliers };
}

function exportJson() {
  download(new Blob([JSON.stringify(matchesRecord())], { type: "application/json" }), "matches.json");
}

function exportCsv() {
  const r = matchesRecord(), rows = ["x0,y0,x1,y1,score,confidence,inlier"];
  for (let k = 0; k < r.count; k++) {
    rows.push([...r.keypoints0[k], ...r.keypoints1[k], r.scores[k], r.confidence ? r.confidence[k] : "",
      r.inliers ? r.inliers[k] : ""].join(","));
  }
  download(new Blob([rows.join("\n") + "\n"], { type: "text/csv" }), "matches.csv");
}

function exportPng() {
  view.draw();
  view.canvas.toBlob((blob) => download(blob, "view.png"), "image/png");
}

function setupTools(info) {
  for (const c of info.choices.ransac) if (c !== "none") $("rr-method").append(new Option(c, c));
  $("min-confidence").addEventListener("input", () => {
    $("min-confidence-value").textContent = minConfidence().toFixed(2);
    view.redraw();
  });
  $("rr-run").addEventListener("click", guarded(rerunRansac));
  $("overlay").addEventListener("change", guarded(refreshOverlay));
  $("overlay-alpha").addEventListener("input", () => view.redraw());
  $("gt-color").addEventListener("change", guarded(colourByGroundTruth));
  $("export-png").addEventListener("click", exportPng);
  $("export-json").addEventListener("click", guarded(exportJson));
  $("export-csv").addEventListener("click", guarded(exportCsv));
}
