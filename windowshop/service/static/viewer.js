// A small GLB viewer for windowshop's page: plain WebGL, no library, no build step.
// showModel(canvas, url) fetches a binary glTF (one mesh, as `windowshop export` writes it),
// draws it lit from the viewer's side, and lets the user orbit it (drag), zoom (wheel, pinch)
// and turn it with the arrow keys. canvas.dataset.state becomes "ready" once it is drawn, or
// "failed" (with canvas.dataset.error) when the file or the browser cannot show it; it resolves
// to the GLB's orbit (below; null when it has none or could not be read), which the page's embed
// snippet also needs, drawn or not. Only showModel is global.
// The GLB's scene extras may hold windowshop.orbit (windowshop/export/orbit.py): the side to open
// on (`start`, degrees of yaw: the camera at (sin, ., cos) about +Y from the model's centre) and,
// when the photos did not go all round (`limited`), the yaw range `min`..`max` (the covered arc
// plus a margin) the view may turn through, said in a note beside it. canvas.dataset.yaw holds
// the current yaw in degrees (the browser test reads it).

(() => {  // a scope of its own: app.js shares the page's globals
"use strict";

const VERTEX_SHADER = `
attribute vec3 position;
attribute vec3 normal;
attribute vec2 uv;
attribute vec3 colour;
uniform mat4 viewProjection;
varying vec3 vNormal;
varying vec2 vUv;
varying vec3 vColour;
void main() {
  vNormal = normal;
  vUv = uv;
  vColour = colour;
  gl_Position = viewProjection * vec4(position, 1.0);
}`;

const FRAGMENT_SHADER = `
precision mediump float;
uniform sampler2D baseColour;
uniform float textured;
uniform vec3 eye;
varying vec3 vNormal;
varying vec2 vUv;
varying vec3 vColour;
void main() {
  vec3 base = textured > 0.5 ? texture2D(baseColour, vUv).rgb : vColour;
  vec3 n = normalize(vNormal);
  float key = max(dot(n, normalize(eye + vec3(0.0, 2.0, 0.0))), 0.0);
  float sky = 0.5 + 0.5 * n.y;
  gl_FragColor = vec4(base * (0.45 + 0.45 * key + 0.15 * sky), 1.0);
}`;

const COMPONENTS = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4 };
const ARRAYS = { 5121: Uint8Array, 5123: Uint16Array, 5125: Uint32Array, 5126: Float32Array };

// ---- reading the GLB -------------------------------------------------------------------------

function parseGlb(buffer) {
  const view = new DataView(buffer);
  if (view.getUint32(0, true) !== 0x46546c67) throw new Error("not a GLB file");
  let offset = 12;
  let json = null;
  let bin = null;
  while (offset < view.byteLength) {
    const length = view.getUint32(offset, true);
    const type = view.getUint32(offset + 4, true);
    const chunk = buffer.slice(offset + 8, offset + 8 + length);
    if (type === 0x4e4f534a) json = JSON.parse(new TextDecoder().decode(chunk));
    if (type === 0x004e4942) bin = chunk;
    offset += 8 + length;
  }
  if (!json || !bin) throw new Error("the GLB has no JSON or no binary chunk");
  return { json, bin };
}

function bufferViewBytes(glb, index) {
  const view = glb.json.bufferViews[index];
  const start = view.byteOffset || 0;
  return glb.bin.slice(start, start + view.byteLength);
}

function accessor(glb, index) {
  if (index === undefined) return null;
  const a = glb.json.accessors[index];
  const bytes = bufferViewBytes(glb, a.bufferView).slice(a.byteOffset || 0);
  const Kind = ARRAYS[a.componentType];
  const values = new Kind(bytes, 0, a.count * COMPONENTS[a.type]);
  if (a.normalized && Kind !== Float32Array) {  // e.g. 8-bit vertex colours
    return Float32Array.from(values, (v) => v / (Kind === Uint8Array ? 255 : 65535));
  }
  return values;
}

async function baseColourImage(glb, primitive) {
  const material = glb.json.materials && glb.json.materials[primitive.material];
  const info = material && material.pbrMetallicRoughness
    && material.pbrMetallicRoughness.baseColorTexture;
  if (!info) return null;
  const image = glb.json.images[glb.json.textures[info.index].source];
  const blob = new Blob([bufferViewBytes(glb, image.bufferView)], { type: image.mimeType });
  return createImageBitmap(blob);
}

// ---- matrices (column-major, as WebGL takes them) --------------------------------------------

function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2);
  return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) / (near - far), -1,
          0, 0, (2 * far * near) / (near - far), 0];
}

