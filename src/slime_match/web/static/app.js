// slime web: tabs, keys, the start, and the probe the browser tests use.
"use strict";

view.painters.push(paintOverlay, paintLayers, paintMatches, paintAnnotations);

// ---------------------------------------------------------------- tabs, keys, start

function setTab(tab) {
  S.tab = tab;
  for (const b of document.querySelectorAll(".tab")) b.classList.toggle("active", b.dataset.tab === tab);
  for (const name of ["match", "runs", "annotate"]) $(`panel-${name}`).hidden = name !== tab;
  view.handler = tab === "annotate" ? annotateHandler : matchHandler;
  $("result-section").hidden = $("display-section").hidden = tab === "annotate";
  if (tab === "annotate") annotationsChanged({ edited: false });
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
  $("preset").value = "auto";
  buildOptions(S.info);
  setupTools(S.info);
  await setupPickers();
  for (const r of S.info.runs) $("run-select").append(new Option(r, r));
  $("run-select").addEventListener("change", guarded(() => loadRun($("run-select").value)));
  if (S.info.runs.length) loadRun(S.info.runs[0]).catch(showError);
  for (const b of document.querySelectorAll(".tab")) b.addEventListener("click", () => setTab(b.dataset.tab));
  $("run").addEventListener("click", guarded(runMatch));
  $("cancel").addEventListener("click", guarded(() => S.job && cancelJob(S.job)));
  for (const id of ["max-lines", "show-matches", "show-outliers"]) $(id).addEventListener("input", () => view.redraw());
  $("ann-undo").addEventListener("click", undo);
  $("ann-delete").addEventListener("click", deleteSelected);
  $("ann-occluded").addEventListener("click", markOccluded);
  $("ann-new-set").addEventListener("click", newSet);
  $("ann-clear").addEventListener("click", () => { remember(); S.annot.pairs = []; S.annot.pending = null; annotationsChanged(); });
  for (const m of ["H", "F"]) $(`model-${m}`).addEventListener("change", () => { S.annot.model = m; annotationsChanged({ edited: false }); });
  $("ann-name").addEventListener("input", () => { S.annot.name = $("ann-name").value.trim(); keepDraft(S.annot); });
  $("ann-save").addEventListener("click", guarded(saveAnnotation));
  $("ann-download").addEventListener("click", guarded(downloadAnnotation));
  $("ann-open").addEventListener("click", guarded(() => openAnnotation($("ann-saved").value)));
  $("ann-open-file").addEventListener("click", guarded(() => openAnnotation($("ann-open-path").value.trim())));
  listSaved().catch(showError);
  S.annot = annotationFor(S.images);
  setTab("match");
  const last = lastPair();  // the pair shown before a reload, with its draft
  if (last) {
    try {
      await setImage(0, last[0], true);
      await setImage(1, last[1], true);
    } catch (error) {
      showError(`the pair shown last (${pairLabel(last)}) is not served any more: ${error.message}`);
    }
  }
  await reattach().catch(showError);
  document.body.dataset.ready = "1";
}

// for the browser tests and the console: the state, the view and a frame-time probe
window.slimeWeb = {
  S, view,
  screenOf(pane, x, y) { return view.toScreen(pane, x, y); },
  busy() { return S.fitting > 0 || view.pending; },
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
