// quadsitl view: the page. Live frames or whole replay logs arrive on the WebSocket /ws; the
// 3-D scene (three.js) and the time plots (uPlot) draw from the same per-track columns.
// Frames: the paper's world frame (x north, y west, z up; metres), so the scene uses it as is
// (three.js is right-handed too; only camera.up is set to +z). Angles on the wire are radians,
// shown in degrees; position errors in millimetres (the paper's controllers hold a millimetre).
// Drawing is on demand: the scene at most FPS_3D and the plots at most PLOT_HZ times a second,
// and only when something changed, so an open page costs the simulation little CPU.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { CSS2DRenderer, CSS2DObject } from 'three/addons/renderers/CSS2DRenderer.js';

const params = new URLSearchParams(location.search);
const clamp = (v, lo, hi) => Math.min(hi, Math.max(lo, v));
// Without a GPU (Chromium's SwiftShader, Mesa's llvmpipe) WebGL is drawn by the CPU, the one the
// simulation needs: there the scene is drawn at 15 fps without antialiasing (measured in headless
// Chromium on a 2-vCPU VM: 30 fps with antialiasing cost 70 % of a core, 15 fps without ~25 %).
// ?fps=, ?aa=0|1, ?plot_hz=, ?ui_hz= override.
function softwareGl() {
  try {
    const gl = document.createElement('canvas').getContext('webgl2') || document.createElement('canvas').getContext('webgl');
    const ext = gl && gl.getExtension('WEBGL_debug_renderer_info');
    const name = ext ? String(gl.getParameter(ext.UNMASKED_RENDERER_WEBGL)) : '';
    gl && gl.getExtension('WEBGL_lose_context')?.loseContext();
    return /swiftshader|llvmpipe|softpipe|software/i.test(name);
  } catch (e) { return false; }
}
const SOFTWARE_GL = softwareGl();
const FPS_3D = clamp(Number(params.get('fps')) || (SOFTWARE_GL ? 15 : 30), 1, 60);
const PLOT_HZ = clamp(Number(params.get('plot_hz')) || (SOFTWARE_GL ? 5 : 10), 1, 30);
const ANTIALIAS = params.has('aa') ? params.get('aa') !== '0' : !SOFTWARE_GL;
// Text (cards, time, slider) at most UI_HZ times a second: each DOM change costs a style, layout
// and paint pass, and at the display's 60 Hz those passes cost more CPU than the scene (measured).
const UI_HZ = clamp(Number(params.get('ui_hz')) || 8, 1, 60);
const MAX_POINTS = 20000;            // per track and column (live: ~11 min at 30 Hz)
const MAX_TEXTS = 200;
// e1..e4, f1..f4: the rotors' health (effectiveness, FAILURE_TYPE), rotors 1 front, 2 right, 3 rear, 4 left
const ROTOR_COLS = ['e1', 'e2', 'e3', 'e4', 'f1', 'f2', 'f3', 'f4'];
const COLS = ['t', 'x', 'y', 'z', 'xr', 'yr', 'zr', 'phi', 'theta', 'psi', 'phir', 'thetar', 'psir',
  'u1', 'tphi', 'ttheta', 'tpsi', 'fx', 'fy', 'fz', 'mx', 'my', 'mz', ...ROTOR_COLS];
// A failed rotor's colour by its FAILURE_TYPE (1 off, 2 stuck, 4 wrong: a loss of effectiveness).
const ROTOR_FAILURES = { 1: ['off', 0xd50000], 2: ['stuck', 0xff6d00], 4: ['', 0xffab00] };
const ROTOR_NAMES = ['front', 'right', 'rear', 'left'];
const DEG = 180 / Math.PI;
const SEVERITY = ['EMERGENCY', 'ALERT', 'CRITICAL', 'ERROR', 'WARNING', 'NOTICE', 'INFO', 'DEBUG'];

// What the browser tests read (window.quadsitlView): connection, rates, mode history, replay.
const state = {
  kind: null, connected: false, messages: 0, frames: 0, rateHz: 0, frameTimes: [],
  drawing: { softwareGl: SOFTWARE_GL, fps3d: FPS_3D, plotHz: PLOT_HZ, uiHz: UI_HZ, antialias: ANTIALIAS },
  tracks: [], modeHistory: {}, windowS: 30, dirty3d: true, dirtyPlots: true, dirtyUi: true,
  renders3d: 0, plotDraws: 0, errors: [], rtf: null, yielding: false,
  cameraMoved: false, cameraTarget: null,   // the user moved the camera; where the last framing looks
  replay: { t: 0, t0: 0, t1: 0, playing: false, ended: false, speed: 1, lastTs: null, textsUpTo: -Infinity },
};
window.quadsitlView = state;
window.addEventListener('error', (e) => state.errors.push(String(e.message)));

const $ = (id) => document.getElementById(id);
const num = (v) => (v === null || v === undefined ? NaN : v);
const fmt = (v, d = 2) => (Number.isFinite(v) ? v.toFixed(d) : '–');

// ------------------------------------------------------------------------------------------
// Tracks
// ------------------------------------------------------------------------------------------
function makeTrack(desc) {
  const cols = {};
  for (const c of COLS) cols[c] = [];
  return {
    id: desc.id, color: desc.color, label: desc.label || `track ${desc.id}`, desc, cols,
    status: { mode: '', armed: null, landed: '', failsafe: null, linked: false },
    timeline: [], timelineT: [], events: [], texts: [], q: null, obj: null, card: null,
  };
}

