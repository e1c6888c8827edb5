// se3dyn viewer: the page's application module.
//
// The page's loader (see se3dyn/viewer/html.py) inflates three.js and OrbitControls into blob:
// URLs and rewrites the two imports below to point at them: nothing is fetched from the network.
// Data come from the page itself: the JSON block #se3dyn-meta and the base64 blocks
// #se3dyn-blob-NAME (deflate; frames are quantised, see se3dyn/viewer/encode.py).
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const META = JSON.parse(document.getElementById('se3dyn-meta').textContent);
const $ = (id) => document.getElementById(id);
const n = META.t.length;
const M = META.nodes.length;
const T = Float64Array.from(META.t);
const t0 = T[0];
const t1 = T[n - 1];
let renderQueued = false;  // a frame is requested (see requestRender)

// ------------------------------------------------------------------------------------------
// data blocks
const TYPES = { uint16: Uint16Array, int32: Int32Array, uint32: Uint32Array,
  float32: Float32Array, uint8: Uint8Array };

async function inflate(b64) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('deflate'));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}

async function blob(name) {
  const el = document.getElementById('se3dyn-blob-' + name);
  if (!el) throw new Error('the page has no data block ' + name);
  const bytes = await inflate(el.textContent.trim());
  const shape = el.dataset.shape.split(',').map(Number);
  if (el.dataset.codec.startsWith('delta16')) {
    // low and high byte planes, then running sums along the first axis (mod 2^16)
    const N = bytes.length / 2;
    const out = new Uint16Array(N);
    for (let i = 0; i < N; i++) out[i] = bytes[i] | (bytes[N + i] << 8);
    const row = shape[0] > 0 ? N / shape[0] : 0;
    for (let i = row; i < N; i++) out[i] = out[i] + out[i - row];
    return out;
  }
  const Type = TYPES[el.dataset.dtype];
  return new Type(bytes.buffer, bytes.byteOffset, bytes.byteLength / Type.BYTES_PER_ELEMENT);
}

// frames: positions (n, M, 3) and unit quaternions (n, M, 4), sign-continuous in time
function decodeFrames(words) {
  const pos = new Float32Array(n * M * 3);
  const quat = new Float32Array(n * M * 4);
  const lo = META.lo;
  const hi = META.hi;
  const S = Math.SQRT1_2;
  const K = 2 / 32767;
  const c = [0, 0, 0];
  for (let k = 0; k < n; k++) {
    for (let i = 0; i < M; i++) {
      const b = (k * M + i) * 6;
      const p = (k * M + i) * 3;
      const q = (k * M + i) * 4;
      for (let a = 0; a < 3; a++) {
        const l = lo[3 * i + a];
        pos[p + a] = l + (words[b + a] / 65535) * (hi[3 * i + a] - l);
      }
      const w0 = words[b + 3];
      const w1 = words[b + 4];
      const w2 = words[b + 5];
      const idx = (w0 >> 15) | ((w1 >> 15) << 1);
      c[0] = ((w0 & 0x7fff) * K - 1) * S;
      c[1] = ((w1 & 0x7fff) * K - 1) * S;
      c[2] = (w2 * K - 1) * S;
      const big = Math.sqrt(Math.max(0, 1 - c[0] * c[0] - c[1] * c[1] - c[2] * c[2]));
      let j = 0;
      let norm = 0;
      for (let a = 0; a < 4; a++) {
        const v = a === idx ? big : c[j++];
        quat[q + a] = v;
        norm += v * v;
      }
      norm = 1 / Math.sqrt(norm);
      let dot = 0;
      for (let a = 0; a < 4; a++) {
        quat[q + a] *= norm;
        if (k > 0) dot += quat[q + a] * quat[q - 4 * M + a];
      }
      if (dot < 0) for (let a = 0; a < 4; a++) quat[q + a] = -quat[q + a];
    }
  }
  return { pos, quat };
}

// ------------------------------------------------------------------------------------------
// formatting
function decimals() {
  const dt = n > 1 ? (t1 - t0) / (n - 1) : 1;
  return Math.min(6, Math.max(2, Math.ceil(-Math.log10(dt)) + 1));
}
const DEC = decimals();
const fmtT = (t) => t.toFixed(DEC);
function fmtV(v) {
  if (!Number.isFinite(v)) return String(v);
  const a = Math.abs(v);
  if (a !== 0 && (a < 1e-3 || a >= 1e5)) return v.toExponential(3);
  return v.toPrecision(4);
}
const escapeName = (s) => String(s).replaceAll('%', '%25').replaceAll('/', '%2F');

// ------------------------------------------------------------------------------------------
// scene
const up = new THREE.Vector3().fromArray(META.up);
const lo3 = new THREE.Vector3().fromArray(META.bounds.lo);
const hi3 = new THREE.Vector3().fromArray(META.bounds.hi);
const center = lo3.clone().add(hi3).multiplyScalar(0.5);
const radius = Math.max(0.5 * lo3.distanceTo(hi3), 2 * META.glyph);

const stage = $('stage');
const renderer = new THREE.WebGLRenderer({ antialias: true });
renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
renderer.setSize(stage.clientWidth, stage.clientHeight);
renderer.autoClear = false;
stage.appendChild(renderer.domElement);

const scene = new THREE.Scene();
scene.background = new THREE.Color(0xf4f5f7);
const camera = new THREE.PerspectiveCamera(35, stage.clientWidth / stage.clientHeight,
  radius / 1000, radius * 50);
