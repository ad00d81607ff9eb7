// slime web: match jobs: the request, the job's progress, its result.
"use strict";

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