function appendSample(tr, s) {
  const c = tr.cols;
  const n = c.t.length;
  if (n && s.t <= c.t[n - 1]) return false;   // the server sends each step once, in order
  if (n >= MAX_POINTS) for (const k of COLS) c[k].splice(0, MAX_POINTS / 4);
  const put = (keys, arr) => keys.forEach((k, i) => c[k].push(arr ? arr[i] : null));
  c.t.push(s.t);
  put(['x', 'y', 'z'], s.p); put(['xr', 'yr', 'zr'], s.pr);
  put(['phi', 'theta', 'psi'], s.eta); put(['phir', 'thetar', 'psir'], s.etar);
  c.u1.push(s.u1); put(['tphi', 'ttheta', 'tpsi'], s.tau);
  put(['fx', 'fy', 'fz'], s.df); put(['mx', 'my', 'mz'], s.dm);
  put(ROTOR_COLS, s.rot);
  tr.q = s.q;
  return true;
}

function setStatus(tr, st, simT) {
  const old = tr.status;
  if (st.mode !== old.mode || st.armed !== old.armed) {
    (state.modeHistory[tr.id] ||= []).push({ mode: st.mode, armed: st.armed, t: simT, wall: performance.now() });
  }
  tr.status = st;
}

// Index of the last element of sorted `arr` <= v (-1 if none).
function upper(arr, v) {
  let lo = 0, hi = arr.length;
  while (lo < hi) { const m = (lo + hi) >> 1; if (arr[m] <= v) lo = m + 1; else hi = m; }
  return lo - 1;
}

// ------------------------------------------------------------------------------------------
// 3-D scene
// ------------------------------------------------------------------------------------------
const sceneEl = $('scene');
const renderer = new THREE.WebGLRenderer({ antialias: ANTIALIAS });
renderer.setPixelRatio(1);   // CPU budget: no supersampling on high-DPI screens
renderer.setClearColor(0xffffff);
sceneEl.appendChild(renderer.domElement);
const labels = new CSS2DRenderer();
labels.domElement.style.position = 'absolute';
labels.domElement.style.top = '0';
labels.domElement.style.pointerEvents = 'none';
sceneEl.appendChild(labels.domElement);

const scene = new THREE.Scene();
const camera = new THREE.PerspectiveCamera(50, 1, 0.05, 500);
camera.up.set(0, 0, 1);
camera.position.set(-3.8, -6.0, 4.4);
const controls = new OrbitControls(camera, renderer.domElement);
controls.target.set(1, 1, 1.3);
controls.update();
controls.addEventListener('change', () => { state.dirty3d = true; });
controls.addEventListener('start', () => { state.cameraMoved = true; });   // the user's own view from now on
scene.add(new THREE.AmbientLight(0xffffff, 0.7));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
sun.position.set(-3, -5, 10);
scene.add(sun);

function label3d(text, cls, pos) {
  const div = document.createElement('div');
  div.className = `label3d ${cls}`;
  div.textContent = text;
  const obj = new CSS2DObject(div);
  obj.position.copy(pos);
  return obj;
}

function buildGround() {
  const grid = new THREE.GridHelper(20, 20, 0x9a9a9a, 0xdedede);
  grid.rotation.x = Math.PI / 2;    // GridHelper lies in x-z; the ground is x-y here
  scene.add(grid);
  const axis = (to, color, text) => {
    const g = new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(), to]);
    scene.add(new THREE.Line(g, new THREE.LineBasicMaterial({ color })));
    scene.add(label3d(text, 'axis', to.clone().multiplyScalar(1.08)));
  };
  axis(new THREE.Vector3(5.5, 0, 0), 0xc62828, 'x (m) north');
  axis(new THREE.Vector3(0, 5.5, 0), 0x2e7d32, 'y (m) west');
  axis(new THREE.Vector3(0, 0, 4.5), 0x1565c0, 'z (m) up');
  for (let v = -4; v <= 4; v += 2) {
    if (v === 0) continue;
    scene.add(label3d(`${v}`, 'tick', new THREE.Vector3(v, -0.25, 0)));
    scene.add(label3d(`${v}`, 'tick', new THREE.Vector3(-0.25, v, 0)));
  }
  for (let v = 1; v <= 4; v += 1) scene.add(label3d(`${v} m`, 'tick', new THREE.Vector3(-0.2, -0.2, v)));
}
buildGround();

function lineBuffer(material) {
  const geometry = new THREE.BufferGeometry();
  const pos = new Float32Array(MAX_POINTS * 3);
  geometry.setAttribute('position', new THREE.BufferAttribute(pos, 3).setUsage(THREE.DynamicDrawUsage));
  geometry.setDrawRange(0, 0);
  const line = new THREE.Line(geometry, material);
  line.frustumCulled = false;       // no bounding sphere over a buffer that is mostly unused
  return { line, geometry, pos, n: -1 };
}