camera.up.copy(up);
scene.add(camera);
const hemi = new THREE.HemisphereLight(0xffffff, 0x8d8d8d, 1.6);
hemi.position.copy(up);
scene.add(hemi);
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
sun.position.set(0.4, 0.8, 1.0);
camera.add(sun);  // light from over the viewer's shoulder, whatever the view

// a horizontal reference direction and the default view
function horizontal() {
  const e = new THREE.Vector3(1, 0, 0);
  if (Math.abs(e.dot(up)) > 0.9) e.set(0, 1, 0);
  return e.sub(up.clone().multiplyScalar(e.dot(up))).normalize();
}
const e1 = horizontal();
const e2 = new THREE.Vector3().crossVectors(up, e1);
function homeView() {
  const dir = e1.clone().multiplyScalar(1.0).addScaledVector(e2, -1.25)
    .addScaledVector(up, 0.8).normalize();
  const dist = (radius * 0.95) / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2));
  camera.position.copy(center).addScaledVector(dir, dist);
  camera.lookAt(center);
  if (controls) {
    controls.target.copy(center);
    controls.update();
  }
}
let controls = null;
controls = new OrbitControls(camera, renderer.domElement);
controls.enableDamping = false;
controls.addEventListener('change', () => requestRender());
homeView();

// grid under the motion, normal to "up"
{
  const size = 2.4 * radius;
  const grid = new THREE.GridHelper(size, 24, 0xc8ccd2, 0xdfe2e6);
  grid.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), up);
  const low = Math.min(lo3.dot(up), hi3.dot(up)) - 2.5 * META.glyph;
  grid.position.copy(center).addScaledVector(up, low - center.dot(up));
  scene.add(grid);
}

// ------------------------------------------------------------------------------------------
// axes inset: inertial axes and gravity, turning with the view
const hud = new THREE.Scene();
const hudCam = new THREE.OrthographicCamera(-1.6, 1.6, 1.6, -1.6, 0.1, 10);
function label(text, color) {
  const c = document.createElement('canvas');
  c.width = 64;
  c.height = 64;
  const g = c.getContext('2d');
  g.fillStyle = color;
  g.font = 'bold 44px sans-serif';
  g.textAlign = 'center';
  g.textBaseline = 'middle';
  g.fillText(text, 32, 34);
  const s = new THREE.Sprite(new THREE.SpriteMaterial({ map: new THREE.CanvasTexture(c),
    depthTest: false }));
  s.scale.set(0.45, 0.45, 1);
  return s;
}
[['x', 0xd62728, '#d62728'], ['y', 0x2ca02c, '#2ca02c'], ['z', 0x1f77b4, '#1f77b4']]
  .forEach(([name, hex, css], a) => {
    const d = new THREE.Vector3().setComponent(a, 1);
    hud.add(new THREE.ArrowHelper(d, new THREE.Vector3(), 1, hex, 0.25, 0.12));
    const l = label(name, css);
    l.position.copy(d).multiplyScalar(1.25);
    hud.add(l);
  });
const g3 = new THREE.Vector3().fromArray(META.gravity);
if (g3.lengthSq() > 0) {
  // gravity: a grey arrow from the origin of the inset, labelled g
  const gd = g3.clone().normalize();
  hud.add(new THREE.ArrowHelper(gd, new THREE.Vector3(), 1.1, 0x555555, 0.3, 0.16));
  const gl = label('g', '#444444');
  gl.position.copy(gd).multiplyScalar(1.4);
  hud.add(gl);
}
const HUD_PX = 110;

// ------------------------------------------------------------------------------------------
// parts: instanced meshes, one per (geometry, role)
function unitGeometry(g, meshes, count) {
  // fewer facets when many instances share the geometry (long chains stay light to draw)
  const fine = count <= 100;
  const seg = fine ? 28 : 12;
  let geo;
  if (g.kind === 'box') geo = new THREE.BoxGeometry(1, 1, 1);
  else if (g.kind === 'sphere') geo = new THREE.SphereGeometry(1, seg, fine ? 18 : 8);
  else if (g.kind === 'cylinder') geo = new THREE.CylinderGeometry(1, 1, 1, seg).rotateX(Math.PI / 2);
  else if (g.kind === 'cone') geo = new THREE.ConeGeometry(1, 1, 4).rotateX(Math.PI / 2);
  else if (g.kind === 'capsule') {
    geo = new THREE.CapsuleGeometry(g.params[0], g.params[1], fine ? 8 : 4, seg).rotateX(Math.PI / 2);
  } else if (g.kind === 'mesh') {
    const m = meshes[g.mesh];
    geo = new THREE.BufferGeometry();
    geo.setAttribute('position', new THREE.BufferAttribute(m.v, 3));
    geo.setIndex(new THREE.BufferAttribute(m.f, 1));
    geo.computeVertexNormals();
  } else throw new Error('unknown solid ' + g.kind);
  return geo;
}
const ROLE_MATERIAL = {
  body: { roughness: 0.55, metalness: 0.05 },
  visual: { roughness: 0.55, metalness: 0.05 },
  joint: { roughness: 0.35, metalness: 0.35 },
  link: { roughness: 0.6, metalness: 0.1 },
  ground: { roughness: 0.9, metalness: 0.0 },
  marker: { roughness: 0.5, metalness: 0.0 },
  drive: { roughness: 0.4, metalness: 0.2 },
};
const JOINT_ROLES = ['joint', 'link', 'drive'];  // toggled together ("joints and links")

