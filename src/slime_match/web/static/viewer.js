// slime web: the matches and Slime's stage layers over the two images, the image pickers, the Runs tab.
"use strict";

// ---------------------------------------------------------------- painters

function paintMatches(ctx, v) {
  if (S.tab === "annotate") return;
  const m = S.matches;
  if (m && $("show-matches").checked && m.count) {
    const hasInliers = Array.isArray(m.inliers);
    const showOut = $("show-outliers").checked;
    // by ground-truth error when asked (tools.js), else inliers and outliers, else by height
    const colorOf = groundTruthColorOf(m) || (hasInliers ? (k) => (m.inliers[k] ? "#22c55e" : "#ef4444")
      : (k) => PALETTE[Math.floor(m.keypoints0[k][1] / 24) % PALETTE.length]);
    const confident = confidenceFilter(m), inlier = hasInliers && !showOut ? (k) => m.inliers[k] : null;
    const keep = confident && inlier ? (k) => confident(k) && inlier(k) : confident || inlier || undefined;
    paintPairs(ctx, v, m.keypoints0, m.keypoints1, colorOf, { keep, record: true });
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
      // the block pair of a plane (each block as its outline: a simulated view's is turned and stretched),
      // the tile pair of a set
      const pair = name === "planes" ? layer.block_pairs[p] : (layer.set_tiles || [])[p];
      const boxes = name === "planes" ? L.blocks : L.tiles;
      for (const i of [0, 1]) {
        const corners = name === "planes" ? layer[`corners${i}`] : null;
        if (corners) paintPolygon(ctx, v, i, corners[p], "#fef08a");
        else if (pair && boxes && boxes[`boxes${i}`][pair[i]]) paintBoxes(ctx, v, i, [boxes[`boxes${i}`][pair[i]]], () => "#fef08a", 3);
      }
    } else if (layer.label) {
      paintPairs(ctx, v, layer.xy0, layer.xy1, (k) => PALETTE[layer.label[k] % PALETTE.length]);
    } else {
      paintPairs(ctx, v, layer.xy0, layer.xy1, () => LAYER_COLORS[name] || "#facc15");
    }
  }
}

// ---------------------------------------------------------------- images

function imageUrl(ref) {
  return `/api/image?root=${encodeURIComponent(ref.root)}&path=${encodeURIComponent(ref.path)}`;
}