function makeBody(color) {
  const group = new THREE.Group();
  const mat = new THREE.MeshLambertMaterial({ color });
  const dark = new THREE.MeshLambertMaterial({ color: 0x333333 });
  const arm = new THREE.BoxGeometry(0.56, 0.035, 0.025);
  const a1 = new THREE.Mesh(arm, dark);
  const a2 = new THREE.Mesh(arm, dark);
  a2.rotation.z = Math.PI / 2;      // '+' configuration: arms on the body x and y axes
  group.add(a1, a2);
  const rotor = new THREE.CylinderGeometry(0.1, 0.1, 0.012, 20);
  const rotors = [];
  // The simulator's rotors 1-4 (front, right, rear, left; body y is left), each its own material
  // so that a failed one shows (rotorHealth).
  for (const [x, y] of [[0.28, 0], [0, -0.28], [-0.28, 0], [0, 0.28]]) {
    const r = new THREE.Mesh(rotor, mat.clone());
    r.rotation.x = Math.PI / 2;     // cylinder axis y -> body z
    r.position.set(x, y, 0.025);
    group.add(r);
    rotors.push(r);
  }
  group.userData = { rotors, color: new THREE.Color(color), health: '' };
  const nose = new THREE.Mesh(new THREE.ConeGeometry(0.04, 0.12, 12), new THREE.MeshLambertMaterial({ color: 0xff1744 }));
  nose.rotation.z = -Math.PI / 2;   // cone axis y -> body +x (the front)
  nose.position.set(0.36, 0, 0);
  group.add(nose, new THREE.Mesh(new THREE.BoxGeometry(0.12, 0.12, 0.06), mat));
  return group;
}

function makeTrackObjects(tr) {
  const color = new THREE.Color(tr.color);
  const path = lineBuffer(new THREE.LineBasicMaterial({ color }));
  const ref = lineBuffer(new THREE.LineDashedMaterial({ color, dashSize: 0.12, gapSize: 0.08, transparent: true, opacity: 0.75 }));
  const dist = new Float32Array(MAX_POINTS);
  ref.geometry.setAttribute('lineDistance', new THREE.BufferAttribute(dist, 1).setUsage(THREE.DynamicDrawUsage));
  ref.dist = dist;
  const body = makeBody(color);
  body.visible = false;
  const stem = new THREE.Line(new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(), new THREE.Vector3()]),
    new THREE.LineDashedMaterial({ color, dashSize: 0.05, gapSize: 0.05 }));
  stem.frustumCulled = false;
  const name = label3d(tr.label, 'vehicle', new THREE.Vector3(0, 0, 0.35));
  name.element.style.color = tr.color;
  body.add(name);
  // One group per vehicle, placed where its local frame's origin (its home) sits in the first
  // vehicle's: a fleet's vehicles with homes apart (quadsitl fleet --spacing) are drawn apart.
  const group = new THREE.Group();
  group.add(path.line, ref.line, body, stem);
  scene.add(group);
  tr.obj = { path, ref, body, stem, name, group, refT: [] };
  placeTrack(tr);
}

function placeTrack(tr) {
  const off = tr.desc.offset_m;
  if (tr.obj) tr.obj.group.position.set(off ? off[0] : 0, off ? off[1] : 0, off ? off[2] : 0);
}

function removeTrackObjects(tr) {
  if (!tr.obj) return;
  const o = tr.obj;
  o.body.remove(o.name);
  o.name.element.remove();
  scene.remove(o.group);
  for (const l of [o.path.line, o.ref.line, o.stem]) l.geometry.dispose();
}

// Rewrite the path and reference buffers from the columns (after a trim or for a replay).
function syncLines(tr) {
  const c = tr.cols, o = tr.obj;
  const n = c.t.length;
  let k = 0, r = 0, d = 0;
  o.refT = [];
  for (let i = 0; i < n; i++) {
    if (c.x[i] !== null) { o.path.pos.set([c.x[i], c.y[i], c.z[i]], 3 * k); k++; }
    if (c.xr[i] !== null && c.yr[i] !== null && c.zr[i] !== null) {
      if (r) d += Math.hypot(c.xr[i] - o.ref.pos[3 * r - 3], c.yr[i] - o.ref.pos[3 * r - 2], c.zr[i] - o.ref.pos[3 * r - 1]);
      o.ref.pos.set([c.xr[i], c.yr[i], c.zr[i]], 3 * r);
      o.ref.dist[r] = d;
      o.refT.push(c.t[i]);
      r++;
    }
  }
  o.path.n = k; o.ref.n = r; o.pathT = n;
  o.path.geometry.attributes.position.needsUpdate = true;
  o.ref.geometry.attributes.position.needsUpdate = true;
  o.ref.geometry.attributes.lineDistance.needsUpdate = true;
}

// Show each track as of simulation time `t` (live: its latest sample).
function poseTracks(tAt) {
  for (const tr of state.tracks) {
    if (!tr.obj) continue;
    const c = tr.cols, o = tr.obj;
    if (o.pathT !== c.t.length || o.path.n < 0) syncLines(tr);
    const i = tAt === null ? c.t.length - 1 : upper(c.t, tAt);
    if (i < 0 || c.x[i] === null) { o.body.visible = false; o.path.geometry.setDrawRange(0, 0); o.ref.geometry.setDrawRange(0, 0); continue; }
    o.path.geometry.setDrawRange(0, tAt === null ? o.path.n : Math.min(o.path.n, i + 1));
    o.ref.geometry.setDrawRange(0, tAt === null ? o.ref.n : upper(o.refT, tAt) + 1);
    o.body.visible = true;
    o.body.position.set(c.x[i], c.y[i], c.z[i]);
    if (tAt === null && tr.q && tr.q[0] !== null) {
      o.body.quaternion.set(tr.q[1], tr.q[2], tr.q[3], tr.q[0]);   // (w, x, y, z) body to world
    } else {
      // The paper's ZYX Euler angles: R = Rz(psi) Ry(theta) Rx(phi) is three.js's order 'ZYX'.
      o.body.rotation.set(num(c.phi[i]), num(c.theta[i]), num(c.psi[i]), 'ZYX');
    }
    rotorHealth(o.body, c, i);
    const sp = o.stem.geometry.attributes.position;
    sp.setXYZ(0, c.x[i], c.y[i], 0); sp.setXYZ(1, c.x[i], c.y[i], c.z[i]);
    sp.needsUpdate = true;
    o.stem.computeLineDistances();
  }
}

