// windowshop's page: choose files, upload them, follow the job, then play and spin the result.
// Plain JavaScript, no build step. The list of "your spins" lives in this browser's localStorage.
"use strict";

const $ = (id) => document.getElementById(id);
const STORE_KEY = "windowshop.jobs";
const FINISHED = ["done", "failed", "cancelled"];
const STAGE_ORDER = ["preparing", "training", "rendering"];
const STATE_TEXT = {
  queued: "Waiting for its turn",
  preparing: "Placing the photos around the item",
  training: "Learning what the item looks like",
  rendering: "Filming the spin",
  done: "Done: drag the picture to spin the item",
  failed: "This spin could not be made",
  cancelled: "Cancelled",
};

let chosen = [];      // files picked, dropped or shot, not yet sent
let captured = new Set();  // those of them shot on the page (capture.js): photos and capture.json
let pollTimer = null;  // the running job's next status request

// ---- the jobs of this browser --------------------------------------------------------------

function myJobs() {
  try { return JSON.parse(localStorage.getItem(STORE_KEY)) || []; } catch { return []; }
}

function saveJobs(jobs) {
  localStorage.setItem(STORE_KEY, JSON.stringify(jobs.slice(0, 50)));
}

function rememberJob(id, name) {
  saveJobs([{ id, name, created: Date.now() }, ...myJobs().filter((j) => j.id !== id)]);
}

function forgetJob(id) {
  saveJobs(myJobs().filter((j) => j.id !== id));
  localStorage.removeItem(ownerKey(id));
}

// The owner token the service gave when this browser created the job: cancel and delete need it
// (whoever has a shared link may watch the job, not remove it).
const ownerKey = (id) => `windowshop.owner.${id}`;
const isOwner = (id) => Boolean(localStorage.getItem(ownerKey(id)));
const ownerHeaders = (id) => ({ Authorization: `Bearer ${localStorage.getItem(ownerKey(id))}` });

async function showMyJobs() {
  const list = $("my-jobs");
  list.replaceChildren();
  const jobs = myJobs();
  $("no-jobs").hidden = jobs.length > 0;
  for (const job of jobs) {
    const item = document.createElement("li");
    item.dataset.id = job.id;
    const link = document.createElement("a");
    link.href = `/jobs/${job.id}`;
    link.textContent = job.name;
    const when = document.createElement("span");
    when.className = "muted";
    when.textContent = new Date(job.created).toLocaleString();
    const badge = document.createElement("span");
    badge.className = "badge";
    item.append(link, when, badge);
    list.append(item);
    fetch(`/api/jobs/${job.id}`).then(async (r) => {
      if (r.status === 404) { badge.textContent = "deleted"; forgetJob(job.id); return; }
      const status = await r.json();
      badge.textContent = status.state;
      badge.dataset.state = status.state;
    }).catch(() => { badge.textContent = "?"; });
  }
}

// ---- choosing and sending files ------------------------------------------------------------

function addFiles(files) {
  chosen = chosen.concat(Array.from(files));
  const bytes = chosen.reduce((sum, f) => sum + f.size, 0);
  $("chosen-text").textContent = `${chosenText(chosen)} (${(bytes / 1e6).toFixed(1)} MB)`;
  $("chosen").hidden = chosen.length === 0;
  $("send").disabled = chosen.length === 0;
  $("new-error").hidden = true;
}

// A capture shot on the page replaces the previous one (it goes on from it: capture.js keeps its
// photos until cleared), since one capture.json goes with an upload.
function addCapture(files) {
  chosen = chosen.filter((f) => !captured.has(f));
  captured = new Set(files);
  addFiles(files);
}

const isCaptureJson = (f) => captured.has(f) && f.name === "capture.json";

function chosenText(files) {
  const json = files.filter(isCaptureJson).length;
  const n = files.length - json;
  if (json) return `${n} photo${n === 1 ? "" : "s"} + capture.json`;
  return `${n} file${n === 1 ? "" : "s"} chosen`;
}

function clearFiles() {
  chosen = [];
  captured = new Set();
  window.windowshopCapture.reset();
  $("chosen").hidden = true;
  $("send").disabled = true;
}