const state = {
  t: t0, playing: false, speed: 1, loop: true, k: 0, ready: false,
  traces: new Set(META.traces), showTraces: false, showFrames: false, showJoints: true,
  showMarkers: true,
};
let frames = null;
let partLocal = [];
let partNode = null;
let partLabel = null;
const groups = [];
let tube = null;  // the beams: one skinned mesh (see se3dyn/viewer/shapes.py, Tube)
let outline = null;  // the default bodies' inertia boxes as edges, while links are drawn
const nodeMat = Array.from({ length: M }, () => new THREE.Matrix4());
const tmp = new THREE.Matrix4();

// ------------------------------------------------------------------------------------------
// poses at time t: interpolation between stored times (slerp for rotations)
function locate(t) {
  if (t <= T[0]) return [0, 0];
  if (t >= T[n - 1]) return [n - 1, 0];
  let a = 0;
  let b = n - 1;
  while (b - a > 1) {
    const m = (a + b) >> 1;
    if (T[m] <= t) a = m; else b = m;
  }
  return [a, (t - T[a]) / (T[b] - T[a])];
}
const _p = new THREE.Vector3();
const _q = new THREE.Quaternion();
const _s = new THREE.Vector3(1, 1, 1);
const _qa = new Float32Array(4);
function nodePose(i, k, w) {
  const { pos, quat } = frames;
  const a = (k * M + i) * 3;
  const qa = (k * M + i) * 4;
  if (w > 0 && k < n - 1) {
    const b = a + 3 * M;
    _p.set(pos[a] + w * (pos[b] - pos[a]), pos[a + 1] + w * (pos[b + 1] - pos[a + 1]),
      pos[a + 2] + w * (pos[b + 2] - pos[a + 2]));
    THREE.Quaternion.slerpFlat(_qa, 0, quat, qa, quat, qa + 4 * M, w);
    _q.fromArray(_qa);
  } else {
    _p.set(pos[a], pos[a + 1], pos[a + 2]);
    _q.set(quat[qa], quat[qa + 1], quat[qa + 2], quat[qa + 3]);
  }
  return [_p, _q];
}

function applyTime() {
  const [k, w] = locate(state.t);
  state.k = w > 0.5 ? Math.min(k + 1, n - 1) : k;
  state.kFloor = k;
  for (let i = 0; i < M; i++) {
    const [p, q] = nodePose(i, k, w);
    nodeMat[i].compose(p, q, _s);
  }
  for (const g of groups) {
    for (let j = 0; j < g.parts.length; j++) {
      const pi = g.parts[j];
      tmp.multiplyMatrices(nodeMat[partNode[pi]], partLocal[pi]);
      g.mesh.setMatrixAt(j, tmp);
    }
    g.mesh.instanceMatrix.needsUpdate = true;
  }
  updateTube();
  updateOutline();
  updateFrames();
  updateTraces(k, w);
  updateReadout();
  drawCursor();
  requestRender();
}

// ------------------------------------------------------------------------------------------
// beams: vertex v = (1 - w) H_a p_a + w H_b p_b (linear blend of its element's two node frames)
async function buildTube() {
  if (!META.tubes || !META.tubes.length) return;
  const [node, w, p, nrm, rgb, f] = await Promise.all(['tube_node', 'tube_w', 'tube_p',
    'tube_n', 'tube_rgb', 'tube_f'].map(blob));
  const V = w.length;
  const geo = new THREE.BufferGeometry();
  geo.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3 * V), 3)
    .setUsage(THREE.DynamicDrawUsage));
  geo.setAttribute('normal', new THREE.BufferAttribute(new Float32Array(3 * V), 3)
    .setUsage(THREE.DynamicDrawUsage));
  const col = new Float32Array(3 * V);
  const c = new THREE.Color();
  for (let v = 0; v < V; v++) {
    c.setRGB(rgb[3 * v] / 255, rgb[3 * v + 1] / 255, rgb[3 * v + 2] / 255, THREE.SRGBColorSpace);
    col[3 * v] = c.r; col[3 * v + 1] = c.g; col[3 * v + 2] = c.b;
  }
  geo.setAttribute('color', new THREE.BufferAttribute(col, 3));
  geo.setIndex(new THREE.BufferAttribute(f, 1));
  const mesh = new THREE.Mesh(geo, new THREE.MeshStandardMaterial({
    vertexColors: true, roughness: 0.45, metalness: 0.25 }));
  mesh.frustumCulled = false;
  scene.add(mesh);
  tube = { node, w, p, nrm, V, mesh };
}

// out[v] = (1 - w) A pa + w B pb, A and B column-major 4x4; translate: points, else unit normals
function blend(out, v, local, A, B, w, translate) {
  const o = 6 * v;
  const u = 1 - w;
  let len = 0;
  for (let r = 0; r < 3; r++) {
    let x = u * (A[r] * local[o] + A[4 + r] * local[o + 1] + A[8 + r] * local[o + 2])
      + w * (B[r] * local[o + 3] + B[4 + r] * local[o + 4] + B[8 + r] * local[o + 5]);
    if (translate) x += u * A[12 + r] + w * B[12 + r];
    out[3 * v + r] = x;
    len += x * x;
  }
  if (!translate && len > 0) {
    len = 1 / Math.sqrt(len);
    for (let r = 0; r < 3; r++) out[3 * v + r] *= len;
  }
}