// A failed rotor in its failure's colour (a loss of effectiveness shaded by what it keeps), the
// healthy ones in the track's; only when the health changed.
function rotorHealth(body, c, i) {
  const key = ROTOR_COLS.map((k) => c[k][i]).join(',');
  const u = body.userData;
  if (key === u.health) return;
  u.health = key;
  u.rotors.forEach((r, n) => {
    const failure = ROTOR_FAILURES[c[`f${n + 1}`][i]];
    const e = num(c[`e${n + 1}`][i]);
    if (!failure) r.material.color.copy(u.color);
    else r.material.color.setHex(failure[1]).lerp(new THREE.Color(0x333333), failure[0] ? 0 : 0.7 * (1 - e));
  });
}

// The rotors' health in words, for the vehicle's card: "healthy", or each failed rotor.
function rotorText(c, i) {
  const out = [];
  for (let n = 0; n < 4; n++) {
    const failure = ROTOR_FAILURES[c[`f${n + 1}`][i]];
    if (!failure) continue;
    const e = num(c[`e${n + 1}`][i]);
    out.push(`${n + 1} ${ROTOR_NAMES[n]}: ${failure[0] || `${fmt(100 * e, 0)} %`}`);
  }
  return out.length ? out.join(', ') : 'healthy';
}

function resize3d() {
  const w = sceneEl.clientWidth, h = sceneEl.clientHeight;
  renderer.setSize(w, h);
  labels.setSize(w, h);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
  state.dirty3d = true;
}

function render3d() {
  poseTracks(state.kind === 'replay' ? state.replay.t : null);
  if ($('follow').checked) {
    const tr = state.tracks.find((t) => t.obj && t.obj.body.visible);
    if (tr) { tr.obj.body.getWorldPosition(controls.target); controls.update(); }   // (in its group)
  }
  renderer.render(scene, camera);
  labels.render(scene, camera);
  state.renders3d++;
  state.dirty3d = false;
}

function fit() {
  const box = new THREE.Box3();
  for (const tr of state.tracks) {
    const c = tr.cols, off = tr.desc.offset_m || [0, 0, 0];
    for (let i = 0; i < c.t.length; i += 5) {
      if (c.x[i] !== null) box.expandByPoint(new THREE.Vector3(c.x[i] + off[0], c.y[i] + off[1], c.z[i] + off[2]));
    }
  }
  if (box.isEmpty()) box.set(new THREE.Vector3(-1, -1, 0), new THREE.Vector3(3, 3, 3));
  frameBox(box);
}

// Live, a fleet spaced apart (--spacing) stands beyond the first view: until the user moves the
// camera, the scene is framed about every vehicle's home as the homes become known (the first
// view's few metres about each). Vehicles all at one home keep the first view.
function frameHomes() {
  if (state.kind !== 'live' || state.cameraMoved) return;
  const homes = state.tracks.map((tr) => tr.desc.offset_m || [0, 0, 0]);
  if (!homes.some((o) => Math.hypot(o[0], o[1]) > 3)) return;
  const box = new THREE.Box3();
  for (const o of homes) {
    box.expandByPoint(new THREE.Vector3(o[0] - 1, o[1] - 1, 0));
    box.expandByPoint(new THREE.Vector3(o[0] + 3, o[1] + 3, 3));
  }
  frameBox(box);
}

function frameBox(box) {
  box.expandByPoint(new THREE.Vector3(box.min.x, box.min.y, 0));
  const center = box.getCenter(new THREE.Vector3());
  const size = Math.max(box.getSize(new THREE.Vector3()).length(), 2);
  controls.target.copy(center);
  camera.position.copy(center).add(new THREE.Vector3(-0.55, -0.8, 0.5).multiplyScalar(size * 1.25));
  camera.far = Math.max(500, 4 * size);   // a fleet a few hundred metres long stays in view
  camera.updateProjectionMatrix();
  controls.update();
  state.cameraTarget = center.toArray();
  state.dirty3d = true;
}
$('fit').addEventListener('click', () => { state.cameraMoved = true; fit(); });   // (the user's framing)
$('follow').addEventListener('change', () => { state.dirty3d = true; });