function lookAt(eye, target) {
  const sub = (a, b) => a.map((v, i) => v - b[i]);
  const norm = (a) => { const l = Math.hypot(...a) || 1; return a.map((v) => v / l); };
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                           a[0] * b[1] - a[1] * b[0]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const z = norm(sub(eye, target));
  const x = norm(cross([0, 1, 0], z));
  const y = cross(z, x);
  return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
          -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
}

function multiply(a, b) {
  const out = new Array(16).fill(0);
  for (let c = 0; c < 4; c++) {
    for (let r = 0; r < 4; r++) {
      for (let k = 0; k < 4; k++) out[c * 4 + r] += a[k * 4 + r] * b[c * 4 + k];
    }
  }
  return out;
}

// ---- drawing -----------------------------------------------------------------------------------

function program(gl) {
  const compile = (type, source) => {
    const shader = gl.createShader(type);
    gl.shaderSource(shader, source);
    gl.compileShader(shader);
    if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(shader));
    return shader;
  };
  const p = gl.createProgram();
  gl.attachShader(p, compile(gl.VERTEX_SHADER, VERTEX_SHADER));
  gl.attachShader(p, compile(gl.FRAGMENT_SHADER, FRAGMENT_SHADER));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
  return p;
}

function attribute(gl, p, name, values, size, fallback) {
  const location = gl.getAttribLocation(p, name);
  if (location < 0) return;
  if (!values) {  // absent: a constant
    gl.disableVertexAttribArray(location);
    gl.vertexAttrib3f(location, ...fallback);
    return;
  }
  gl.bindBuffer(gl.ARRAY_BUFFER, gl.createBuffer());
  gl.bufferData(gl.ARRAY_BUFFER, values, gl.STATIC_DRAW);
  gl.enableVertexAttribArray(location);
  gl.vertexAttribPointer(location, size, gl.FLOAT, false, 0, 0);
}

function upload(gl, p, glb, image) {
  const primitive = glb.json.meshes[0].primitives[0];
  const a = primitive.attributes;
  const positions = accessor(glb, a.POSITION);
  const colours = accessor(glb, a.COLOR_0);
  attribute(gl, p, "position", positions, 3);
  attribute(gl, p, "normal", accessor(glb, a.NORMAL), 3, [0, 1, 0]);
  attribute(gl, p, "uv", accessor(glb, a.TEXCOORD_0), 2, [0, 0, 0]);
  const size = colours ? colours.length / (positions.length / 3) : 3;
  attribute(gl, p, "colour", colours, size, [0.8, 0.8, 0.8]);
  let indices = accessor(glb, primitive.indices);
  if (indices instanceof Uint32Array && !(gl instanceof WebGL2RenderingContext)
      && !gl.getExtension("OES_element_index_uint")) {
    throw new Error("this browser cannot draw more than 65536 vertices");
  }
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, gl.createBuffer());
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, indices, gl.STATIC_DRAW);
  if (image) {
    gl.bindTexture(gl.TEXTURE_2D, gl.createTexture());
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGB, gl.RGB, gl.UNSIGNED_BYTE, image);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
  }
  gl.uniform1f(gl.getUniformLocation(p, "textured"), image ? 1 : 0);
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < positions.length; i++) {
    lo[i % 3] = Math.min(lo[i % 3], positions[i]);
    hi[i % 3] = Math.max(hi[i % 3], positions[i]);
  }
  return {
    count: indices.length,
    type: indices instanceof Uint32Array ? gl.UNSIGNED_INT : gl.UNSIGNED_SHORT,
    centre: lo.map((v, i) => (v + hi[i]) / 2),
    radius: Math.hypot(...hi.map((v, i) => v - lo[i])) / 2 || 1,
  };
}

// ---- the orbit the photos support ------------------------------------------------------------

function orbitOf(glb) {
  const scenes = glb.json.scenes || [];
  const scene = scenes[glb.json.scene || 0] || {};
  const extras = scene.extras && scene.extras.windowshop;
  return (extras && extras.orbit) || null;
}

const RADIANS = Math.PI / 180;

function yawLimit(orbit) {
  if (!orbit || !orbit.limited) return (yaw) => yaw;
  const [lo, hi] = [orbit.min * RADIANS, orbit.max * RADIANS];
  return (yaw) => Math.max(lo, Math.min(hi, yaw));
}

function showNote(canvas, orbit) {
  const id = `${canvas.id || "model-view"}-note`;
  let note = document.getElementById(id);
  if (!orbit || !orbit.limited) {
    if (note) note.hidden = true;
    return;
  }
  if (!note) {
    note = document.createElement("p");
    note.id = id;
    note.className = "model-note";
    canvas.insertAdjacentElement("afterend", note);
  }
  note.hidden = false;
  note.textContent = `The photos show ${Math.round(orbit.covered_degrees)}° around the item: ` +
    `the 3D view turns across that side (and ${Math.round(orbit.margin)}° past it); ` +
    "the side nobody photographed is closed in plain grey.";
}