function describe(files) {
  const videos = files.filter((f) => f.type.startsWith("video/")).length;
  if (videos) return "A video";
  if (files.length === 1 && /\.zip$/i.test(files[0].name)) return files[0].name;
  return `${files.filter((f) => !isCaptureJson(f)).length} photos`;
}

function showError(element, text) {
  element.textContent = text;
  element.hidden = false;
}

function upload() {
  const form = new FormData();
  for (const file of chosen) form.append("files", file, file.name);
  const request = new XMLHttpRequest();  // fetch() cannot report upload progress
  request.open("POST", "/api/jobs");
  request.responseType = "json";
  request.upload.onprogress = (e) => {
    if (!e.lengthComputable) return;
    $("upload-bar").value = e.loaded / e.total;
    $("upload-text").textContent = `Uploading… ${Math.round((100 * e.loaded) / e.total)}%`;
  };
  request.upload.onload = () => { $("upload-text").textContent = "Checking the files…"; };
  request.onload = () => {
    $("upload").hidden = true;
    $("send").disabled = false;
    const body = request.response || {};
    if (request.status === 201) {
      localStorage.setItem(ownerKey(body.id), body.owner_token);
      rememberJob(body.id, describe(chosen));
      clearFiles();
      history.pushState({}, "", body.page);
      route();
    } else {
      showError($("new-error"), body.detail || `The upload was refused (HTTP ${request.status}).`);
    }
  };
  request.onerror = () => {
    $("upload").hidden = true;
    $("send").disabled = false;
    showError($("new-error"), "The upload did not reach the service; check the connection and try again.");
  };
  $("upload").hidden = false;
  $("upload-bar").value = 0;
  $("send").disabled = true;
  $("new-error").hidden = true;
  request.send(form);
}

// ---- following a job -----------------------------------------------------------------------

function minutes(seconds) {
  if (seconds < 60) return `about ${Math.max(5, Math.round(seconds / 5) * 5)} s left`;
  return `about ${Math.round(seconds / 60)} min left`;
}

function showStages(status) {
  const current = STAGE_ORDER.indexOf(status.state);
  for (const item of $("stages").children) {
    const stage = item.dataset.stage;
    const bar = item.querySelector("progress");
    const note = item.querySelector("small");
    const seen = stage in status.stages;
    const later = current >= 0 && STAGE_ORDER.indexOf(stage) > current;
    bar.value = seen ? status.stages[stage] : 0;
    item.dataset.status = stage === status.state ? "running" : seen ? "over" : "";
    if (stage === status.state) {
      note.textContent = status.eta_seconds != null ? minutes(status.eta_seconds) : "";
    } else if (!seen && (status.state === "done" || (current >= 0 && !later))) {
      note.textContent = "not needed";
      bar.value = 1;
    } else {
      note.textContent = "";
    }
  }
}

function showStatus(status) {
  let text = STATE_TEXT[status.state] || status.state;
  if (status.state === "queued" && status.queue_position) {
    text += ` (${status.queue_position} ahead)`;
  }
  $("job-state").textContent = text;
  $("job-state").dataset.state = status.state;
  $("job-input").textContent = status.input ? `From ${status.input}` : "";
  const badge = document.querySelector(`#my-jobs li[data-id="${status.id}"] .badge`);
  if (badge) { badge.textContent = status.state; badge.dataset.state = status.state; }
  $("stages").hidden = status.state === "done";
  showStages(status);
  $("cancel").hidden = FINISHED.includes(status.state) || !isOwner(status.id);
  if (status.error) showError($("job-error"), status.error); else $("job-error").hidden = true;
  if (status.state === "done" && $("result").hidden) showResult(status);
}

async function follow(id) {
  clearTimeout(pollTimer);
  let response;
  try {
    response = await fetch(`/api/jobs/${id}`);
  } catch {
    pollTimer = setTimeout(() => follow(id), 3000);  // the service may be restarting
    return;
  }
  if (response.status === 404) {
    forgetJob(id);
    $("job-state").textContent = "There is no such spin: it was deleted, or the link is mistyped.";
    $("stages").hidden = true;
    $("delete").hidden = true;
    return;
  }
  const status = await response.json();
  showStatus(status);
  if (!FINISHED.includes(status.state)) pollTimer = setTimeout(() => follow(id), 1000);
}