function updateTube() {
  if (!tube) return;
  const pos = tube.mesh.geometry.attributes.position;
  const nrm = tube.mesh.geometry.attributes.normal;
  for (let v = 0; v < tube.V; v++) {
    const a = nodeMat[tube.node[2 * v]].elements;
    const b = nodeMat[tube.node[2 * v + 1]].elements;
    blend(pos.array, v, tube.p, a, b, tube.w[v], true);
    blend(nrm.array, v, tube.nrm, a, b, tube.w[v], false);
  }
  pos.needsUpdate = true;
  nrm.needsUpdate = true;
}

// ------------------------------------------------------------------------------------------
// default inertia boxes (role body, box): a quiet outline (12 edges) while the joints and links
// are drawn, the solid box when they are hidden or the model has none
const CORNER = [];
for (let c = 0; c < 8; c++) CORNER.push([(c & 1) - 0.5, ((c >> 1) & 1) - 0.5, ((c >> 2) & 1) - 0.5]);
const EDGES = [];
for (let a = 0; a < 8; a++) for (const bit of [1, 2, 4]) if (!(a & bit)) EDGES.push([a, a | bit]);

function buildOutline(pi) {
  const boxes = groups.filter((g) => g.role === 'body' && META.geometries[g.geom].kind === 'box');
  const linked = groups.some((g) => g.role === 'joint' || g.role === 'link');
  if (!boxes.length || !linked) return;
  const parts = boxes.flatMap((g) => g.parts);
  const geo = new THREE.BufferGeometry();
  geo.setAttribute('position', new THREE.BufferAttribute(new Float32Array(parts.length * 72), 3)
    .setUsage(THREE.DynamicDrawUsage));
  const col = new Float32Array(parts.length * 72);
  const c = new THREE.Color();
  parts.forEach((p, j) => {
    c.setHex(pi[5 * p + 2]);
    for (let v = 0; v < 24; v++) { col[72 * j + 3 * v] = c.r; col[72 * j + 3 * v + 1] = c.g; col[72 * j + 3 * v + 2] = c.b; }
  });
  geo.setAttribute('color', new THREE.BufferAttribute(col, 3));
  const lines = new THREE.LineSegments(geo, new THREE.LineBasicMaterial({
    vertexColors: true, transparent: true, opacity: 0.7 }));
  lines.frustumCulled = false;
  scene.add(lines);
  for (const g of boxes) g.outlined = true;
  outline = { parts, boxes, lines };
  showOutline();
}

function showOutline() {
  if (!outline) return;
  outline.lines.visible = state.showJoints;
  for (const g of outline.boxes) g.mesh.visible = !state.showJoints;
}

const _c = new THREE.Vector3();
function updateOutline() {
  if (!outline || !outline.lines.visible) return;
  const pos = outline.lines.geometry.attributes.position;
  const w = [];
  outline.parts.forEach((p, j) => {
    tmp.multiplyMatrices(nodeMat[partNode[p]], partLocal[p]);
    for (let k = 0; k < 8; k++) w[k] = _c.fromArray(CORNER[k]).applyMatrix4(tmp).toArray();
    EDGES.forEach(([a, b], e) => {
      pos.array.set(w[a], 72 * j + 6 * e);
      pos.array.set(w[b], 72 * j + 6 * e + 3);
    });
  });
  pos.needsUpdate = true;
}

// ------------------------------------------------------------------------------------------
// node frames
let frameLines = null;
function buildFrames() {
  const geo = new THREE.BufferGeometry();
  geo.setAttribute('position', new THREE.BufferAttribute(new Float32Array(M * 18), 3));
  const col = new Float32Array(M * 18);
  const rgb = [[0.84, 0.15, 0.16], [0.17, 0.63, 0.17], [0.12, 0.47, 0.71]];
  for (let i = 0; i < M; i++) {
    for (let a = 0; a < 3; a++) {
      for (let e = 0; e < 2; e++) col.set(rgb[a], i * 18 + a * 6 + e * 3);
    }
  }
  geo.setAttribute('color', new THREE.BufferAttribute(col, 3));
  frameLines = new THREE.LineSegments(geo, new THREE.LineBasicMaterial({ vertexColors: true,
    depthTest: false, transparent: true }));
  frameLines.renderOrder = 2;
  frameLines.frustumCulled = false;
  frameLines.visible = false;
  scene.add(frameLines);
}
function updateFrames() {
  if (!frameLines || !state.showFrames) return;
  const L = 2.5 * META.glyph;
  const arr = frameLines.geometry.attributes.position.array;
  for (let i = 0; i < M; i++) {
    const m = nodeMat[i].elements;
    for (let a = 0; a < 3; a++) {
      const o = i * 18 + a * 6;
      arr[o] = m[12];
      arr[o + 1] = m[13];
      arr[o + 2] = m[14];
      arr[o + 3] = m[12] + L * m[4 * a];
      arr[o + 4] = m[13] + L * m[4 * a + 1];
      arr[o + 5] = m[14] + L * m[4 * a + 2];
    }
  }
  frameLines.geometry.attributes.position.needsUpdate = true;
}

