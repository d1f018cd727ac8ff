// Shooting on the page: a live view from the rear camera that takes a photo each time the phone has
// turned about 12° round the item (once it is still and the frame is sharp), a ring of the headings
// covered, and each photo's gravity and heading, sent beside the photos as capture.json.
// Plain JavaScript, no build step. Only window.windowshopCapture is global: open() and reset() for
// app.js, and the pure functions (the maths) so that a test can check them in the browser.

(() => {  // a scope of its own: app.js shares the page's globals
"use strict";

const STEP_DEG = 12;           // a photo each time the phone has turned this far round the item
const STEADY_MS = 300;         // ...and has been still for this long
const STEADY_DEG = 1.5;        // "still": turned less than this within STEADY_MS
const STEADY_RATE = 15;        // ...and spinning slower than this (°/s) where devicemotion says so
const FAST_RATE = 45;          // turning faster than this (°/s): "slower"
const STEEP_DEG = 80;          // looking down more steeply than this, the heading means nothing
const SEGMENTS = 36;           // the coverage ring's segments, 10° each
const COVER_HALF_DEG = 7.5;    // a photo covers its heading ± this: neighbours 12-15° apart leave no gap
const FULL_SHARE = 0.9;        // a ring this well covered is full
const RING_STEP_DEG = 15;      // a photo of the higher ring looks down this much more than the first's median
const BLUR_RATIO = 0.4;         // sharper than this share of the recent kept photos' median, or blurred...
const DETAIL_RATIO = 0.5;      // ...unless the finest detail's share of the edges held up (see judge)
const BLUR_FLOOR = 1e-4;       // variance of the Laplacian (grey 0..1) under which any frame is blurred
const RECENT = 7;              // the kept photos the running median is taken over
const DARK_FLOOR = 0.1;        // mean brightness (0..1) under which a frame is too dark
const ANALYSIS_WIDTH = 160;    // the grey copy that sharpness and brightness are measured on
const JPEG_QUALITY = 0.92;
const TICK_MS = 100;           // how often the page looks at the sensors and decides
const RETRY_MS = 400;          // after a frame was not kept, the next try
const TIMER_MS = 2000;         // the timed shutter, where there are no motion sensors
const NO_SENSOR_MS = 1500;     // no orientation event this long after the camera started: no sensors
const NOTICE_MS = 1500;        // how long "blurred — not kept" and the like stay up
const GRAVITY = 9.81;
const CONSTRAINTS = {  // the rear camera at the highest resolution the device offers
  audio: false,
  video: { facingMode: "environment", width: { ideal: 4096 }, height: { ideal: 4096 } },
};

const $ = (id) => document.getElementById(id);
const rad = (d) => (d * Math.PI) / 180;
const deg = (r) => (r * 180) / Math.PI;
const clamp = (v, low, high) => Math.min(high, Math.max(low, v));
const wrap360 = (d) => ((d % 360) + 360) % 360;

// ---- the maths: pure functions --------------------------------------------------------------

// The device-to-earth rotation of a deviceorientation reading (W3C: R = Rz(alpha)·Rx(beta)·Ry(gamma);
// device x = right of the screen, y = its top, z = out of the screen), as rows.
function rotation(alpha, beta, gamma) {
  const [a, b, g] = [alpha || 0, beta, gamma].map(rad);
  const [ca, sa, cb, sb, cg, sg] = [Math.cos(a), Math.sin(a), Math.cos(b), Math.sin(b),
    Math.cos(g), Math.sin(g)];
  return [
    [ca * cg - sa * sb * sg, -sa * cb, ca * sg + sa * sb * cg],
    [sa * cg + ca * sb * sg, ca * cb, sa * sg - ca * sb * cg],
    [-cb * sg, sb, cb * cg],
  ];
}

// The angle (°) between two orientations {alpha, beta, gamma}.
function rotationAngle(o1, o2) {
  const r1 = rotation(o1.alpha, o1.beta, o1.gamma);
  const r2 = rotation(o2.alpha, o2.beta, o2.gamma);
  let trace = 0;
  for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) trace += r1[i][j] * r2[i][j];
  return deg(Math.acos(clamp((trace - 1) / 2, -1, 1)));
}

function normalise(v) {
  const size = Math.hypot(...v);
  return size > 0 ? v.map((x) => x / size) : null;
}

// Up (opposite to gravity) in the device frame, from the orientation angles: the earth's z in it.
function upDevice(beta, gamma) {
  const [b, g] = [rad(beta), rad(gamma)];
  return [-Math.cos(b) * Math.sin(g), Math.sin(b), Math.cos(b) * Math.cos(g)];
}

// Up in the device frame from devicemotion's accelerationIncludingGravity, which points up at rest.
function upFromMotion(acceleration) {
  return normalise([acceleration.x, acceleration.y, acceleration.z]);
}

// Up in the photo's camera frame (OpenCV: x right, y down, z into the scene; the rear camera looks
// along the device's -z), for a screen turned by `angle` degrees (screen.orientation.angle).
function upCamera(up, angle = 0) {
  const a = rad(angle);
  const sx = up[0] * Math.cos(a) - up[1] * Math.sin(a);
  const sy = up[0] * Math.sin(a) + up[1] * Math.cos(a);
  return [sx, -sy, -up[2]];
}

// Where the rear camera looks, in the earth frame (x east, y north, z up): R·(0, 0, -1).
function viewDirection(alpha, beta, gamma) {
  const r = rotation(alpha, beta, gamma);
  return [-r[0][2], -r[1][2], -r[2][2]];
}

// The azimuth of the view (°, 0..360, clockwise seen from above); null looking straight down or up.
function heading(alpha, beta, gamma) {
  const d = viewDirection(alpha, beta, gamma);
  if (Math.hypot(d[0], d[1]) < 1e-6) return null;
  return wrap360(deg(Math.atan2(d[0], d[1])));
}

// How far below the horizon the camera looks (°).
function elevation(alpha, beta, gamma) {
  return deg(Math.asin(clamp(-viewDirection(alpha, beta, gamma)[2], -1, 1)));
}

// The angle between two headings (°, 0..180).
function turned(h1, h2) {
  const d = wrap360(h1 - h2);
  return Math.min(d, 360 - d);
}

function median(values) {
  if (!values.length) return null;
  const sorted = [...values].sort((a, b) => a - b);
  const middle = sorted.length >> 1;
  return sorted.length % 2 ? sorted[middle] : (sorted[middle - 1] + sorted[middle]) / 2;
}

// Was the phone still over the last `windowMs`? Samples {t, alpha, beta, gamma}, oldest first; the
// reading before the window is the orientation the window started with (a still phone may send none).
function steadiness(samples, now, windowMs = STEADY_MS) {
  if (!samples.length) return { steady: false, speed: 0 };
  const current = samples[samples.length - 1];
  let from = samples.length - 1;
  while (from >= 0 && samples[from].t > now - windowMs) from--;
  if (from < 0) return { steady: false, speed: 0 };  // not watched for long enough yet
  let most = 0;
  for (let i = from; i < samples.length; i++) most = Math.max(most, rotationAngle(samples[i], current));
  return { steady: most < STEADY_DEG, speed: rotationAngle(samples[from], current) / (windowMs / 1000) };
}

// Sharpness (variance of the Laplacian), mean brightness, and detail (the Laplacian's variance over
// the mean squared gradient: what share of the edges' energy is fine detail) of a small RGBA copy
// {data, width, height}.
function frameStats(image) {
  const { data, width, height } = image;
  const grey = new Float64Array(width * height);
  let sum = 0;
  for (let i = 0, p = 0; i < grey.length; i++, p += 4) {
    grey[i] = (0.299 * data[p] + 0.587 * data[p + 1] + 0.114 * data[p + 2]) / 255;
    sum += grey[i];
  }
  let n = 0, total = 0, squares = 0, gradient = 0;
  for (let y = 1; y < height - 1; y++) {
    for (let x = 1; x < width - 1; x++) {
      const i = y * width + x;
      const v = grey[i - 1] + grey[i + 1] + grey[i - width] + grey[i + width] - 4 * grey[i];
      n++; total += v; squares += v * v;
      gradient += (grey[i + 1] - grey[i]) ** 2 + (grey[i + width] - grey[i]) ** 2;
    }
  }
  const sharpness = n ? squares / n - (total / n) ** 2 : 0;
  const brightness = sum / Math.max(1, grey.length);
  return { sharpness, brightness, detail: gradient > 0 ? (sharpness * n) / gradient : 0 };
}

// Why a frame is not kept ("dark", "blurred") or null. Blur is judged against the running median of
// the photos kept last (`recent`: their frameStats), once there are a few, and an absolute floor. A
// plain side of the item (or a bare wall behind it) also has a low Laplacian variance: its detail
// share stays as high as the others', where blur takes the fine detail first.
function judge(stats, recent) {
  if (stats.brightness < DARK_FLOOR) return "dark";
  if (stats.sharpness < BLUR_FLOOR) return "blurred";
  if (recent.length < 3) return null;
  const sharpness = median(recent.map((r) => r.sharpness));
  const detail = median(recent.map((r) => r.detail));
  return stats.sharpness < BLUR_RATIO * sharpness && stats.detail < DETAIL_RATIO * detail ? "blurred" : null;
}

// The ring a photo looking `elev` degrees down belongs to: 0, the first pass, or 1, the higher one
// (a clear step above the first ring's median; the first photos set what the first ring is).
function ringOf(elev, lowElevations) {
  if (elev === null || !lowElevations.length) return 0;
  return elev >= median(lowElevations) + RING_STEP_DEG ? 1 : 0;
}

function segmentOf(headingDeg, segments = SEGMENTS) {
  return Math.floor(wrap360(headingDeg) / (360 / segments)) % segments;
}

// Which of the ring's segments the photos at `headings` cover: those whose middle lies within
// COVER_HALF_DEG of a photo (one photo per 12° then fills the circle, without gaps).
function coveredSegments(headings, segments = SEGMENTS, half = COVER_HALF_DEG) {
  const size = 360 / segments;
  const near = (middle) => headings.some((h) => turned(middle, h) <= half);
  return Array.from({ length: segments }, (_, i) => near((i + 0.5) * size));
}

const share = (covered) => covered.filter(Boolean).length / covered.length;

// Whether a photo is due at `pose` {heading, elevation}: the first one, or one at least STEP_DEG
// from every photo of the same ring (going on past the start of a full ring takes none).
function wantsPhoto(pose, photos) {
  if (!photos.length) return true;
  if (pose.heading === null || pose.elevation > STEEP_DEG) return false;
  const ring = ringOf(pose.elevation, lowElevations(photos));
  return photos.filter((p) => p.ring === ring && p.heading_deg !== null)
    .every((p) => turned(p.heading_deg, pose.heading) >= STEP_DEG - 1e-6);  // 12° less rounding
}

const lowElevations = (photos) => photos.filter((p) => p.ring === 0 && p.elevation_deg !== null)
  .map((p) => p.elevation_deg);

// capture.json: what the service reads beside the photos (docs/capture.md).
function captureJson(photos, userAgent) {
  const sources = new Set(photos.map((p) => p.upSource));
  const sensors = sources.has("devicemotion") ? "devicemotion"
    : sources.has("deviceorientation") ? "deviceorientation" : "none";
  const round = (v, digits) => (v === null ? null : Number(v.toFixed(digits)));
  return {
    format: "windowshop-capture",
    version: 1,
    sensors,
    user_agent: userAgent,
    photos: photos.map((p, order) => ({
      file: p.file,
      order,
      time_ms: round(p.time_ms, 1),
      up: p.up ? p.up.map((v) => round(v, 6)) : null,
      heading_deg: round(p.heading_deg, 2),
      elevation_deg: round(p.elevation_deg, 2),
      sharpness: Number(p.sharpness.toPrecision(6)),
    })),
  };
}

// ---- the live capture ------------------------------------------------------------------------

let session = freshSession();  // the kept photos; "Shoot on the page" again goes on with them
let live = null;               // while the camera is on: its stream, timers and sensor readings

function freshSession() {
  return { photos: [], rejected: 0, start: performance.now() };
}

function reset() {
  if (live) close();
  session = freshSession();
}

const screenAngle = () => (screen.orientation ? screen.orientation.angle : Number(window.orientation) || 0);

function onOrientation(e) {
  if (e.beta == null || e.gamma == null) return;  // Chrome sends an empty event where there is no sensor
  const samples = live.orientation;
  samples.push({ t: performance.now(), alpha: e.alpha, beta: e.beta, gamma: e.gamma });
  prune(samples);
  live.events++;
  $("capture").dataset.events = String(live.events);
  if (!live.hasOrientation) sensorsFound();
}

function onMotion(e) {
  const g = e.accelerationIncludingGravity;
  const r = e.rotationRate;
  const sample = { t: performance.now() };
  if (g && g.x != null) sample.g = [g.x, g.y, g.z];
  if (r && r.alpha != null) sample.rate = Math.hypot(r.alpha, r.beta, r.gamma);
  if (sample.g || sample.rate !== undefined) live.motion.push(sample);
  prune(live.motion);
}

// Keeps the last second of readings, and the one before it (the orientation the second began with).
function prune(samples) {
  const old = performance.now() - 1000;
  while (samples.length > 1 && samples[1].t < old) samples.shift();
}

const latest = () => live.orientation[live.orientation.length - 1] || null;

// Up from gravity where the phone is not accelerating (devicemotion, averaged over STEADY_MS), else
// from the orientation angles. Where both exist and disagree in sign, the angles win: older iOS
// reported accelerationIncludingGravity the other way round.
function currentUp(now) {
  const o = latest();
  const fromAngles = o ? upDevice(o.beta, o.gamma) : null;
  const recent = live.motion.filter((s) => s.g && s.t >= now - STEADY_MS);
  if (recent.length && (!o || steadiness(live.orientation, now).steady)) {
    const mean = [0, 1, 2].map((i) => recent.reduce((sum, s) => sum + s.g[i], 0) / recent.length);
    const size = Math.hypot(...mean);
    if (Math.abs(size - GRAVITY) < 0.15 * GRAVITY) {
      let up = mean.map((v) => v / size);
      if (fromAngles && up.reduce((sum, v, i) => sum + v * fromAngles[i], 0) < 0) up = up.map((v) => -v);
      return { up, source: "devicemotion" };
    }
  }
  return fromAngles ? { up: fromAngles, source: "deviceorientation" } : { up: null, source: "none" };
}

function currentPose() {
  const o = latest();
  if (!o || o.alpha == null) return { heading: null, elevation: o ? elevation(0, o.beta, o.gamma) : null };
  return { heading: heading(o.alpha, o.beta, o.gamma), elevation: elevation(o.alpha, o.beta, o.gamma) };
}

function steadyNow(now) {
  const { steady, speed } = steadiness(live.orientation, now);
  const rates = live.motion.filter((s) => s.rate !== undefined && s.t >= now - STEADY_MS).map((s) => s.rate);
  const spinning = rates.length ? Math.max(...rates) : 0;
  return { steady: steady && spinning < STEADY_RATE, speed: Math.max(speed, spinning) };
}

// Each tick: take a photo where one is due and the phone is still, else say what to do.
function tick() {
  const now = performance.now();
  const view = $("capture");
  if (live.hasOrientation) drawRing(currentPose());
  if (live.busy) return;
  if (!live.hasOrientation) {
    if (!live.noSensors && now - live.since > NO_SENSOR_MS) sensorsMissing();
    if (live.timer && now - live.lastTimed >= TIMER_MS) { live.lastTimed = now; take(); }
    return;
  }
  const { steady, speed } = steadyNow(now);
  view.dataset.steady = String(steady);
  const pose = currentPose();
  const due = wantsPhoto(pose, session.photos);
  if (speed > FAST_RATE) say("slower", "Slower");
  else if (due && !steady) say("hold", "Hold still");
  else if (due && now - live.lastMiss >= RETRY_MS) { take(); return; }
  else if (!due) say(...guidance());
  if (steady) view.dataset.settled = String(live.events);  // decided, for this reading, what to do
}

function guidance() {
  const photos = session.photos;
  if (!photos.length) return ["point", "Point at the item and hold still"];
  const [low, high] = [0, 1].map((ring) => share(coveredSegments(headingsOf(ring))));
  if (low < FULL_SHARE) return ["around", `Keep going ${direction()}around the item`];
  if (high < FULL_SHARE) {
    return ["higher", "Now one ring from higher up: raise the phone, look down at the item"];
  }
  return ["done", "Done: send it"];
}

const headingsOf = (ring) => session.photos.filter((p) => p.ring === ring && p.heading_deg !== null)
  .map((p) => p.heading_deg);

// Headings growing clockwise (seen from above) mean walking to one's left round the item.
function direction() {
  const headings = headingsOf(0);
  let sum = 0;
  for (let i = 1; i < headings.length; i++) sum += ((headings[i] - headings[i - 1] + 540) % 360) - 180;
  return sum > 0 ? "left, " : sum < 0 ? "right, " : "";
}

// Shows a prompt; a notice ("blurred — not kept") stays up a moment before guidance replaces it.
function say(kind, text, notice = false) {
  const now = performance.now();
  if (!notice && now < live.noticeUntil) return;
  if (notice) live.noticeUntil = now + NOTICE_MS;
  const prompt = $("capture-prompt");
  if (prompt.textContent !== text) prompt.textContent = text;
  prompt.dataset.kind = kind;
}

async function grab() {
  if (live.imageCapture) {
    try {
      const bitmap = await live.imageCapture.grabFrame();
      return { image: bitmap, width: bitmap.width, height: bitmap.height, close: () => bitmap.close() };
    } catch {
      live.imageCapture = null;  // some browsers list ImageCapture but cannot grab: use the video
    }
  }
  const video = $("capture-video");
  return { image: video, width: video.videoWidth, height: video.videoHeight, close: () => {} };
}

function analyse(frame) {
  const canvas = document.createElement("canvas");
  canvas.width = ANALYSIS_WIDTH;
  canvas.height = Math.max(1, Math.round((ANALYSIS_WIDTH * frame.height) / frame.width));
  const context = canvas.getContext("2d", { willReadFrequently: true });
  context.imageSmoothingQuality = "high";  // a fair average, not every 20th pixel of a 4K frame
  context.drawImage(frame.image, 0, 0, canvas.width, canvas.height);
  return frameStats(context.getImageData(0, 0, canvas.width, canvas.height));
}

function encode(frame) {
  const canvas = document.createElement("canvas");
  [canvas.width, canvas.height] = [frame.width, frame.height];
  canvas.getContext("2d").drawImage(frame.image, 0, 0);
  return new Promise((resolve, reject) => canvas.toBlob(
    (blob) => (blob ? resolve(blob) : reject(new Error("the photo could not be encoded"))),
    "image/jpeg", JPEG_QUALITY));
}

// Takes a photo from the track; keeps it unless it is too dark or blurred.
async function take() {
  if (!live || live.busy) return;
  const current = live;
  const now = performance.now();
  const { up, source } = currentUp(now);  // the sensors as the frame is grabbed, not once it is encoded
  const pose = current.hasOrientation ? currentPose() : { heading: null, elevation: null };
  const ring = ringOf(pose.elevation, lowElevations(session.photos));
  setBusy(true);
  try {
    const frame = await grab();
    try {
      if (!frame.width || live !== current) return;  // no frame yet, or closed meanwhile
      const stats = analyse(frame);
      const verdict = judge(stats, session.photos.slice(-RECENT).map((p) => p.stats));
      if (verdict) { miss(verdict); return; }
      const blob = await encode(frame);
      if (live !== current) return;  // closed meanwhile
      const order = session.photos.length;
      session.photos.push({
        file: `capture-${String(order + 1).padStart(3, "0")}.jpg`, blob, ring, upSource: source,
        time_ms: now - session.start, up: up ? upCamera(up, screenAngle()) : null,
        heading_deg: pose.heading, elevation_deg: pose.elevation, sharpness: stats.sharpness, stats,
      });
      current.noticeUntil = 0;
      showCount();
    } finally {
      frame.close();
    }
  } catch (err) {
    if (live === current) say("error", `The photo could not be taken (${err.message || err.name})`, true);
  } finally {
    if (live === current) setBusy(false);
  }
}

function miss(verdict) {
  session.rejected++;
  live.lastMiss = performance.now();
  $("capture").dataset.rejected = String(session.rejected);
  if (verdict === "dark") say("dark", "Too dark — not kept: more light, please", true);
  else say("blurred", "Blurred — not kept: hold still a moment", true);
}

function setBusy(busy) {
  live.busy = busy;
  $("capture").dataset.busy = String(busy);
}

function showCount() {
  const n = session.photos.length;
  const photos = `${n} photo${n === 1 ? "" : "s"}`;
  $("capture").dataset.photos = String(n);
  $("capture-done").disabled = n === 0;
  if (!live.hasOrientation) { $("capture-count").textContent = photos; return; }
  const [low, high] = [0, 1].map((ring) => Math.round(100 * share(coveredSegments(headingsOf(ring)))));
  $("capture-count").textContent = `${photos} · ${low}% of the circle` +
    (headingsOf(1).length ? ` · ${high}% from higher up` : "");
  drawRing(currentPose());
}

// ---- the ring --------------------------------------------------------------------------------

// Two rings of SEGMENTS arcs round the view, the first photo's heading at the top: the first pass
// inside, the higher one outside; a dot where the phone points now.
function drawRing(pose) {
  const canvas = $("capture-ring");
  const scale = window.devicePixelRatio || 1;
  const [w, h] = [Math.round(canvas.clientWidth * scale), Math.round(canvas.clientHeight * scale)];
  if (canvas.width !== w || canvas.height !== h) [canvas.width, canvas.height] = [w, h];
  const context = canvas.getContext("2d");
  context.clearRect(0, 0, w, h);
  const first = session.photos.find((p) => p.heading_deg !== null);
  const reference = first ? first.heading_deg : pose.heading || 0;
  const size = Math.min(w, h);
  const thickness = size * 0.035;
  const radii = [size * 0.4, size * 0.4 + thickness * 1.6];
  const toScreen = (d) => rad(d - reference - 90);  // canvas angles start at 3 o'clock
  const gap = rad(0.8);
  const arc = 360 / SEGMENTS;
  const counts = [0, 1].map((ring) => {
    const covered = coveredSegments(headingsOf(ring));
    covered.forEach((on, i) => {
      // a dark rim under a light segment: visible on a white table as on a dark floor
      for (const [style, width] of [["rgb(0 0 0 / 40%)", thickness + 2 * scale],
        [on ? "#3ddc97" : ring === 0 ? "rgb(255 255 255 / 55%)" : "rgb(255 255 255 / 25%)", thickness]]) {
        context.strokeStyle = style;
        context.lineWidth = width;
        context.beginPath();
        context.arc(w / 2, h / 2, radii[ring], toScreen(i * arc) + gap, toScreen((i + 1) * arc) - gap);
        context.stroke();
      }
    });
    return covered.filter(Boolean).length;
  });
  if (pose.heading !== null) {
    const ring = ringOf(pose.elevation, lowElevations(session.photos));
    const angle = toScreen(pose.heading);
    context.fillStyle = "#fff";
    context.beginPath();
    context.arc(w / 2 + radii[ring] * Math.cos(angle), h / 2 + radii[ring] * Math.sin(angle),
      thickness * 0.9, 0, 2 * Math.PI);
    context.fill();
    context.strokeStyle = "rgb(0 0 0 / 50%)";
    context.lineWidth = 2 * scale;
    context.stroke();
  }
  canvas.dataset.covered = String(counts[0]);
  canvas.dataset.coveredHigh = String(counts[1]);
}

// ---- opening and closing ---------------------------------------------------------------------

const INSECURE = "The camera works only on a page opened over https:// or on localhost, and this " +
  "page came over plain http://. Serve it with `windowshop serve --certfile cert.pem --keyfile key.pem` " +
  "and open the https:// address, or use “Take a photo” below (the phone's camera app).";
const NO_CAMERA_API = "This browser gives web pages no live camera; use “Take a photo” below instead.";
const MOTION_REFUSED = "Without motion access the page cannot tell which way is up or how far you " +
  "turned; photos are taken by the shutter instead (or every 2 s with the timer).";

function cameraProblem(err) {
  if (err && (err.name === "NotAllowedError" || err.name === "SecurityError")) {
    return "The camera was refused. To allow it, tap the camera or lock icon beside the address " +
      "(or open the browser's site settings), allow the camera for this site, and press “Shoot on " +
      "the page” again; or use “Take a photo” below.";
  }
  if (err && (err.name === "NotFoundError" || err.name === "OverconstrainedError")) {
    return "No camera was found; use “Take a photo” below, or choose files.";
  }
  if (err && err.name === "NotReadableError") {
    return "The camera is busy (another app or tab is using it); close that and try again, " +
      "or use “Take a photo” below.";
  }
  const why = (err && (err.message || err.name)) || "unknown";
  return `The camera could not be started (${why}); use “Take a photo” below.`;
}

// Says why the live camera is not available and points at the phone's camera app (#shoot) instead.
function fail(text) {
  const error = $("capture-error");
  error.textContent = text;
  error.hidden = false;
  $("shoot").closest("label").classList.add("suggested");
}

// iOS asks for motion access only from a tap: this runs before open()'s first await.
function askMotion() {
  const asks = [window.DeviceOrientationEvent, window.DeviceMotionEvent]
    .filter((kind) => kind && typeof kind.requestPermission === "function")
    .map((kind) => kind.requestPermission().catch(() => "denied"));
  return Promise.all(asks).then((answers) => answers.every((answer) => answer === "granted"));
}

// Opens the capture screen; onDone(files) gets the kept photos and capture.json.
async function open({ onDone }) {
  if (live) return;
  $("capture-error").hidden = true;
  if (!window.isSecureContext) { fail(INSECURE); return; }
  if (!navigator.mediaDevices || !navigator.mediaDevices.getUserMedia) { fail(NO_CAMERA_API); return; }
  const motion = askMotion();
  const view = $("capture");
  view.hidden = false;
  view.dataset.state = "starting";
  document.body.classList.add("capturing");
  $("capture-prompt").textContent = "Starting the camera…";
  const motionAllowed = await motion;
  let stream;
  try {
    stream = await navigator.mediaDevices.getUserMedia(CONSTRAINTS);
  } catch (err) {
    hide();
    fail(cameraProblem(err));
    return;
  }
  start(stream, motionAllowed, onDone);
}

async function start(stream, motionAllowed, onDone) {
  const track = stream.getVideoTracks()[0];
  live = {
    stream, onDone, kept: session.photos.length, orientation: [], motion: [], events: 0,
    hasOrientation: false, noSensors: false, timer: false, busy: false, since: performance.now(),
    lastTimed: 0, lastMiss: -Infinity, noticeUntil: 0,
    imageCapture: "ImageCapture" in window ? new ImageCapture(track) : null,
  };
  const video = $("capture-video");
  video.srcObject = stream;
  await video.play().catch(() => {});  // muted and inline: allowed; the frames come either way
  track.onended = () => {  // unplugged, or taken by another app
    if (!live) return;
    close();
    fail("The camera stopped; press “Shoot on the page” to go on.");
  };
  window.addEventListener("deviceorientation", onOrientation);
  window.addEventListener("devicemotion", onMotion);
  const view = $("capture");
  Object.assign(view.dataset, { state: "live", photos: String(session.photos.length),
    rejected: String(session.rejected), events: "0", settled: "", busy: "false", steady: "false",
    sensors: "" });
  $("capture-note").hidden = motionAllowed;
  $("capture-note").textContent = motionAllowed ? "" : MOTION_REFUSED;
  $("capture-ring").hidden = true;
  $("capture-timer").hidden = true;
  showCount();
  say("point", "Point at the item and hold still");
  if (!motionAllowed) sensorsMissing();
  live.ticker = setInterval(tick, TICK_MS);
}

function sensorsFound() {
  live.hasOrientation = true;
  live.timer = false;
  $("capture").dataset.sensors = "orientation";
  $("capture-ring").hidden = false;
  $("capture-timer").hidden = true;
  showCount();
}

function sensorsMissing() {
  live.noSensors = true;
  $("capture").dataset.sensors = "none";
  $("capture-timer").hidden = false;
  setTimer(false);
  say("manual", "Press the shutter for each photo, or start the timer");
}

function setTimer(on) {
  live.timer = on;
  live.lastTimed = performance.now();
  const button = $("capture-timer");
  button.setAttribute("aria-pressed", String(on));
  button.textContent = on ? "Stop the timer" : "A photo every 2 s";
}

function hide() {
  $("capture").hidden = true;
  $("capture").dataset.state = "closed";
  document.body.classList.remove("capturing");
}

// Stops the camera and the sensors.
function close() {
  if (!live) return;
  clearInterval(live.ticker);
  for (const track of live.stream.getTracks()) track.stop();
  window.removeEventListener("deviceorientation", onOrientation);
  window.removeEventListener("devicemotion", onMotion);
  $("capture-video").srcObject = null;
  live = null;
  hide();
}

function done() {
  if (!live) return;
  const onDone = live.onDone;
  close();
  const photos = session.photos;
  if (!photos.length) return;
  const files = photos.map((p) => new File([p.blob], p.file, { type: "image/jpeg" }));
  const json = JSON.stringify(captureJson(photos, navigator.userAgent), null, 1);
  files.push(new File([json], "capture.json", { type: "application/json" }));
  onDone(files);
}

// Cancel drops the photos of this opening; those of an earlier one (already chosen) stay.
function cancel() {
  if (!live) return;
  session.photos.length = live.kept;
  close();
}

function setUp() {
  $("capture-shutter").onclick = () => take();
  $("capture-done").onclick = done;
  $("capture-cancel").onclick = cancel;
  $("capture-timer").onclick = () => setTimer(!live.timer);
  document.addEventListener("keydown", (e) => {
    if (!live) return;
    if (e.key === "Escape") cancel();
    else if (e.key === " " && e.target === document.body) { e.preventDefault(); take(); }
  });
}

setUp();
window.windowshopCapture = {
  open, reset,
  // the maths, for tests in the browser
  rotation, rotationAngle, upDevice, upFromMotion, upCamera, viewDirection, heading, elevation, turned,
  median, steadiness, frameStats, judge, ringOf, segmentOf, coveredSegments, wantsPhoto, captureJson,
  constants: { STEP_DEG, STEADY_MS, STEADY_DEG, SEGMENTS, COVER_HALF_DEG, FULL_SHARE, RING_STEP_DEG,
    BLUR_RATIO, DETAIL_RATIO, BLUR_FLOOR, RECENT, DARK_FLOOR, ANALYSIS_WIDTH, TIMER_MS },
};
})();