// ---- the result: video, drag-to-spin viewer, download, share --------------------------------

function showResult(status) {
  $("result").hidden = false;
  const video = $("video");
  video.poster = status.links.poster;
  video.src = status.links.video;
  video.play().catch(() => {});  // autoplay may be refused; the video then waits for a tap
  $("download").href = status.links.video;
  $("download").hidden = false;
  $("share").hidden = false;
  startSpin(status.links.frames);
  showReport(status.links);
  showModels(status.links);
}

// The 3D model (viewer.js) and, on iPhones and iPads, AR Quick Look of the USDZ.
function showModels(links) {
  $("model").hidden = !links.model;
  if (!links.model) return;
  $("model-download").href = links.model;
  $("usdz-download").href = links.usdz;
  const ar = $("ar");
  ar.href = links.usdz;
  $("ar-image").src = links.poster;
  ar.hidden = !document.createElement("a").relList.supports("ar");  // Safari on iOS only
  $("embed").hidden = true;
  window.showModel($("model-view"), links.model).then((orbit) => showEmbed(links, orbit));
}

// ---- the embed snippet: the model on the seller's own shop page, with Google's model-viewer ----

// As text only: this page never loads it (its Content-Security-Policy allows no other origin).
const MODEL_VIEWER_SCRIPT = '<script type="module" ' +
  'src="https://ajax.googleapis.com/ajax/libs/model-viewer/3.5.0/model-viewer.min.js"></script>';