// ------------------------------------------------------------------------------------------
// traces of chosen points (node origins)
const traceLines = new Map();
const TRACE_COLORS = ['#d62728', '#1f77b4', '#2ca02c', '#9467bd', '#ff7f0e', '#17becf'];
function traceLine(i) {
  if (traceLines.has(i)) return traceLines.get(i);
  const pts = new Float32Array(n * 3);
  for (let k = 0; k < n; k++) {
    const a = (k * M + i) * 3;
    pts[3 * k] = frames.pos[a];
    pts[3 * k + 1] = frames.pos[a + 1];
    pts[3 * k + 2] = frames.pos[a + 2];
  }
  const geo = new THREE.BufferGeometry();
  geo.setAttribute('position', new THREE.BufferAttribute(pts, 3));
  const color = META.colors[i] || TRACE_COLORS[traceLines.size % TRACE_COLORS.length];
  const line = new THREE.Line(geo, new THREE.LineBasicMaterial({ color }));
  line.frustumCulled = false;
  scene.add(line);
  traceLines.set(i, line);
  return line;
}
function updateTraces(k, w) {
  for (const [i, line] of traceLines) {
    line.visible = state.showTraces && state.traces.has(i);
    line.geometry.setDrawRange(0, w > 0 ? k + 2 : k + 1);
  }
  if (state.showTraces) {
    for (const i of state.traces) {
      if (!traceLines.has(i)) {
        const line = traceLine(i);
        line.visible = true;
        line.geometry.setDrawRange(0, w > 0 ? k + 2 : k + 1);
      }
    }
  }
  const names = [...state.traces].map((i) => META.nodes[i]);
  $('trace-list').textContent = names.length ? names.join(', ') : 'none';
}