function loadImage(side, ref) {
  return new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => {
      S.imgs[side] = img; S.images[side] = ref;
      view.fit(side); view.redraw();
      showPairAnnotation();
      resolve(img);
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

// no result on screen: matches, layers, counts, warnings, and the last job's progress unless one is followed
function clearResults() {
  S.matches = null; S.selected = null; S.stages = null; S.layers = {}; S.hover = null; S.source = null;
  S.overlay = null; S.gtErrors = null; $("overlay").value = ""; $("gt-color").checked = false; $("gt-summary").textContent = "";
  $("result").hidden = true; renderLayers(); renderStageTable(); renderInfo("");
  if ($("cancel").disabled) { $("progress").innerHTML = ""; $("status").textContent = ""; }
  view.redraw();
}

// the pickers' folders and events; resolves when the first folder of each is listed
function setupPickers() {
  const listed = [];
  for (const side of [0, 1]) {
    const rootSel = $(`img${side}-root`);
    for (const f of S.info.folders) if (f.kind !== "annotations") rootSel.append(new Option(f.name, f.name));
    if (S.info.annotations) rootSel.append(new Option("annotations", "annotations"));
    rootSel.addEventListener("change", guarded(() => listImages(side, rootSel.value)));
    const pathSel = $(`img${side}-path`);
    pathSel.addEventListener("change", guarded(async () => {
      const ref = { root: rootSel.value, path: pathSel.value }, images = [...S.images];
      images[side] = ref;
      if (!ref.path) return;
      if (!mayLeavePair(images)) {  // back to the shown image
        const shown = S.images[side];
        if (shown) await setImage(side, shown, true); else pathSel.value = "";
        return;
      }
      await loadImage(side, ref);
      clearResults();
    }));
    $(`img${side}-upload`).addEventListener("change", guarded(async (e) => {
      const file = e.target.files[0];
      if (!file || !mayLeavePair()) { e.target.value = ""; return; }
      const form = new FormData();
      form.append("file", file);
      const ref = await api("/api/upload", { method: "POST", body: form });
      e.target.value = "";
      await setImage(side, { root: ref.root, path: ref.path });
    }));
    if (rootSel.options.length) listed.push(listImages(side, rootSel.value).catch(showError));
  }
  return Promise.all(listed);
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
  const warnings = m.warnings || [];
  $("warnings").hidden = !warnings.length;
  $("warnings-summary").textContent = `${warnings.length} warning${warnings.length === 1 ? "" : "s"}`;
  $("warnings-list").innerHTML = "";
  for (const text of warnings) {
    const li = document.createElement("li");
    li.textContent = text;
    $("warnings-list").append(li);
  }
  const decisions = m.decisions || [];  // the adaptive steps' choices and why (views tried, vote, DTM frame)
  $("decisions").hidden = !decisions.length;
  $("decisions-list").innerHTML = "";
  for (const text of decisions) {
    const li = document.createElement("li");
    li.textContent = text.trim();
    if (text.startsWith("  ")) li.className = "sub";
    $("decisions-list").append(li);
  }
  renderInfo(`${m.count} matches: click a keypoint to see its match`);
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
    label.title = `${name}: ${title} (${count})`;
    label.append(box2, " ", swatch, `${name}: ${title} (${count})`);
    box.append(label);
  }
}

function renderStageTable() {
  const table = $("stage-table");
  table.innerHTML = "";
  const seconds = (S.stages && S.stages.seconds) || (S.matches && S.matches.seconds) || {};
  const counts = (S.stages && S.stages.counts) || (S.matches && S.matches.counts) || {};
  $("stage-box").hidden = !Object.keys(seconds).length && !Object.keys(counts).length;
  if ($("stage-box").hidden) return;
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

const matchHandler = {
  click(pane, x, y) {  // returns how to take the click back (a double-click fits the pane and selects nothing)
    const m = S.matches;
    if (!m || !m.count) return undefined;
    const before = { selected: S.selected, info: $("info").textContent };
    const undo = () => {
      if (S.matches !== m) return;
      S.selected = before.selected; renderInfo(before.info); view.redraw();
    };
    const pts = pane === 0 ? m.keypoints0 : m.keypoints1;
    const k = nearest(pts, x, y, 10, view.views[pane].s);
    if (k < 0) { S.selected = null; renderInfo(`${m.count} matches`); view.redraw(); return undo; }
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
    return undo;
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
      const viewed = [0, 1].map((i) => (name === "planes" && layer[`views${i}`] ? layer[`views${i}`][label] : null))
        .map((view, i) => (view && view[0] > 1
          ? ` (image ${i}'s block in its simulated view of tilt ${+view[0].toFixed(2)} at ${+view[1].toFixed(1)} deg)` : ""));
      const where = name === "planes" ? `block pair ${layer.block_pairs[label].join(" / ")}` + viewed.join("")
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
  if (!mayLeavePair(m.images)) return;
  for (const row of $("run-pairs").querySelectorAll("tr.selected")) row.classList.remove("selected");
  if (tr) tr.classList.add("selected");
  clearResults();
  if (m.images_missing) showError(m.images_missing);
  for (const side of [0, 1]) {
    if (m.images[side]) await setImage(side, m.images[side], true);
    else { S.imgs[side] = null; S.images[side] = null; showPairAnnotation(); }
  }
  showMatches(m, { run: name, index }, `${base}/files/`);
  if (m.has_stages) await loadStages(`${base}/stages`);
}