// ------------------------------------------------------------------------------------------
// Time plots (uPlot)
// ------------------------------------------------------------------------------------------
const diffMm = (a, b) => (c, i) => (c[a][i] === null || c[b][i] === null ? null : (c[a][i] - c[b][i]) * 1000);
const deg = (k) => (c, i) => (c[k][i] === null ? null : c[k][i] * DEG);
const raw = (k) => (c, i) => c[k][i];
const DASH = [[], [7, 3], [2, 3]];
const REF = { dash: [5, 4], width: 1.2, ref: true };
const PLOTS = [
  { id: 'err', span: 1, title: 'position error p − p_d', y: 'error (mm)', s: [['e_x', diffMm('x', 'xr')], ['e_y', diffMm('y', 'yr')], ['e_z', diffMm('z', 'zr')]] },
  { id: 'roll', span: 1, title: 'roll φ and reference φ_d', y: 'angle (deg)', s: [['φ', deg('phi')], ['φ_d', deg('phir'), REF]] },
  { id: 'pitch', span: 1, title: 'pitch θ and reference θ_d', y: 'angle (deg)', s: [['θ', deg('theta')], ['θ_d', deg('thetar'), REF]] },
  { id: 'yaw', span: 1, title: 'yaw ψ and reference ψ_d', y: 'angle (deg)', s: [['ψ', deg('psi')], ['ψ_d', deg('psir'), REF]] },
  { id: 'u1', span: 1, title: 'thrust U1', y: 'U1 (N)', s: [['U1', raw('u1')]] },
  { id: 'tau', span: 0.01, title: 'torques τ (Euler coordinates)', y: 'torque (N·m)', s: [['τ_φ', raw('tphi')], ['τ_θ', raw('ttheta')], ['τ_ψ', raw('tpsi')]] },
  { id: 'dforce', span: 0.2, title: 'disturbance force (world)', y: 'force (N)', s: [['A_x', raw('fx')], ['A_y', raw('fy')], ['A_z', raw('fz')]] },
  { id: 'dtorque', span: 0.02, title: 'disturbance torque (Euler coord.)', y: 'torque (N·m)', s: [['A_φ', raw('mx')], ['A_θ', raw('my')], ['A_ψ', raw('mz')]] },
];
let plots = [];
let xRange = null;

function alpha(hex, a) {
  const c = new THREE.Color(hex);
  return `rgba(${Math.round(c.r * 255)},${Math.round(c.g * 255)},${Math.round(c.b * 255)},${a})`;
}

function drawEvents(u) {
  const ctx = u.ctx, { top, height } = u.bbox;
  const tNow = state.kind === 'replay' ? state.replay.t : Infinity;
  ctx.save();
  ctx.lineWidth = 1;
  ctx.setLineDash([4, 3]);
  for (const tr of state.tracks) {
    ctx.strokeStyle = alpha(tr.color, 0.8);
    for (const t of tr.events) {
      if (t > tNow || t < u.scales.x.min || t > u.scales.x.max) continue;
      const x = Math.round(u.valToPos(t, 'x', true)) + 0.5;
      ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, top + height); ctx.stroke();
    }
  }
  ctx.restore();
}

// y range: the data with 5 % margins, at least `span` wide (uPlot makes a flat 0 line 0..100).
function yRange(span) {
  return (u, min, max) => {
    if (min === null || max === null || !Number.isFinite(min) || !Number.isFinite(max)) return [-span / 2, span / 2];
    const pad = Math.max((max - min) * 0.05, (span - (max - min)) / 2, 0);
    return [min - pad, max + pad];
  };
}

function buildPlots() {
  for (const p of plots) p.u.destroy();
  plots = [];
  const host = $('plots');
  host.innerHTML = '';
  for (const def of PLOTS) {
    const div = document.createElement('div');
    div.className = 'plot';
    div.dataset.plot = def.id;
    host.appendChild(div);
    const series = [{ label: 't (s)' }];
    for (const tr of state.tracks) {
      def.s.forEach(([name, , opt], k) => {
        const ref = opt && opt.ref;
        series.push({
          label: name,    // the swatch's colour says which track (as in the scene and the cards)
          stroke: ref ? alpha(tr.color, 0.75) : tr.color,
          dash: ref ? opt.dash : DASH[k % DASH.length],
          width: ref ? opt.width : 1.5,
          spanGaps: true,
          points: { show: false },
          value: (u, v) => (v === null || v === undefined ? '–' : v.toFixed(Math.abs(v) < 10 ? 3 : 1)),
        });
      });
    }
    const width = Math.max(div.clientWidth - 4, 200);
    const u = new uPlot({
      title: def.title, width, height: 150, series,
      scales: { x: { time: false, range: (self, lo, hi) => xRange || [lo, hi] }, y: { range: yRange(def.span) } },
      axes: [{ label: 't (s, simulation)', size: 34, labelSize: 14 }, { label: def.y, size: 56, labelSize: 14, space: 20 }],
      legend: { show: true },
      cursor: { sync: { key: 'quadsitl' } },
      hooks: { draw: [drawEvents] },
    }, [[]].concat(series.slice(1).map(() => [])), div);
    plots.push({ def, u, div });
  }
  state.dirtyPlots = true;
}

function plotWindow() {
  const w = state.windowS;
  if (state.kind === 'replay') {
    const r = state.replay;
    return w > 0 ? [Math.max(r.t0, r.t - w), Math.max(r.t, r.t0 + 1e-3)] : [r.t0, Math.max(r.t1, r.t0 + 1e-3)];
  }
  let tEnd = -Infinity, tStart = Infinity;
  for (const tr of state.tracks) {
    const t = tr.cols.t;
    if (t.length) { tEnd = Math.max(tEnd, t[t.length - 1]); tStart = Math.min(tStart, t[0]); }
  }
  if (!Number.isFinite(tEnd)) return null;
  return w > 0 ? [Math.max(tStart, tEnd - w), tEnd] : [tStart, tEnd];
}

