// slime web: match jobs: the options (built from the server's definitions, those of `slime match`), one job
// per click, its progress and notices, the server's job list (a reloaded page finds its running job again),
// and the result.
"use strict";

// ---------------------------------------------------------------- the options

const MAIN_OPTIONS = ["ransac", "threshold", "views", "scales", "max_side"];  // the others under "More options"
const OPTION_HINTS = { threshold: "3", scales: "1,2,3", max_side: "auto", min_side: "auto", seed: "0",
  magnification: "6 (hz+)" };

// one row per option the server lists (GET /api/info): a menu where the option has choices
function buildOptions(info) {
  for (const key of info.options) {
    const row = document.createElement("div"), label = document.createElement("label");
    row.className = "row";
    label.htmlFor = `opt-${key}`; label.textContent = key.replace(/_/g, " ");
    const choices = info.choices[key] || (key === "upright" ? ["true", "false"] : null);
    let input;
    if (choices) {
      input = document.createElement("select");
      input.append(new Option("(preset)", ""));
      for (const c of choices) {
        const option = new Option(c, c);
        if (key === "device" && c === "cuda" && !info.cuda) { option.disabled = true; option.text = "cuda (none here)"; }
        input.append(option);
      }
    } else {
      input = document.createElement("input");
      input.placeholder = OPTION_HINTS[key] || "(preset)";
      if (key === "workers") {
        Object.assign(input, { type: "number", min: 1, max: info.max_workers, placeholder: `auto (1-${info.max_workers})` });
      }
    }
    input.id = `opt-${key}`; input.dataset.option = key;
    row.append(label, input);
    $(MAIN_OPTIONS.includes(key) ? "options-main" : "options-rest").append(row);
  }
}

function matchRequest() {
  if (!S.images[0] || !S.images[1]) throw new Error("choose two images first");
  const options = {};
  for (const input of document.querySelectorAll("[data-option]")) {
    const value = input.value.trim();
    if (value) options[input.dataset.option] = value;
  }
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

// ---------------------------------------------------------------- one job per click

async function runMatch() {
  if (S.starting) return;  // a second click while the first is being sent
  const body = matchRequest();
  S.starting = true;
  $("run").disabled = true;
  body.request = `${Date.now().toString(36)}-${Math.random().toString(36).slice(2, 10)}`;  // the click's key
  try {
    clearResults();
    follow(await api("/api/match", { method: "POST", json: body }));
  } catch (error) {
    $("run").disabled = false;
    throw error;
  } finally {
    S.starting = false;
  }
}

// show a job's progress until it ends, then its result
function follow(job) {
  S.job = job.id;
  $("run").disabled = true; $("cancel").disabled = false;
  renderJob(job);
  poll(job.id);
  listJobs().catch(showError);
}

function poll(id) {
  clearTimeout(S.polling);
  S.polling = setTimeout(async () => {
    if (S.job !== id) return;
    try {
      const job = await api(`/api/jobs/${id}`);
      if (S.job !== id) return;
      renderJob(job);
      if (job.status === "queued" || job.status === "running") { poll(id); return; }
      $("run").disabled = false; $("cancel").disabled = true;
      listJobs().catch(showError);
      if (job.status === "done") await showJobResult(job);
      else if (job.status === "failed") showError(`match failed: ${job.error}`);
    } catch (error) {
      $("run").disabled = false; $("cancel").disabled = true;
      showError(error);
    }
  }, 250);
}

async function cancelJob(id) {
  const job = await api(`/api/jobs/${id}/cancel`, { method: "POST" });
  if (id === S.job) renderJob(job);
  listJobs().catch(showError);
}

const SETUP_HINT = "loading the models; the first match also starts the matching worker, and on a new install "
  + "numba compiles Slime's loops during the first match (a minute or more, once)";

function renderJob(job) {
  const live = job.status === "queued" || job.status === "running";
  $("run").disabled = live; $("cancel").disabled = !live;
  const list = $("progress");
  list.innerHTML = "";
  for (const st of job.stages) {
    const li = document.createElement("li");
    li.textContent = st.seconds === null ? st.name : `${st.name}: ${fmt(st.seconds, 2)} s`;
    if (st.seconds === null && job.status === "running") li.className = "running";
    list.append(li);
  }
  const elapsed = job.elapsed === null ? "" : ` (${fmt(job.elapsed, 1)} s)`;
  const setup = job.status === "running"
    && (!job.stages.length || job.stages.some((st) => st.name === "setup" && st.seconds === null));
  const lines = [`${job.status}${elapsed}${job.error ? ": " + job.error : ""}`];
  if (setup) lines.push(SETUP_HINT);
  if (job.status === "running") lines.push(...job.notices.map((text) => `notice: ${text}`));
  $("status").textContent = lines.join("\n");
}

// ---------------------------------------------------------------- the server's jobs

async function listJobs() {
  const { jobs } = await api("/api/jobs");
  const tbody = $("jobs").querySelector("tbody");
  tbody.innerHTML = "";
  for (const job of jobs) {
    const tr = document.createElement("tr"), what = document.createElement("td"), act = document.createElement("td");
    what.textContent = `#${job.number} ${job.preset}: ${job.images.map((r) => r.path).join(" × ")} · ${job.status}`
      + (job.elapsed === null ? "" : ` ${fmt(job.elapsed, 1)} s`);
    const button = (text, id, fn) => {
      const b = document.createElement("button");
      b.textContent = text; b.id = id;
      b.addEventListener("click", guarded(fn));
      act.append(b);
    };
    if (job.status === "queued" || job.status === "running") {
      if (S.job !== job.id) button("follow", `job-follow-${job.id}`, () => follow(job));
      button("cancel", `job-cancel-${job.id}`, () => cancelJob(job.id));
    } else if (job.status === "done") {
      button("show", `job-show-${job.id}`, () => mayLeavePair(job.images) && showJobResult(job));
    }
    tr.append(what, act);
    tbody.append(tr);
  }
  const live = jobs.filter((job) => job.status === "queued" || job.status === "running").length;
  $("jobs-summary").textContent = `Jobs (${jobs.length}${live ? `, ${live} running` : ""})`;
  return jobs;
}

// after a reload: follow the newest job that still runs
async function reattach() {
  const live = (await listJobs()).find((job) => job.status === "queued" || job.status === "running");
  if (live) { $("jobs-box").open = true; follow(live); }
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