function controls(canvas, camera, redraw) {
  const pointers = new Map();
  let pinch = 0;
  canvas.addEventListener("pointerdown", (e) => {
    canvas.setPointerCapture(e.pointerId);
    pointers.set(e.pointerId, [e.clientX, e.clientY]);
  });
  const release = (e) => { pointers.delete(e.pointerId); pinch = 0; };
  canvas.addEventListener("pointerup", release);
  canvas.addEventListener("pointercancel", release);
  canvas.addEventListener("pointermove", (e) => {
    if (!pointers.has(e.pointerId)) return;
    const [x, y] = pointers.get(e.pointerId);
    pointers.set(e.pointerId, [e.clientX, e.clientY]);
    if (pointers.size === 2) {  // two fingers: pinch to zoom
      const [a, b] = [...pointers.values()];
      const apart = Math.hypot(a[0] - b[0], a[1] - b[1]);
      if (pinch) camera.distance *= pinch / apart;
      pinch = apart;
    } else {
      camera.yaw = camera.limit(camera.yaw - (e.clientX - x) * 0.01);
      camera.pitch = Math.max(-1.5, Math.min(1.5, camera.pitch + (e.clientY - y) * 0.01));
    }
    redraw();
  });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    camera.distance *= Math.exp(e.deltaY * 0.001);
    redraw();
  }, { passive: false });
  canvas.addEventListener("keydown", (e) => {
    const turn = { ArrowLeft: 0.2, ArrowRight: -0.2 }[e.key];
    if (turn === undefined) return;
    camera.yaw = camera.limit(camera.yaw + turn);
    redraw();
  });
}

async function showModel(canvas, url) {
  canvas.dataset.state = "loading";
  let orbit = null;
  try {
    const response = await fetch(url);
    if (!response.ok) throw new Error(`the model could not be fetched (${response.status})`);
    const glb = parseGlb(await response.arrayBuffer());
    orbit = orbitOf(glb);
    const image = await baseColourImage(glb, glb.json.meshes[0].primitives[0]);
    const options = { preserveDrawingBuffer: true, antialias: true };
    const gl = canvas.getContext("webgl2", options) || canvas.getContext("webgl", options);
    if (!gl) throw new Error("this browser has no WebGL");
    const p = program(gl);
    gl.useProgram(p);
    const mesh = upload(gl, p, glb, image);
    const limit = yawLimit(orbit);
    const camera = { yaw: limit(orbit ? orbit.start * RADIANS : 0.6), pitch: 0.35,
                     distance: 2.6 * mesh.radius, limit };
    if (orbit && orbit.limited) {
      [canvas.dataset.yawMin, canvas.dataset.yawMax] = [orbit.min, orbit.max];
    } else {
      delete canvas.dataset.yawMin;
      delete canvas.dataset.yawMax;
    }
    showNote(canvas, orbit);
    let pending = false;
    const draw = () => {
      pending = false;
      const width = canvas.clientWidth * devicePixelRatio;
      const height = canvas.clientHeight * devicePixelRatio;
      if (canvas.width !== width || canvas.height !== height) [canvas.width, canvas.height] = [width, height];
      gl.viewport(0, 0, canvas.width, canvas.height);
      gl.clearColor(1, 1, 1, 1);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      gl.enable(gl.DEPTH_TEST);
      const c = mesh.centre;
      const d = camera.distance;
      const eye = [c[0] + d * Math.cos(camera.pitch) * Math.sin(camera.yaw),
                   c[1] + d * Math.sin(camera.pitch), c[2] + d * Math.cos(camera.pitch) * Math.cos(camera.yaw)];
      const projection = perspective(0.8, canvas.width / Math.max(canvas.height, 1), d / 100, d * 10);
      gl.uniformMatrix4fv(gl.getUniformLocation(p, "viewProjection"), false,
                          multiply(projection, lookAt(eye, c)));
      gl.uniform3fv(gl.getUniformLocation(p, "eye"), eye.map((v, i) => v - c[i]));
      gl.drawElements(gl.TRIANGLES, mesh.count, mesh.type, 0);
      canvas.dataset.yaw = (camera.yaw / RADIANS).toFixed(1);
      canvas.dataset.state = "ready";
    };
    const redraw = () => { if (!pending) { pending = true; requestAnimationFrame(draw); } };
    controls(canvas, camera, redraw);
    new ResizeObserver(redraw).observe(canvas);
    draw();
  } catch (err) {
    canvas.dataset.state = "failed";
    canvas.dataset.error = String(err.message || err);
  }
  return orbit;
}

window.showModel = showModel;
})();