function drawPlots() {
  state.dirtyPlots = false;
  const win = plotWindow();
  if (!win) return;
  const [lo, hi] = win;
  xRange = [lo, hi > lo ? hi : lo + 1e-3];
  const tNow = state.kind === 'replay' ? state.replay.t : Infinity;
  for (const p of plots) {
    const tables = [];
    for (const tr of state.tracks) {
      const c = tr.cols;
      const i0 = Math.max(0, upper(c.t, lo));
      const i1 = upper(c.t, Math.min(hi, tNow)) + 1;
      const xs = c.t.slice(i0, Math.max(i0, i1));
      const cols = p.def.s.map(([, f]) => xs.map((_, j) => f(c, i0 + j)));
      tables.push([xs, ...cols]);
    }
    let data;
    if (tables.length === 1) data = tables[0];
    else data = uPlot.join(tables);
    p.u.setData(data, true);
  }
  state.plotDraws++;
}

function resizePlots() {
  for (const p of plots) p.u.setSize({ width: Math.max(p.div.clientWidth - 4, 200), height: 150 });
  state.dirtyPlots = true;
}

$('window').addEventListener('change', (e) => { state.windowS = Number(e.target.value); state.dirtyPlots = true; });

// ------------------------------------------------------------------------------------------
// Side panel: vehicle cards, replay controls, STATUSTEXT feed
// ------------------------------------------------------------------------------------------
function buildCards() {
  const host = $('vehicles');
  host.innerHTML = '';
  for (const tr of state.tracks) {
    const card = document.createElement('div');
    card.className = 'card';
    card.dataset.id = tr.id;
    card.style.borderLeftColor = tr.color;
    card.innerHTML = `<div class="name"></div><div class="grid">
      <span class="k">mode</span><span class="mode">–</span>
      <span class="k">armed</span><span><span class="arm badge off">–</span></span>
      <span class="k">landed</span><span class="landed">–</span>
      <span class="k">failsafe</span><span><span class="failsafe">none</span></span>
      <span class="k">t</span><span class="time">–</span>
      <span class="k">|p − p_d|</span><span class="err">–</span>
      <span class="k">rotors</span><span class="rotors">–</span></div>`;
    card.querySelector('.name').textContent = tr.label;
    card.title = tr.desc.source || `instance ${tr.desc.instance}, MAVLink system ${tr.desc.system_id}`;
    host.appendChild(card);
    tr.card = card;
  }
}

function setText(el, text) { if (el.textContent !== text) el.textContent = text; }

function updateCards() {
  for (const tr of state.tracks) {
    if (!tr.card) continue;
    let st = tr.status, i = tr.cols.t.length - 1;
    if (state.kind === 'replay') {
      const k = upper(tr.timelineT, state.replay.t);
      const e = k >= 0 ? tr.timeline[k] : [0, '', null, ''];
      const next = { mode: e[1], armed: e[2], landed: e[3], failsafe: replayFailsafe(tr), linked: true };
      if (next.mode !== st.mode || next.armed !== st.armed) setStatus(tr, next, state.replay.t);
      tr.status = st = next;
      i = upper(tr.cols.t, state.replay.t);
    }
    const q = (s) => tr.card.querySelector(s);
    setText(q('.mode'), st.mode || (st.linked === false ? 'no MAVLink yet' : '–'));
    const armed = q('.arm');
    setText(armed, st.armed === null || st.armed === undefined ? '–' : st.armed ? 'ARMED' : 'disarmed');
    armed.className = `arm badge ${st.armed ? 'armed' : 'off'}`;
    setText(q('.landed'), st.landed || '–');
    const fs = q('.failsafe');
    setText(fs, st.failsafe || 'none');
    fs.className = `failsafe ${st.failsafe ? 'badge warn' : ''}`;
    const c = tr.cols;
    if (i >= 0) {
      setText(q('.time'), `${fmt(c.t[i], 2)} s`);
      const e = c.xr[i] === null ? NaN : Math.hypot(c.x[i] - c.xr[i], c.y[i] - c.yr[i], c.z[i] - c.zr[i]) * 1000;
      setText(q('.err'), Number.isFinite(e) ? `${fmt(e, e < 10 ? 3 : 1)} mm` : '–');
      const rotors = rotorText(c, i);
      setText(q('.rotors'), rotors);
      q('.rotors').className = `rotors ${rotors === 'healthy' ? '' : 'badge warn'}`;
    }
  }
}

// Replays have no failsafe stream: the rules of gcs_scripts/view/telemetry.py over the recorded
// STATUSTEXT and mode timeline (a failsafe lasts until its "recovered" text, a later mode change
// (the pilot took over) or the disarm; link and simulator loss only end with their text).
const FAILSAFES = [
  { name: 'GCS link lost', start: 'GCS connection lost', end: 'GCS connection regained', onMode: false },
  { name: 'geofence', start: 'geofence breached', end: null, onMode: true },
  { name: 'offboard loss', start: 'offboard setpoints lost', end: null, onMode: true },
  { name: 'simulator lost', start: 'simulator lost', end: 'simulator link recovered', onMode: false, keepDisarmed: true },
];
function replayFailsafe(tr) {
  const t = state.replay.t;
  let found = null;
  for (const [tt, , text] of tr.texts) {
    if (tt > t) break;
    for (const f of FAILSAFES) {
      if (text.startsWith(f.start)) { found = { f, t: tt }; break; }
      if (f.end && found && found.f === f && text.startsWith(f.end)) { found = null; break; }
    }
  }
  if (!found) return null;
  const after = tr.timeline.filter((e) => e[0] >= found.t - 0.05 && e[0] <= t);
  for (const e of after.slice(1)) {
    if (e[2] === false && !found.f.keepDisarmed) return null;
    if (found.f.onMode && e[1] !== after[0][1]) return null;
  }
  return found.f.name;
}