// ------------------------------------------------------------------------------------------
// channel plot synchronised with the time cursor
const plot = { name: null, y: null, unit: '', lo: 0, hi: 1, image: null };
let channelData = null;
function channelValues(name) {
  const e = META.channels.names.indexOf(name);
  if (e >= 0) return [channelData.subarray(e * n, (e + 1) * n), META.channels.units[e]];
  const m = /^node\/([^/]+)\/(position|displacement)\/([xyz])$/.exec(name);
  if (m) {
    const i = META.nodes.findIndex((s) => escapeName(s) === m[1]);
    if (i >= 0) {
      const a = 'xyz'.indexOf(m[3]);
      const y = new Float64Array(n);
      for (let k = 0; k < n; k++) y[k] = frames.pos[(k * M + i) * 3 + a];
      if (m[2] === 'displacement') { const y0 = y[0]; for (let k = 0; k < n; k++) y[k] -= y0; }
      return [y, 'm'];
    }
  }
  return null;
}
const PLOT_PAD = { l: 58, r: 18, t: 24, b: 22 };
function plotSize() {
  const c = $('plot-canvas');
  const dpr = window.devicePixelRatio || 1;
  const w = c.clientWidth;
  const h = c.clientHeight;
  if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
    c.width = Math.round(w * dpr);
    c.height = Math.round(h * dpr);
  }
  return [c, w, h, dpr];
}
const xOf = (t, w) => PLOT_PAD.l + ((t - t0) / Math.max(t1 - t0, 1e-300)) * (w - PLOT_PAD.l - PLOT_PAD.r);
const yOf = (v, h) => PLOT_PAD.t + (1 - (v - plot.lo) / (plot.hi - plot.lo)) * (h - PLOT_PAD.t - PLOT_PAD.b);
function niceTicks(a, b, count) {
  // "nice" values (1, 2, 2.5, 5 x 10^k apart) in [a, b], each with its label
  const span = b - a;
  if (!(span > 0)) return [[a, fmtV(a)]];
  const step0 = span / count;
  const mag = 10 ** Math.floor(Math.log10(step0));
  const f = [1, 2, 2.5, 5, 10].find((x) => x * mag >= step0) || 10;
  const step = f * mag;
  const dec = Math.max(0, -Math.floor(Math.log10(step)) + (f === 2.5 ? 1 : 0));
  const big = Math.max(Math.abs(a), Math.abs(b));
  const out = [];
  for (let i = Math.ceil(a / step); i * step <= b + 1e-9 * span; i++) {
    const v = i * step;
    const text = big >= 1e5 || (big < 1e-3 && big > 0) ? v.toExponential(1) : v.toFixed(Math.min(dec, 8));
    out.push([v, text]);
  }
  return out;
}
function selectChannel(name) {
  const got = channelValues(name);
  const msg = $('plot-msg');
  if (!got) {
    msg.textContent = `no channel '${name}' in this page`;
    return false;
  }
  msg.textContent = '';
  [plot.y, plot.unit] = got;
  plot.name = name;
  let lo = Infinity;
  let hi = -Infinity;
  for (const v of plot.y) if (Number.isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
  if (!(hi > lo)) { const c = Number.isFinite(lo) ? lo : 0; lo = c - 1; hi = c + 1; }
  const pad = 0.06 * (hi - lo);
  plot.lo = lo - pad;
  plot.hi = hi + pad;
  drawCurve();
  drawCursor();
  return true;
}
function drawCurve() {
  const [c, w, h, dpr] = plotSize();
  const off = document.createElement('canvas');
  off.width = c.width;
  off.height = c.height;
  const g = off.getContext('2d');
  g.scale(dpr, dpr);
  g.fillStyle = '#ffffff';
  g.fillRect(0, 0, w, h);
  g.font = '10px system-ui, sans-serif';
  g.strokeStyle = '#e3e6ea';
  g.fillStyle = '#5b616b';
  g.lineWidth = 1;
  g.textAlign = 'right';
  g.textBaseline = 'middle';
  for (const [v, text] of niceTicks(plot.lo, plot.hi, 4)) {
    const y = yOf(v, h);
    g.beginPath(); g.moveTo(PLOT_PAD.l, y); g.lineTo(w - PLOT_PAD.r, y); g.stroke();
    g.fillText(text, PLOT_PAD.l - 4, y);
  }
  g.textAlign = 'center';
  g.textBaseline = 'top';
  for (const [v, text] of niceTicks(t0, t1, 5)) {
    const x = xOf(v, w);
    g.beginPath(); g.moveTo(x, PLOT_PAD.t); g.lineTo(x, h - PLOT_PAD.b); g.stroke();
    g.fillText(text, x, h - PLOT_PAD.b + 4);
  }
  g.strokeStyle = '#b8bec6';
  g.strokeRect(PLOT_PAD.l, PLOT_PAD.t, w - PLOT_PAD.l - PLOT_PAD.r, h - PLOT_PAD.t - PLOT_PAD.b);
  g.strokeStyle = '#1f5fa8';
  g.lineWidth = 1.4;
  g.beginPath();
  let first = true;
  for (let k = 0; k < n; k++) {
    const v = plot.y[k];
    if (!Number.isFinite(v)) { first = true; continue; }
    const x = xOf(T[k], w);
    const y = yOf(v, h);
    if (first) g.moveTo(x, y); else g.lineTo(x, y);
    first = false;
  }
  g.stroke();
  plot.image = off;
}
function drawCursor() {
  if (!plot.image || !plot.y) return;
  const [c, w, h, dpr] = plotSize();
  const g = c.getContext('2d');
  g.setTransform(1, 0, 0, 1, 0, 0);
  g.drawImage(plot.image, 0, 0);
  g.scale(dpr, dpr);
  const x = xOf(state.t, w);
  g.strokeStyle = '#e4572e';
  g.lineWidth = 1.2;
  g.beginPath(); g.moveTo(x, PLOT_PAD.t); g.lineTo(x, h - PLOT_PAD.b); g.stroke();
  const [k, wt] = locate(state.t);
  const v = wt > 0 && k < n - 1 ? plot.y[k] + wt * (plot.y[k + 1] - plot.y[k]) : plot.y[k];
  if (Number.isFinite(v)) {
    g.fillStyle = '#e4572e';
    g.beginPath(); g.arc(x, yOf(v, h), 3.2, 0, 2 * Math.PI); g.fill();
  }
  g.fillStyle = '#22262c';
  g.font = '11px system-ui, sans-serif';
  g.textAlign = 'left';
  g.textBaseline = 'top';
  g.fillText(`${plot.name} = ${fmtV(v)}${plot.unit ? ' ' + plot.unit : ''}`, PLOT_PAD.l, 6);
}

// ------------------------------------------------------------------------------------------
// rendering on demand
function requestRender() {
  if (renderQueued) return;
  renderQueued = true;
  requestAnimationFrame(renderNow);
}
function renderNow() {
  renderQueued = false;
  const w = stage.clientWidth;
  const h = stage.clientHeight;
  renderer.setViewport(0, 0, w, h);
  renderer.setScissorTest(false);
  renderer.clear();
  renderer.render(scene, camera);
  // axes inset, bottom left
  const dir = new THREE.Vector3().subVectors(camera.position, controls.target).normalize();
  hudCam.position.copy(dir).multiplyScalar(4);
  hudCam.up.copy(camera.up);
  hudCam.lookAt(0, 0, 0);
  renderer.clearDepth();
  renderer.setScissorTest(true);
  renderer.setScissor(8, 8, HUD_PX, HUD_PX);
  renderer.setViewport(8, 8, HUD_PX, HUD_PX);
  renderer.render(hud, hudCam);
  renderer.setScissorTest(false);
  if (!state.ready) {
    state.ready = true;
    document.documentElement.dataset.ready = '1';
    $('loading').hidden = true;
  }
}

// ------------------------------------------------------------------------------------------
// playback
let lastClock = null;
function tick(now) {
  if (!state.playing) { lastClock = null; return; }
  if (lastClock !== null) {
    let t = state.t + ((now - lastClock) / 1000) * state.speed;
    if (t > t1) {
      if (state.loop && t1 > t0) t = t0 + ((t - t0) % (t1 - t0));
      else { t = t1; setPlaying(false); }
    }
    state.t = t;
    applyTime();
  }
  lastClock = now;
  requestAnimationFrame(tick);
}
function setPlaying(on) {
  if (on && state.t >= t1 && !state.loop) state.t = t0;
  state.playing = on;
  $('play').textContent = on ? '\u275a\u275a' : '\u25b6';
  $('play').title = on ? 'pause (space)' : 'play (space)';
  if (on) { lastClock = null; requestAnimationFrame(tick); } else shareTime();
}
function setTime(t) {
  state.t = Math.min(t1, Math.max(t0, Number(t)));
  applyTime();
}
function shareTime() {
  try { history.replaceState(null, '', '#t=' + fmtT(state.t)); } catch (e) { /* srcdoc frame */ }
}
function updateReadout() {
  $('time').textContent = `t = ${fmtT(state.t)} s`;
  $('frame').textContent = `frame ${state.k + 1} / ${n}`;
  const s = $('scrub');
  if (document.activeElement !== s || !scrubbing) s.value = String(state.t);
}
function hashTime() {
  const m = /(?:^#|&)t=([-+0-9.eE]+)/.exec(location.hash || '');
  const v = m ? Number(m[1]) : NaN;
  return Number.isFinite(v) ? v : null;
}
let scrubbing = false;

// ------------------------------------------------------------------------------------------
// picking: hover labels, click a body to toggle its trace
const raycaster = new THREE.Raycaster();
const pointer = new THREE.Vector2();
function pick(ev) {
  const r = renderer.domElement.getBoundingClientRect();
  pointer.set(((ev.clientX - r.left) / r.width) * 2 - 1, -((ev.clientY - r.top) / r.height) * 2 + 1);
  raycaster.setFromCamera(pointer, camera);
  const meshes = groups.filter((g) => g.mesh.visible || g.outlined).map((g) => g.mesh);
  for (const g of groups) g.mesh.computeBoundingSphere();
  const hit = raycaster.intersectObjects(meshes, false)[0];
  if (!hit || hit.instanceId === undefined) return null;
  const g = groups.find((gg) => gg.mesh === hit.object);
  return g.parts[hit.instanceId];
}
let down = null;
renderer.domElement.addEventListener('pointerdown', (ev) => { down = [ev.clientX, ev.clientY]; });
renderer.domElement.addEventListener('pointerup', (ev) => {
  if (!down || Math.hypot(ev.clientX - down[0], ev.clientY - down[1]) > 4) return;
  const p = pick(ev);
  if (p === null) return;
  const i = partNode[p];
  if (state.traces.has(i)) state.traces.delete(i); else state.traces.add(i);
  state.showTraces = true;
  $('show-traces').checked = true;
  applyTime();
});
let hoverAt = 0;
renderer.domElement.addEventListener('pointermove', (ev) => {
  const now = performance.now();
  if (ev.buttons || now - hoverAt < 80) return;
  hoverAt = now;
  const p = pick(ev);
  const tip = $('tooltip');
  if (p === null) { tip.hidden = true; return; }
  tip.textContent = META.labels[partLabel[p]];
  tip.style.left = ev.clientX + 12 + 'px';
  tip.style.top = ev.clientY + 12 + 'px';
  tip.hidden = false;
});
renderer.domElement.addEventListener('pointerleave', () => { $('tooltip').hidden = true; });

// ------------------------------------------------------------------------------------------
// user interface
function setupUI() {
  $('title').textContent = META.title;
  $('sub').textContent = `${META.counts.nodes} nodes, ${META.counts.joints} joints, ${n} stored ` +
    `times, t = ${fmtV(t0)} \u2026 ${fmtV(t1)} s`;
  const s = $('scrub');
  s.min = String(t0);
  s.max = String(t1);
  s.step = 'any';
  s.addEventListener('input', () => { scrubbing = true; setTime(Number(s.value)); });
  s.addEventListener('change', () => { scrubbing = false; if (!state.playing) shareTime(); });
  $('play').addEventListener('click', () => setPlaying(!state.playing));
  const sp = $('speed');
  for (const v of [0.1, 0.25, 0.5, 1, 2, 5, 10]) {
    const o = document.createElement('option');
    o.value = String(v);
    o.textContent = `${v}\u00d7`;
    if (v === 1) o.selected = true;
    sp.appendChild(o);
  }
  sp.addEventListener('change', () => { state.speed = Number(sp.value); });
  $('loop').addEventListener('change', (e) => { state.loop = e.target.checked; });
  $('show-frames').addEventListener('change', (e) => {
    state.showFrames = e.target.checked;
    frameLines.visible = state.showFrames;
    applyTime();
  });
  $('show-traces').addEventListener('change', (e) => { state.showTraces = e.target.checked; applyTime(); });
  $('show-joints').addEventListener('change', (e) => {
    state.showJoints = e.target.checked;
    for (const g of groups) {
      if (JOINT_ROLES.includes(g.role)) g.mesh.visible = state.showJoints;
    }
    showOutline();
    applyTime();
  });
  const markers = META.markers || [];
  $('markers-row').hidden = !markers.length;
  $('show-markers').addEventListener('change', (e) => {
    state.showMarkers = e.target.checked;
    for (const g of groups) if (g.role === 'marker') g.mesh.visible = state.showMarkers;
    requestRender();
  });
  $('marker-list').textContent = markers.map((m) => m.name).join(', ');
  // drives: their names, each plotting its effort when clicked
  const drives = META.drives || [];
  const dl = $('drives');
  dl.hidden = !drives.length;
  if (drives.length) dl.append('drives (orange): ');
  drives.forEach((d, i) => {
    const a = document.createElement('a');
    a.href = '#';
    a.className = 'drive';
    a.textContent = d.name;
    a.title = `${d.kind} drive on joint '${d.joint}': plot ${d.channel}`;
    a.addEventListener('click', (ev) => {
      ev.preventDefault();
      $('channel').value = d.channel;
      selectChannel(d.channel);
    });
    if (i) dl.append(', ');
    dl.append(a);
  });
  $('reset-view').addEventListener('click', () => { homeView(); requestRender(); });
  // channel list
  const list = $('channel-list');
  const names = META.channels.names.slice();
  for (const name of META.nodes) {
    for (const q of ['position', 'displacement']) {
      for (const a of 'xyz') names.push(`node/${escapeName(name)}/${q}/${a}`);
    }
  }
  const frag = document.createDocumentFragment();
  for (const name of names) {
    const o = document.createElement('option');
    o.value = name;
    frag.appendChild(o);
  }
  list.appendChild(frag);
  const ch = $('channel');
  ch.addEventListener('change', () => selectChannel(ch.value.trim()));
  ch.addEventListener('keydown', (e) => { if (e.key === 'Enter') selectChannel(ch.value.trim()); });
  $('plot-note').textContent = META.channels.note || '';
  // seek by clicking or dragging on the plot
  const pc = $('plot-canvas');
  const seek = (ev) => {
    const r = pc.getBoundingClientRect();
    const f = (ev.clientX - r.left - PLOT_PAD.l) / (r.width - PLOT_PAD.l - PLOT_PAD.r);
    setTime(t0 + Math.min(1, Math.max(0, f)) * (t1 - t0));
  };
  pc.addEventListener('pointerdown', (ev) => { pc.setPointerCapture(ev.pointerId); seek(ev); });
  pc.addEventListener('pointermove', (ev) => { if (ev.buttons) seek(ev); });
  pc.addEventListener('pointerup', () => { if (!state.playing) shareTime(); });
  $('plot-toggle').addEventListener('click', () => {
    const body = $('plot-body');
    body.hidden = !body.hidden;
    $('plot-toggle').textContent = body.hidden ? 'plot \u25b8' : 'plot \u25be';
    if (!body.hidden) { drawCurve(); drawCursor(); }
  });
  $('notes').textContent = META.notes.join(' \u00b7 ');
  window.addEventListener('keydown', (e) => {
    if (e.target instanceof HTMLInputElement && e.target.type === 'text') return;
    if (e.target instanceof HTMLSelectElement) return;
    if (e.code === 'Space') { e.preventDefault(); setPlaying(!state.playing); }
    else if (e.key === 'ArrowRight' || e.key === 'ArrowLeft') {
      e.preventDefault();
      setPlaying(false);
      const k = Math.max(0, Math.min(n - 1, state.kFloor + (e.key === 'ArrowRight' ? 1 : -1)));
      setTime(T[k]);
      shareTime();
    } else if (e.key === 'Home') { setTime(t0); } else if (e.key === 'End') { setTime(t1); }
  });
  window.addEventListener('resize', () => {
    camera.aspect = stage.clientWidth / stage.clientHeight;
    camera.updateProjectionMatrix();
    renderer.setSize(stage.clientWidth, stage.clientHeight);
    drawCurve();
    drawCursor();
    requestRender();
  });
  window.addEventListener('hashchange', () => {
    const h = hashTime();
    if (h !== null) { setPlaying(false); setTime(h); }
  });
}

// ------------------------------------------------------------------------------------------
async function main() {
  const [words, pf, pi, ch] = await Promise.all([blob('frames'), blob('part_matrix'),
    blob('part_info'), META.channels.names.length ? blob('channels') : null]);
  frames = decodeFrames(words);
  channelData = ch;
  const meshes = [];
  for (let k = 0; k < META.meshes; k++) {
    meshes.push({ v: await blob(`mesh${k}_v`), f: await blob(`mesh${k}_f`) });
  }
  const P = pi.length / 5;
  partNode = new Int32Array(P);
  partLabel = new Int32Array(P);
  const byGroup = new Map();
  for (let p = 0; p < P; p++) {
    const e = pf.subarray(12 * p, 12 * p + 12);
    partLocal.push(new THREE.Matrix4().set(e[0], e[1], e[2], e[3], e[4], e[5], e[6], e[7],
      e[8], e[9], e[10], e[11], 0, 0, 0, 1));
    partNode[p] = pi[5 * p];
    const geom = pi[5 * p + 1];
    const role = META.roles[pi[5 * p + 3]];
    partLabel[p] = pi[5 * p + 4];
    const key = geom + ':' + role;
    if (!byGroup.has(key)) byGroup.set(key, { geom, role, parts: [] });
    byGroup.get(key).parts.push(p);
  }
  const color = new THREE.Color();
  for (const g of byGroup.values()) {
    const mat = new THREE.MeshStandardMaterial(ROLE_MATERIAL[g.role]);
    const mesh = new THREE.InstancedMesh(unitGeometry(META.geometries[g.geom], meshes,
      g.parts.length), mat, g.parts.length);
    mesh.instanceMatrix.setUsage(THREE.DynamicDrawUsage);
    mesh.frustumCulled = false;
    g.parts.forEach((p, j) => { mesh.setColorAt(j, color.setHex(pi[5 * p + 2])); });
    mesh.instanceColor.needsUpdate = true;
    g.mesh = mesh;
    groups.push(g);
    scene.add(mesh);
  }
  await buildTube();
  buildOutline(pi);
  buildFrames();
  setupUI();
  $('channel').value = META.plot || '';
  if (META.plot) selectChannel(META.plot);
  window.se3dyn = {
    meta: META, state, setTime, play: () => setPlaying(true), pause: () => setPlaying(false),
    time: () => state.t, frame: () => state.k,
    nodePosition: (i, k) => Array.from(frames.pos.subarray((k * M + i) * 3, (k * M + i) * 3 + 3)),
    nodeQuaternion: (i, k) => Array.from(frames.quat.subarray((k * M + i) * 4, (k * M + i) * 4 + 4)),
    project: (x, y, z) => {
      const v = new THREE.Vector3(x, y, z).project(camera);
      const r = renderer.domElement.getBoundingClientRect();
      return [r.left + ((v.x + 1) / 2) * r.width, r.top + ((1 - v.y) / 2) * r.height];
    },
    selectChannel, plotted: () => plot.name,
    markers: META.markers || [], drives: META.drives || [],
    partsOfRole: (role) => groups.filter((g) => g.role === role)
      .reduce((c, g) => c + (g.mesh.visible ? g.parts.length : 0), 0),
    tubePositions: () => (tube ? Array.from(tube.mesh.geometry.attributes.position.array) : []),
  };
  const h = hashTime();
  state.t = h === null ? t0 : Math.min(t1, Math.max(t0, h));
  applyTime();
  if (h === null && n > 1) setPlaying(true);
  else setPlaying(false);
}

main().catch((e) => {
  console.error(e);
  const box = $('se3dyn-error');
  box.textContent = 'se3dyn viewer: ' + (e && e.message ? e.message : e);
  box.hidden = false;
});