// The same element as windowshop/export/orbit.py's embed_snippet (the browser test holds them
// equal): the orbit's attributes are the GLB's own (`model_viewer`); only the addresses are put in
// here, absolute, since the snippet goes on another site.
function modelViewerElement(links, orbit) {
  const escape = (text) => String(text).replace(/[&<>"']/g, (c) =>
    ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#x27;" })[c]);
  const quoted = (values) => Object.entries(values).filter(([, v]) => v != null)
    .map(([k, v]) => `${k}="${escape(v)}"`);
  const address = (path) => path && new URL(path, location.href).href;
  const parts = [...quoted({ src: address(links.model), "ios-src": address(links.usdz) }),
                 "camera-controls", ...quoted((orbit && orbit.model_viewer) || {})];
  return `<model-viewer ${parts.join(" ")}></model-viewer>`;
}

function showEmbed(links, orbit) {
  $("embed-code").value = `${MODEL_VIEWER_SCRIPT}\n${modelViewerElement(links, orbit)}`;
  $("embed-status").textContent = "";
  $("embed").hidden = false;
}

// Copies the snippet; where the clipboard is refused (no permission, plain HTTP) it stays
// selected, for the seller to copy by hand.
async function copyEmbed() {
  const code = $("embed-code");
  code.select();
  try {
    await navigator.clipboard.writeText(code.value);
    $("embed-status").textContent = "Copied";
  } catch {
    $("embed-status").textContent = "Selected: press Ctrl+C (⌘C on a Mac) to copy";
  }
}

// What the photos gave and what to reshoot: the capture's quality report.
async function showReport(links) {
  const response = await fetch(links.report);
  if (!response.ok) return;
  const report = await response.json();
  const psnr = report.held_out_psnr === null ? "" :
    `, held-out photos reproduced at ${report.held_out_psnr.toFixed(1)} dB`;
  $("quality-summary").textContent = `${report.placed} of ${report.photos} photos placed, ` +
    `${Math.round(report.covered_degrees || 0)}° of the circle covered${psnr}.`;
  // which part of the result the checks stand behind (windowshop.quality.trust)
  const trust = $("quality-trust");
  trust.hidden = !report.trust;
  trust.textContent = report.trust ? report.trust.summary : "";
  trust.dataset.level = report.trust ? report.trust.level : "";
  // what the phone's sensors gave (a capture shot on the page): up from gravity, headings
  const priors = $("quality-priors");
  priors.hidden = !(report.priors && report.priors.summary);
  priors.textContent = priors.hidden ? "" : report.priors.summary;
  $("quality-note").hidden = !report.note;
  $("quality-note").textContent = report.note || "";
  const list = $("advice");
  list.replaceChildren(...report.advice.map((tip) => {
    const item = document.createElement("li");
    item.textContent = tip;
    return item;
  }));
  $("coverage").src = links.coverage;
}

function startSpin(urls) {
  const view = $("spin");
  const image = $("spin-img");
  const frames = urls.map((url) => { const im = new Image(); im.src = url; return im; });
  let index = 0;
  let dragStart = null;  // {x, index} while a finger or the mouse is down
  view.setAttribute("aria-valuemax", String(Math.max(0, urls.length - 1)));

  const show = (i) => {
    index = ((i % urls.length) + urls.length) % urls.length;
    image.src = frames[index].src;
    view.dataset.frame = String(index);
    view.setAttribute("aria-valuenow", String(index));
  };
  // One drag across the viewer's width turns the item once around.
  const pixelsPerFrame = () => Math.max(2, view.clientWidth / urls.length);

  view.onpointerdown = (e) => {
    dragStart = { x: e.clientX, index };
    view.setPointerCapture(e.pointerId);
    view.classList.add("dragging");
  };
  view.onpointermove = (e) => {
    if (dragStart) show(dragStart.index - Math.round((e.clientX - dragStart.x) / pixelsPerFrame()));
  };
  view.onpointerup = view.onpointercancel = () => {
    dragStart = null;
    view.classList.remove("dragging");
  };
  view.onkeydown = (e) => {
    if (e.key === "ArrowLeft") show(index + 1);
    else if (e.key === "ArrowRight") show(index - 1);
  };
  if (urls.length) show(0);
}

async function share() {
  const url = location.origin + location.pathname;
  if (navigator.share) {
    try { await navigator.share({ title: "A 360° spin", url }); return; } catch { /* fall back */ }
  }
  $("share-url").value = url;
  $("share-note").hidden = false;
  $("share-url").select();
  try { await navigator.clipboard.writeText(url); } catch { /* the selected field is the fallback */ }
}

async function cancelJob(id) {
  const response = await fetch(`/api/jobs/${id}/cancel`, { method: "POST", headers: ownerHeaders(id) });
  if (response.status === 403) { showError($("job-error"), (await response.json()).detail); return; }
  follow(id);
}

async function deleteJob(id) {
  if (!confirm("Delete this spin and its files for everyone with the link?")) return;
  const response = await fetch(`/api/jobs/${id}`, { method: "DELETE", headers: ownerHeaders(id) });
  if (response.status === 403) { showError($("job-error"), (await response.json()).detail); return; }
  forgetJob(id);
  history.pushState({}, "", "/");
  route();
}

// ---- pages ---------------------------------------------------------------------------------

function route() {
  clearTimeout(pollTimer);
  const match = location.pathname.match(/^\/jobs\/([A-Za-z0-9_-]+)$/);
  $("new").hidden = Boolean(match);
  $("job").hidden = !match;
  if (match) {
    const id = match[1];
    $("result").hidden = true;
    $("download").hidden = $("share").hidden = $("share-note").hidden = true;
    $("delete").hidden = !isOwner(id);
    $("job-error").hidden = true;
    $("cancel").onclick = () => cancelJob(id);
    $("delete").onclick = () => deleteJob(id);
    follow(id);
  }
  showMyJobs();
}

function setUp() {
  const drop = $("drop");
  for (const input of [$("pick"), $("shoot"), $("film")]) {
    input.onchange = () => { addFiles(input.files); input.value = ""; };
  }
  drop.onclick = () => $("pick").click();
  drop.onkeydown = (e) => { if (e.key === "Enter" || e.key === " ") $("pick").click(); };
  drop.ondragover = (e) => { e.preventDefault(); drop.classList.add("over"); };
  drop.ondragleave = () => drop.classList.remove("over");
  drop.ondrop = (e) => {
    e.preventDefault();
    drop.classList.remove("over");
    addFiles(e.dataTransfer.files);
  };
  $("capture-start").onclick = () => window.windowshopCapture.open({ onDone: addCapture });
  $("clear").onclick = clearFiles;
  $("send").onclick = upload;
  $("share").onclick = share;
  $("embed-copy").onclick = copyEmbed;
  window.onpopstate = route;
  route();
}

setUp();
