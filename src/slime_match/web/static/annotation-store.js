// slime web: annotations belong to their image pair. Each pair has its own state (points, sets, undo history,
// model, name), kept while the page lives and as a draft in the browser's localStorage, which a reload
// restores together with the pair last shown; leaving a pair with unsaved points asks first.
"use strict";

const DRAFT_PREFIX = "slime-web:annotation:";  // + the pair's key: its draft
const LAST_PAIR = "slime-web:last-pair";        // the two images last shown

// the key of a pair of image references ({root, path} each), null unless both are given
function pairKey(images) {
  return images && images[0] && images[1] ? JSON.stringify(images.map((r) => [r.root, r.path])) : null;
}
const pairLabel = (images) => images.map((r) => (r ? `${r.root}/${r.path}` : "–")).join(" + ");

function blankAnnotation(images) {
  return { images: images.map((r) => (r ? { root: r.root, path: r.path } : null)), pairs: [], pending: null,
    set: 0, selected: -1, history: [], fit: null, fixedH: null, cursor: null, model: "H", name: "pair",
    epiline: null, reprojected: null, saved: "", dirty: false };
}

// the annotation of a pair: from this page's memory, else from the browser's draft, else a new one
function annotationFor(images) {
  const key = pairKey(images);
  if (key === null) return blankAnnotation(images);
  if (!S.annotations.has(key)) {
    const A = blankAnnotation(images);
    let draft = null;
    try { draft = JSON.parse(localStorage.getItem(DRAFT_PREFIX + key) || "null"); } catch (error) { draft = null; }
    if (draft && Array.isArray(draft.pairs)) {
      Object.assign(A, { pairs: draft.pairs, set: Number(draft.set) || 0, model: draft.model === "F" ? "F" : "H",
        name: String(draft.name || "pair"), dirty: !!draft.dirty, fixedH: draft.fixedH || null });
    }
    S.annotations.set(key, A);
  }
  return S.annotations.get(key);
}

// the pair's draft written to the browser (removed when there is nothing to keep)
function keepDraft(A) {
  const key = pairKey(A.images);
  if (key === null) return;
  try {
    if (!A.pairs.length && !A.dirty) localStorage.removeItem(DRAFT_PREFIX + key);
    else localStorage.setItem(DRAFT_PREFIX + key, JSON.stringify({ pairs: A.pairs, set: A.set, model: A.model,
      name: A.name, dirty: A.dirty, fixedH: A.fixedH }));
  } catch (error) {
    showError(`this browser refused to keep the draft (${error.message}): save the pair to keep it`);
  }
}

// the shown images changed: the tool shows that pair's annotation
function showPairAnnotation() {
  const A = annotationFor(S.images);
  if (A === S.annot) return;
  S.annot = A;
  $(`model-${A.model}`).checked = true;
  $("ann-name").value = A.name;
  if (pairKey(S.images)) localStorage.setItem(LAST_PAIR, JSON.stringify(S.images));
  annotationsChanged({ edited: false });
}

// whether the page may leave the shown pair for `images` (another pair when not given): asks the user when the
// shown pair has unsaved points
function mayLeavePair(images) {
  const A = S.annot;
  if (!A.dirty || !A.pairs.length || (images && pairKey(images) === pairKey(A.images))) return true;
  return window.confirm(`${pairLabel(A.images)} has ${A.pairs.length} unsaved annotated pairs. They stay as this `
    + "pair's draft in this browser (open the pair again to go on). Leave the pair?");
}

// the pair last shown, as the browser kept it (null when none)
function lastPair() {
  try {
    const images = JSON.parse(localStorage.getItem(LAST_PAIR) || "null");
    return pairKey(images) ? images : null;
  } catch (error) {
    return null;
  }
}