function addText(tr, t, sev, text) {
  const li = document.createElement('li');
  li.style.borderLeftColor = tr.color;
  li.className = sev <= 2 ? 'sev-crit' : sev <= 4 ? 'sev-warn' : '';
  li.textContent = `t=${fmt(t, 2)} s ${SEVERITY[sev] || sev} [${tr.label}] ${text}`;
  const list = $('texts');
  list.insertBefore(li, list.firstChild);
  while (list.childElementCount > MAX_TEXTS) list.lastChild.remove();
}

function rebuildTextsUpTo(t) {
  $('texts').innerHTML = '';
  const all = [];
  for (const tr of state.tracks) for (const e of tr.texts) if (e[0] <= t) all.push([tr, ...e]);
  all.sort((a, b) => a[1] - b[1]);
  for (const [tr, tt, sev, text] of all.slice(-MAX_TEXTS)) addText(tr, tt, sev, text);
  state.replay.textsUpTo = t;
}

function appendTextsBetween(t0, t1) {
  const all = [];
  for (const tr of state.tracks) for (const e of tr.texts) if (e[0] > t0 && e[0] <= t1) all.push([tr, ...e]);
  all.sort((a, b) => a[1] - b[1]);
  for (const [tr, tt, sev, text] of all) addText(tr, tt, sev, text);
  state.replay.textsUpTo = t1;
}

// Replay controls: the page plays the logs itself.
const r = state.replay;
function setReplayTime(t) {
  const prev = r.t;
  r.t = clamp(t, r.t0, r.t1);
  r.ended = r.t >= r.t1;
  if (r.t < prev || r.t - prev > 5) rebuildTextsUpTo(r.t); else appendTextsBetween(r.textsUpTo, r.t);
  state.dirty3d = true; state.dirtyPlots = true; state.dirtyUi = true;
}
function updateReplayUi() {
  const slider = $('slider');
  if (document.activeElement !== slider) slider.value = String(r.t);   // not under the user's drag
  setText($('time'), `t = ${fmt(r.t, 2)} s of ${fmt(r.t0, 2)} … ${fmt(r.t1, 2)} s`);
  updateReplayState();
}
function updateReplayState() {
  setText($('replay-state'), r.playing ? 'playing' : r.ended ? 'ended' : 'paused');
  setText($('play'), r.playing ? 'pause' : r.ended ? 'replay' : 'play');
}
$('play').addEventListener('click', () => {
  if (r.playing) { r.playing = false; } else { if (r.ended) setReplayTime(r.t0); r.playing = true; r.lastTs = null; }
  updateReplayState();
});
$('speed').addEventListener('change', (e) => { r.speed = Number(e.target.value); });
$('slider').addEventListener('input', (e) => setReplayTime(Number(e.target.value)));

function advanceReplay(ts) {
  if (!r.playing) return;
  if (r.lastTs !== null) {
    const t = r.t + ((ts - r.lastTs) / 1000) * r.speed;
    if (t >= r.t1) {
      r.playing = false;
      setReplayTime(r.t1);
      updateReplayUi(); updateCards();   // the end, at once (not at the next UI tick)
    } else setReplayTime(t);
  }
  r.lastTs = ts;
}

// ------------------------------------------------------------------------------------------
// Messages
// ------------------------------------------------------------------------------------------
function onHello(m) {
  for (const tr of state.tracks) removeTrackObjects(tr);
  state.kind = m.kind;
  state.tracks = m.tracks.map((d) => makeTrack(d));
  state.modeHistory = {};
  $('texts').innerHTML = '';
  $('replay').hidden = m.kind !== 'replay';
  setText($('kind'), m.kind === 'replay' ? `replay of ${m.tracks.length} log(s)` : `live: ${m.tracks.length} vehicle(s)`);
  if (m.kind === 'replay') {
    let t0 = Infinity, t1 = -Infinity;
    m.tracks.forEach((d, i) => {
      const tr = state.tracks[i];
      for (const k of COLS) tr.cols[k] = d.cols[k] || d.cols.t.map(() => null);
      tr.timeline = d.status || []; tr.timelineT = tr.timeline.map((e) => e[0]); tr.events = d.events || []; tr.texts = d.texts || [];
      if (tr.cols.t.length) { t0 = Math.min(t0, tr.cols.t[0]); t1 = Math.max(t1, tr.cols.t[tr.cols.t.length - 1]); }
    });
    if (!Number.isFinite(t0)) { t0 = 0; t1 = 1; }
    Object.assign(r, { t0, t1, t: t0, playing: false, ended: false, lastTs: null, textsUpTo: -Infinity });
    const slider = $('slider');
    slider.min = String(t0); slider.max = String(t1); slider.step = String(Math.max((t1 - t0) / 2000, 0.001));
    $('window').value = '0';
    state.windowS = 0;
  }
  for (const tr of state.tracks) makeTrackObjects(tr);
  buildCards();
  buildPlots();
  if (m.kind === 'replay') { setReplayTime(r.t0); fit(); } else frameHomes();
  state.dirty3d = true;
}

function onTracks(m) {
  for (const d of m.tracks) {
    const tr = state.tracks.find((t) => t.id === d.id);
    if (!tr) continue;
    tr.desc = d; tr.label = d.label;
    tr.obj.name.element.textContent = d.label;
    placeTrack(tr);
    state.dirty3d = true;
  }
  frameHomes();
  buildCards();
  buildPlots();
}

function onFrame(m) {
  state.frames++;
  state.rtf = m.rtf; state.yielding = m.yielding;
  const now = performance.now();
  state.frameTimes.push(now);
  while (state.frameTimes.length && now - state.frameTimes[0] > 2000) state.frameTimes.shift();
  const span = (now - state.frameTimes[0]) / 1000;
  state.rateHz = state.frameTimes.length > 1 && span > 0 ? (state.frameTimes.length - 1) / span : 0;
  let moved = false;
  for (const v of m.v) {
    const tr = state.tracks[v.id];
    if (!tr) continue;
    if (v.s && appendSample(tr, v.s)) moved = true;
    const t = tr.cols.t.length ? tr.cols.t[tr.cols.t.length - 1] : null;
    setStatus(tr, v.st, t);
  }
  for (const [id, t] of m.events) { const tr = state.tracks[id]; if (tr) tr.events.push(t); }
  for (const [id, t, sev, text] of m.texts) {
    const tr = state.tracks[id];
    if (!tr) continue;
    tr.texts.push([t, sev, text]);
    addText(tr, t, sev, text);
  }
  if (moved) { state.dirty3d = true; state.dirtyPlots = true; }
  state.dirtyUi = true;
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  ws.onopen = () => { state.connected = true; const c = $('conn'); c.textContent = 'connected'; c.className = 'badge on'; };
  ws.onmessage = (ev) => {
    state.messages++;
    const m = JSON.parse(ev.data);
    if (m.type === 'hello') onHello(m);
    else if (m.type === 'tracks') onTracks(m);
    else if (m.type === 'frame') onFrame(m);
    schedule();
  };
  ws.onclose = () => {
    state.connected = false;
    const c = $('conn'); c.textContent = 'disconnected'; c.className = 'badge off';
    setTimeout(connect, 1000);    // the server restarts with the SITL: come back by ourselves
  };
}

// ------------------------------------------------------------------------------------------
// Loop: draw what changed, at most FPS_3D / PLOT_HZ / UI_HZ times a second, and only then: the
// loop is scheduled on demand (a frame arrived, the user did something, a replay plays), not
// at the display's 60 Hz, so an idle page costs nothing.
// ------------------------------------------------------------------------------------------
let last3d = -Infinity, lastPlots = -Infinity, lastRateLabel = -Infinity, lastUi = -Infinity;
let pending = null;
function schedule(delayMs = 0) {
  if (pending !== null) return;
  if (delayMs <= 0) { pending = 'frame'; requestAnimationFrame(loop); }
  else pending = setTimeout(() => { pending = null; schedule(0); }, delayMs);
}

function loop(ts) {
  pending = null;
  if (state.kind === 'replay') advanceReplay(ts);
  // While the server says the simulation runs much faster than real time (a batch run, the view
  // yielding the CPU to it), the page draws less often too: nobody follows 12x by eye.
  const uiPeriod = 1000 / (state.yielding ? Math.min(UI_HZ, 4) : UI_HZ);
  const period3d = 1000 / (state.yielding ? Math.min(FPS_3D, 5) : FPS_3D);
  const periodPlots = 1000 / (state.yielding ? Math.min(PLOT_HZ, 2) : PLOT_HZ);
  if (state.dirtyUi && ts - lastUi >= uiPeriod - 2) {
    lastUi = ts;
    state.dirtyUi = false;
    if (state.kind === 'replay') updateReplayUi();
    updateCards();
  }
  if (state.dirty3d && ts - last3d >= period3d - 2) { last3d = ts; render3d(); }
  if (state.dirtyPlots && ts - lastPlots >= periodPlots - 2) { lastPlots = ts; drawPlots(); }
  if (state.kind === 'live' && ts - lastRateLabel >= 500) {
    lastRateLabel = ts;
    const speed = state.rtf ? ` · simulation at ${fmt(state.rtf, 1)}× real time` : '';
    setText($('rate'), `${fmt(state.rateHz, 1)} frames/s${speed}${state.yielding ? ' (view yielding the CPU)' : ''}`);
  } else if (state.kind === 'replay') setText($('rate'), '');
  let next = Infinity;
  if (state.kind === 'replay' && r.playing) next = 0;
  if (state.dirtyUi) next = Math.min(next, lastUi + uiPeriod - ts);
  if (state.dirty3d) next = Math.min(next, last3d + period3d - ts);
  if (state.dirtyPlots) next = Math.min(next, lastPlots + periodPlots - ts);
  if (state.kind === 'live') next = Math.min(next, lastRateLabel + 500 - ts);
  if (next < Infinity) schedule(Math.max(0, next));
}

// Everything that can change what is shown asks for a loop turn.
for (const [el, ev] of [['play', 'click'], ['slider', 'input'], ['window', 'change'], ['speed', 'change'],
  ['fit', 'click'], ['follow', 'change']]) $(el).addEventListener(ev, () => schedule());
controls.addEventListener('change', () => schedule());

window.addEventListener('resize', () => { resize3d(); resizePlots(); schedule(); });
resize3d();
buildPlots();
connect();
schedule();
