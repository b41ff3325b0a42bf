// boomfmi's virtual view: the boom at the rig's geometry, the machine's posture with
// the model's as a ghost, the estimated force at the bucket, and live plots.
// Frames come over the WebSocket /ws (protocol: src/boomfmi/view/server.py); the page
// does no physics: the server sends the pivots R (rod) and T (bucket tip) per frame.
// The whole excavator (scene.kind 'excavator', frames.py) likewise: every frame carries
// the world points of its swing, boom, arm, bucket and cylinders (z up), drawn as they
// come; the tip forces are 3-vectors drawn as arrows whose heads are at the tip.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import uPlot from 'uplot';

const COLORS = { machine: 0xf0a030, ghost: 0x5ab0ff, force: 0xff4d5e, truth: 0x9aa3b5, steel: 0xb8c0cc, base: 0x59606c };
const FORCE_SCALE = 0.15 / 500;   // m of arrow per N of piston force
const WINDOW = 10;                // s of plot history

const $ = (id) => document.getElementById(id);

// -- the test and automation hook -----------------------------------------------------------
const view = {
  connected: false, connections: 0, closeCode: null, framesReceived: 0, errors: [],
  mode: null, t: null, playing: false, webgl: false, hello: null,
  _arrivals: [],
  fps() { const now = performance.now(); return this._arrivals.filter((a) => now - a <= 1000).length; },
  state() { return drawnState(); },
  play() { send({ cmd: 'play' }); }, pause() { send({ cmd: 'pause' }); },
  seek(t) { send({ cmd: 'seek', t }); },
};
window.boomView = view;

// -- 3D scene --------------------------------------------------------------------------------
const three = { scene: null, camera: null, renderer: null, controls: null, machine: null, ghost: null,
                fEst: null, fExt: null, geo: null, dirty: true };

function webglAvailable() {
  try {
    const c = document.createElement('canvas');
    return !!(c.getContext('webgl2') || c.getContext('webgl'));
  } catch (e) { return false; }
}

function material(color, ghost) {
  return ghost
    ? new THREE.MeshStandardMaterial({ color, transparent: true, opacity: 0.35, depthWrite: false, roughness: 0.6 })
    : new THREE.MeshStandardMaterial({ color, roughness: 0.55, metalness: 0.2 });
}

function along(mesh, length) {         // a cylinder or box lying on +x from 0 to length
  mesh.geometry.rotateZ(-Math.PI / 2);
  mesh.geometry.translate(length / 2, 0, 0);
  return mesh;
}

// One posture of the mechanism: the boom (a group turning about O) and the cylinder
// (a group turning about C, its rod sliding out to R).
function mechanism(g, ghost) {
  const boomMat = material(ghost ? COLORS.ghost : COLORS.machine, ghost);
  const steel = material(ghost ? COLORS.ghost : COLORS.steel, ghost);
  const boom = new THREE.Group();
  const beam = new THREE.Mesh(new THREE.BoxGeometry(g.r_tip, 0.035, 0.04), boomMat);
  beam.position.x = g.r_tip / 2;
  boom.add(beam);
  const bucket = new THREE.Mesh(new THREE.BoxGeometry(0.06, 0.07, 0.08), boomMat);
  bucket.position.set(g.r_tip, -0.03, 0);
  boom.add(bucket);
  const pinR = new THREE.Mesh(new THREE.CylinderGeometry(0.008, 0.008, 0.06, 16), steel);
  pinR.rotation.x = Math.PI / 2; pinR.position.x = g.b;
  boom.add(pinR);

  const cyl = new THREE.Group();
  cyl.position.set(g.C[0], g.C[1], 0);
  const body = along(new THREE.Mesh(new THREE.CylinderGeometry(g.bore / 2 + 0.004, g.bore / 2 + 0.004, g.body_length, 24), boomMat), g.body_length);
  const rod = along(new THREE.Mesh(new THREE.CylinderGeometry(g.rod / 2, g.rod / 2, g.rod_length, 16), steel), g.rod_length);
  cyl.add(body, rod);
  const group = new THREE.Group();
  group.add(boom, cyl);
  if (ghost) group.renderOrder = 1;
  return { group, boom, cyl, rod };
}

function pose(m, f) {
  const g = three.geo;
  if (!f || !f.R) { m.group.visible = false; return; }
  m.group.visible = true;
  m.boom.rotation.z = Math.atan2(f.T[1] - g.O[1], f.T[0] - g.O[0]);
  const dx = f.R[0] - g.C[0], dy = f.R[1] - g.C[1];
  m.cyl.rotation.z = Math.atan2(dy, dx);
  m.rod.position.x = Math.hypot(dx, dy) - g.rod_length;
}

// A solid arrow along +y of unit length (shaft and head), scaled to the force.
function solidArrow(color) {
  const mat = new THREE.MeshStandardMaterial({ color, roughness: 0.4, emissive: color, emissiveIntensity: 0.25 });
  const shaft = new THREE.Mesh(new THREE.CylinderGeometry(0.006, 0.006, 1, 12), mat);
  const head = new THREE.Mesh(new THREE.ConeGeometry(0.018, 0.04, 16), mat);
  const a = new THREE.Group();
  a.add(shaft, head);
  a.userData = { shaft, head, length: 0 };
  return a;
}

function arrow(a, f, tip, boomAngle, z) {
  if (f === null || f === undefined || !tip || Math.abs(f) < 2) { a.visible = false; a.userData.length = 0; return 0; }
  const s = Math.sign(f);   // positive: against extension, so down on the bucket (toward smaller alpha)
  const dir = new THREE.Vector3(s * Math.sin(boomAngle), -s * Math.cos(boomAngle), 0);
  const length = Math.max(0.05, Math.abs(f) * FORCE_SCALE);
  const { shaft, head } = a.userData;
  shaft.scale.y = length - 0.04;
  shaft.position.y = (length - 0.04) / 2;
  head.position.y = length - 0.02;
  a.position.set(tip[0] - dir.x * length, tip[1] - dir.y * length, z);   // its head at the bucket
  a.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), dir);
  a.visible = true;
  a.userData.length = length;
  return length;
}

function buildScene(g) {
  three.kind = g.kind || 'boom';
  if (three.controls) { three.controls.dispose(); three.controls = null; }
  if (three.kind === 'excavator') { buildExcavatorScene(g); return; }
  three.geo = g;
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x1c2027);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x303540, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.8);
  sun.position.set(0.6, 1.2, 1.0);
  scene.add(sun);
  const grid = new THREE.GridHelper(2, 20, 0x3a414d, 0x2a3039);
  grid.position.y = g.C[1] - 0.12;
  scene.add(grid);
  const baseMat = material(COLORS.base, false);
  const post = new THREE.Mesh(new THREE.BoxGeometry(0.05, 0.12 - g.C[1], 0.07), baseMat);
  post.position.set(0, (g.C[1] - 0.12) / 2, 0);
  const sill = new THREE.Mesh(new THREE.BoxGeometry(g.C[0] + 0.08, 0.03, 0.09), baseMat);
  sill.position.set(g.C[0] / 2, g.C[1] - 0.03, 0);
  scene.add(post, sill);
  for (const p of [g.O, g.C]) {
    const pin = new THREE.Mesh(new THREE.CylinderGeometry(0.01, 0.01, 0.08, 16), material(COLORS.steel, false));
    pin.rotation.x = Math.PI / 2; pin.position.set(p[0], p[1], 0);
    scene.add(pin);
  }
  three.machine = mechanism(g, false);
  three.ghost = mechanism(g, true);
  three.ghost.group.visible = false;
  scene.add(three.machine.group, three.ghost.group);
  three.fEst = solidArrow(COLORS.force);
  three.fExt = solidArrow(COLORS.truth);
  three.fEst.visible = three.fExt.visible = false;
  scene.add(three.fEst, three.fExt);
  three.scene = scene;

  const host = $('scene');
  three.camera = new THREE.PerspectiveCamera(40, host.clientWidth / Math.max(1, host.clientHeight), 0.01, 20);
  three.camera.position.set(0.32, 0.12, 1.15);
  startRenderer([0.25, 0.05, 0]);
}

function startRenderer(target) {
  const host = $('scene');
  if (!three.renderer) {
    view.webgl = webglAvailable();
    if (view.webgl) {
      three.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
      three.renderer.setPixelRatio(window.devicePixelRatio);
      host.appendChild(three.renderer.domElement);
    } else {
      host.innerHTML = '<p class="nogl">WebGL is not available in this browser: the 3D view is off, the plots go on.</p>';
      console.warn('boomfmi view: no WebGL context');
    }
  }
  if (three.renderer) {
    three.controls = new OrbitControls(three.camera, three.renderer.domElement);
    three.controls.target.set(...target);
    three.controls.addEventListener('change', () => { three.dirty = true; });
    three.controls.update();
  }
  resize();
}

// -- the whole excavator ----------------------------------------------------------------------
const TIP_ARROW_MIN = 0.5;        // N: a smaller tip force is not drawn
const UP = new THREE.Vector3(0, 1, 0);

// A mesh lying along +y from 0 to 1, placed between two world points by beamTo().
function beam(radius, mat, box) {
  const geo = box ? new THREE.BoxGeometry(radius * 2, 1, radius * 1.6) : new THREE.CylinderGeometry(radius, radius, 1, 16);
  geo.translate(0, 0.5, 0);
  return new THREE.Mesh(geo, mat);
}

function beamTo(mesh, a, b, fraction = 1) {
  const A = new THREE.Vector3(...a), B = new THREE.Vector3(...b);
  const d = B.clone().sub(A);
  const length = d.length();
  if (!(length > 1e-9)) { mesh.visible = false; return; }
  mesh.visible = true;
  mesh.position.copy(A);
  mesh.quaternion.setFromUnitVectors(UP, d.normalize());
  mesh.scale.set(1, length * fraction, 1);
}

// The drawn ends of a beam, in the world frame (what the screen shows).
function ends(mesh) {
  mesh.updateWorldMatrix(true, false);
  return [mesh.localToWorld(new THREE.Vector3(0, 0, 0)), mesh.localToWorld(new THREE.Vector3(0, 1, 0))];
}

function excavatorMechanism(g, ghost) {
  const body = material(ghost ? COLORS.ghost : COLORS.machine, ghost);
  const steel = material(ghost ? COLORS.ghost : COLORS.steel, ghost);
  const group = new THREE.Group();
  const upper = new THREE.Group();                 // the upper structure, turned by the swing
  const deck = new THREE.Mesh(new THREE.CylinderGeometry(0.09, 0.09, 0.03, 32), body);
  deck.rotation.x = Math.PI / 2; deck.position.z = 0.135;
  const cab = new THREE.Mesh(new THREE.BoxGeometry(0.12, 0.10, 0.08), body);
  cab.position.set(-0.04, 0.05, 0.19);
  upper.add(deck, cab);
  const links = { boom: beam(0.017, body, true), arm: beam(0.013, body, true), bucket: beam(0.02, body, true) };
  const cyl = {};
  for (const j of g.joints) {
    const c = g.cylinders[j];
    cyl[j] = { body: beam(c.bore / 2 + 0.003, body), rod: beam(c.rod / 2, steel) };
    group.add(cyl[j].body, cyl[j].rod);
  }
  group.add(upper, links.boom, links.arm, links.bucket);
  if (ghost) group.renderOrder = 1;
  return { group, upper, links, cyl };
}

function poseExcavator(m, f) {
  if (!f || !f.points) { m.group.visible = false; return; }
  m.group.visible = true;
  const p = f.points;
  m.upper.position.set(...p.swing_axis);
  m.upper.rotation.z = Math.atan2(p.boom_pivot[1] - p.swing_axis[1], p.boom_pivot[0] - p.swing_axis[0]);
  beamTo(m.links.boom, p.boom_pivot, p.arm_pivot);
  beamTo(m.links.arm, p.arm_pivot, p.bucket_pivot);
  beamTo(m.links.bucket, p.bucket_pivot, p.tip);
  for (const j of three.geo.joints) {
    const base = p[`cyl_${j}_base`], rod = p[`cyl_${j}_rod`];
    beamTo(m.cyl[j].body, base, rod, 0.55);
    beamTo(m.cyl[j].rod, base, rod);
  }
}

// The joint angles the drawing shows, read back from the drawn meshes (frames.py's
// _angles_of_points and excavator_angle_map): the upper structure's heading, then each
// link's pitch in its vertical plane, relative to the link before.
function excavatorAngles(m) {
  const g = three.geo;
  const h = m.upper.rotation.z;
  const e = new THREE.Vector3(Math.cos(h), Math.sin(h), 0);
  const pitch = (mesh) => { const [a, b] = ends(mesh); const d = b.sub(a); return Math.atan2(d.z, d.dot(e)); };
  const eb = pitch(m.links.boom), ea = pitch(m.links.arm), ek = pitch(m.links.bucket);
  const drawn = [h, eb, ea - eb, ek - ea];
  const wrap = (a) => Math.atan2(Math.sin(a), Math.cos(a));
  const out = {};
  g.angle_map.forEach((am, k) => { out[am.joint] = am.sign * wrap(drawn[k] - am.offset); });
  return out;
}

function tipArrow(a, f, tip, side) {
  const mag = f ? Math.hypot(f[0], f[1], f[2]) : 0;
  if (!f || !tip || !(mag >= TIP_ARROW_MIN)) {
    a.visible = false; a.userData.length = 0; a.userData.dir = null; a.userData.headAt = null; return 0;
  }
  const dir = new THREE.Vector3(f[0] / mag, f[1] / mag, f[2] / mag);
  const length = Math.max(0.05, mag * three.geo.force_scale);
  const { shaft, head } = a.userData;
  shaft.scale.y = length - 0.04;
  shaft.position.y = (length - 0.04) / 2;
  head.position.y = length - 0.02;
  const H = new THREE.Vector3(...tip).add(side);                      // its head at the tip (beside it)
  a.position.copy(H.clone().sub(dir.clone().multiplyScalar(length)));
  a.quaternion.setFromUnitVectors(UP, dir);
  a.visible = true;
  a.userData.length = length;
  a.userData.dir = [dir.x, dir.y, dir.z];
  a.userData.headAt = [H.x, H.y, H.z];
  return length;
}

// The interval of the estimated tip force (per axis, f_tip_lo to f_tip_hi) as a box
// around the estimate's arrow: the tails, at the page's force scale with the head
// fixed, of the arrows of every force in the interval.  A side reaches at most
// INTERVAL_REACH N beyond the estimate; an open side (null: a stop or a sticking joint
// leaves it unbounded) or one beyond that is drawn there and reported as open.
const INTERVAL_REACH = 100;
function intervalBox(box, arrow, f, lo, hi) {
  if (!arrow.visible || !f || !lo || !hi) { box.visible = false; box.userData = {}; return; }
  const scale = three.geo.force_scale, H = arrow.userData.headAt, min = [], max = [], open = [];
  const given = (v) => v !== null && v !== undefined;
  for (let k = 0; k < 3; k++) {
    const a = given(lo[k]) ? Math.max(lo[k], f[k] - INTERVAL_REACH) : f[k] - INTERVAL_REACH;
    const b = given(hi[k]) ? Math.min(hi[k], f[k] + INTERVAL_REACH) : f[k] + INTERVAL_REACH;
    open.push([a !== lo[k], b !== hi[k]]);
    min.push(H[k] - b * scale); max.push(H[k] - a * scale);
  }
  box.scale.set(...[0, 1, 2].map((k) => Math.max(max[k] - min[k], 0.002)));
  box.position.set(...[0, 1, 2].map((k) => (min[k] + max[k]) / 2));
  box.visible = true;
  box.userData = { min, max, open };
}

function buildExcavatorScene(g) {
  three.geo = g;
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x1c2027);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x303540, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.8);
  sun.position.set(0.6, -0.8, 1.6);
  scene.add(sun);
  const grid = new THREE.GridHelper(3, 30, 0x3a414d, 0x2a3039);   // the ground plane, z = ground_z
  grid.rotation.x = Math.PI / 2; grid.position.z = g.ground_z;
  scene.add(grid);
  const under = new THREE.Mesh(new THREE.BoxGeometry(0.30, 0.22, 0.10), material(COLORS.base, false));
  under.position.set(0, 0, g.ground_z + 0.05);                      // the undercarriage
  scene.add(under);
  three.machine = excavatorMechanism(g, false);
  three.ghost = excavatorMechanism(g, true);
  three.ghost.group.visible = false;
  scene.add(three.machine.group, three.ghost.group);
  three.fEst = solidArrow(COLORS.force);
  three.fExt = solidArrow(COLORS.truth);
  three.fEst.visible = three.fExt.visible = false;
  three.fBox = new THREE.LineSegments(new THREE.EdgesGeometry(new THREE.BoxGeometry(1, 1, 1)),
                                      new THREE.LineBasicMaterial({ color: COLORS.force, transparent: true, opacity: 0.7 }));
  three.fBox.visible = false;
  scene.add(three.fEst, three.fExt, three.fBox);
  three.scene = scene;
  const host = $('scene');
  three.camera = new THREE.PerspectiveCamera(40, host.clientWidth / Math.max(1, host.clientHeight), 0.01, 30);
  three.camera.up.set(0, 0, 1);
  three.camera.position.set(0.9, -1.6, 0.9);
  startRenderer([0.35, 0, 0.15]);
}

function showExcavator(f) {
  poseExcavator(three.machine, f.machine);
  poseExcavator(three.ghost, f.model);
  const tip = f.machine && f.machine.points ? f.machine.points.tip : null;
  const h = three.machine.upper.rotation.z;
  const side = new THREE.Vector3(-Math.sin(h), Math.cos(h), 0).multiplyScalar(0.03);   // across the plane
  tipArrow(three.fEst, f.f_tip_est, tip, side);
  tipArrow(three.fExt, f.f_tip, tip, side.clone().negate());
  intervalBox(three.fBox, three.fEst, f.f_tip_est, f.f_tip_lo, f.f_tip_hi);
  three.dirty = true;
  const deg = (a) => (a === null || a === undefined ? '   -  ' : (a * 180 / Math.PI).toFixed(2).padStart(7));
  const vec = (v) => (v ? v.map((c) => c.toFixed(1).padStart(6)).join(' ') : '   -');
  const lines = [`t       ${f.t.toFixed(3)} s          machine    model [deg]`];
  for (const j of three.geo.joints) {
    lines.push(`${j.padEnd(8)}${deg(f.machine && f.machine.angle[j])}    ${deg(f.model && f.model.angle[j])}`);
  }
  lines.push(`f_tip_est [N] ${vec(f.f_tip_est)}   f_tip (truth) ${vec(f.f_tip)}`);
  $('readout').textContent = lines.join('\n');
}

function excavatorState() {
  const m = three.machine, gh = three.ghost;
  const arrowOf = (a) => ({ visible: a.visible, length: a.visible ? a.userData.length : 0,
                            dir: a.userData.dir || null, head: a.userData.headAt || null });
  return {
    kind: 'excavator', t: view.t, playing: view.playing, webgl: view.webgl,
    machineAngles: m.group.visible ? excavatorAngles(m) : null, machineVisible: m.group.visible,
    ghostAngles: gh.group.visible ? excavatorAngles(gh) : null, ghostVisible: gh.group.visible,
    tip: last && last.machine && last.machine.points ? last.machine.points.tip : null,
    arrowEst: arrowOf(three.fEst), arrowTruth: arrowOf(three.fExt),
    intervalBox: { visible: three.fBox.visible, min: three.fBox.userData.min || null,
                   max: three.fBox.userData.max || null, open: three.fBox.userData.open || null },
    fTipLo: last ? last.f_tip_lo || null : null, fTipHi: last ? last.f_tip_hi || null : null,
    arrowLength: three.fEst.visible ? three.fEst.userData.length : 0,
    fTipEst: last ? last.f_tip_est : null, fTip: last ? last.f_tip : null,
  };
}

function drawnState() {
  const g = three.geo;
  if (!g) return null;
  if (three.kind === 'excavator') return excavatorState();
  const ref = Math.atan2(g.C[1] - g.O[1], g.C[0] - g.O[0]);          // the direction O->C
  const m = three.machine, gh = three.ghost;
  return {
    t: view.t, playing: view.playing, webgl: view.webgl,
    machineAlpha: m.boom.rotation.z - ref, machineVisible: m.group.visible,
    ghostAlpha: gh.boom.rotation.z - ref, ghostVisible: gh.group.visible,
    arrowLength: three.fEst.visible ? three.fEst.userData.length : 0,
    fEst: last ? last.f_est : null,
  };
}

// -- plots -----------------------------------------------------------------------------------
const BOOM_PLOTS = [
  { title: 'p_a [bar gauge]: machine, model dashed', unit: 'bar', series: [['machine', COLORS.machine, (f) => bar(f.machine && f.machine.p_a)],
                                                    ['model', COLORS.ghost, (f) => bar(f.model && f.model.p_a), true]] },
  { title: 'p_b [bar gauge]: machine, model dashed', unit: 'bar', series: [['machine', COLORS.machine, (f) => bar(f.machine && f.machine.p_b)],
                                                    ['model', COLORS.ghost, (f) => bar(f.model && f.model.p_b), true]] },
  { title: 'x [mm]: machine, model dashed', unit: 'mm', series: [['machine', COLORS.machine, (f) => mm(f.machine && f.machine.x)],
                                          ['model', COLORS.ghost, (f) => mm(f.model && f.model.x), true]] },
  { title: 'force on the piston [N]: f_est, f_ext dashed', unit: 'N', series: [['f_est', COLORS.force, (f) => f.f_est],
                                            ['f_ext (truth)', COLORS.truth, (f) => f.f_ext, true]] },
];
const JOINT_COLORS = { swing: 0xc792ea, boom: 0xf0a030, arm: 0x7fd17f, bucket: 0x5ad8e6 };
const AXIS_COLORS = [0xff4d5e, 0x7fd17f, 0x5ab0ff];            // the tip force's x, y, z
const EXCAVATOR_JOINTS = ['swing', 'boom', 'arm', 'bucket'];
const rad2deg = (a) => (a === null || a === undefined ? null : a * 180 / Math.PI);
const perJoint = (what, conv, model) => EXCAVATOR_JOINTS.map((j) => [`${j}${model ? ' model' : ''}`, JOINT_COLORS[j],
  (f) => { const p = model ? f.model : f.machine; return p ? conv(p[what][j]) : null; }, model]);
const EXCAVATOR_PLOTS = [
  { title: 'joint angles [deg]: machine, model dashed', series: [...perJoint('angle', rad2deg, false), ...perJoint('angle', rad2deg, true)] },
  { title: 'p_a [bar gauge] per joint: machine, model dashed', series: [...perJoint('p_a', (p) => bar(p), false), ...perJoint('p_a', (p) => bar(p), true)] },
  { title: 'p_b [bar gauge] per joint: machine, model dashed', series: [...perJoint('p_b', (p) => bar(p), false), ...perJoint('p_b', (p) => bar(p), true)] },
  { title: 'tip force [N]: estimated, truth dashed, interval shaded', series: [0, 1, 2].flatMap((k) => [
    [`est ${'xyz'[k]}`, AXIS_COLORS[k], (f) => (f.f_tip_est ? f.f_tip_est[k] : null)],
    [`truth ${'xyz'[k]}`, AXIS_COLORS[k], (f) => (f.f_tip ? f.f_tip[k] : null), true],
    [`${'xyz'[k]} low`, AXIS_COLORS[k], (f) => (f.f_tip_lo ? f.f_tip_lo[k] : null), false, 'lo'],
    [`${'xyz'[k]} high`, AXIS_COLORS[k], (f) => (f.f_tip_hi ? f.f_tip_hi[k] : null), false, 'hi']]) },
];
let PLOTS = BOOM_PLOTS;
function bar(p) { return p === null || p === undefined ? null : p / 1e5; }
function mm(x) { return x === null || x === undefined ? null : x * 1e3; }
const hex = (c) => '#' + c.toString(16).padStart(6, '0');
const plots = { charts: [], data: [], dirty: false };

function buildPlots(kind) {
  PLOTS = kind === 'excavator' ? EXCAVATOR_PLOTS : BOOM_PLOTS;
  plots.kind = kind || 'boom';
  $('legend').querySelector('.band').hidden = plots.kind !== 'excavator';   // the tip force's interval
  const host = $('plots');
  host.innerHTML = '';
  plots.charts = []; plots.data = [];
  for (const p of PLOTS) {
    const div = document.createElement('div');
    div.className = 'plot';
    host.appendChild(div);
    // every colour named in the plot's legend (live: false, the labels only); an
    // interval's low and high lines thin and faint, the band between them shaded
    const bands = [];
    p.series.forEach(([, color, , , role], j) => {
      if (role === 'hi') bands.push({ series: [j + 1, j], fill: hex(color) + '33' });
    });
    const opts = {
      title: p.title, width: Math.max(200, div.clientWidth), height: 80,
      scales: { x: { time: false } }, legend: { show: true, live: false }, bands,
      axes: [{ stroke: '#8a93a3', grid: { stroke: '#2a3039' } }, { stroke: '#8a93a3', grid: { stroke: '#2a3039' }, size: 50 }],
      series: [{ label: 't [s]' }, ...p.series.map(([label, color, , dashed, role]) => ({
        label, stroke: role ? hex(color) + '66' : hex(color), width: role ? 0.75 : 1.5,
        dash: dashed ? [6, 4] : undefined, spanGaps: false,
      }))],
    };
    const data = [[], ...p.series.map(() => [])];
    plots.data.push(data);
    plots.charts.push(new uPlot(opts, data, div));
  }
  if (plots.charts.length) resize();          // each to its share, now that all are laid out
}

function plotPush(f) {
  if ((f.kind || 'boom') !== plots.kind) return;          // the other machine's frame: not these plots
  PLOTS.forEach((p, i) => {
    const d = plots.data[i];
    d[0].push(f.t);
    p.series.forEach(([, , get], j) => { const v = get(f); d[j + 1].push(v === undefined ? null : v); });
    let cut = 0;
    while (cut < d[0].length && d[0][cut] < f.t - WINDOW) cut++;
    if (cut) d.forEach((col) => col.splice(0, cut));
  });
  plots.dirty = true;
}

function plotReset(frames) {
  plots.data.forEach((d) => d.forEach((col) => { col.length = 0; }));
  frames.forEach(plotPush);
}

// -- frames and the connection ---------------------------------------------------------------
let socket = null, last = null, retry = 500, wanted = null;

function send(msg) { if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(msg)); }

function show(f) {
  last = f;
  view.t = f.t;
  view.playing = !!f.playing;
  if (!three.geo) return;
  if ((f.kind || 'boom') !== three.kind) return;       // a frame of the other machine before its hello
  if (three.kind === 'excavator') { showExcavator(f); showControls(f); return; }
  pose(three.machine, f.machine);
  pose(three.ghost, f.model);
  const ang = three.machine.boom.rotation.z;
  arrow(three.fEst, f.f_est, f.machine && f.machine.T, ang, 0.06);
  arrow(three.fExt, f.f_ext, f.machine && f.machine.T, ang, -0.06);
  three.dirty = true;
  const deg = (a) => (a === null || a === undefined ? '   -  ' : (a * 180 / Math.PI).toFixed(2).padStart(6));
  const num = (v, d = 0) => (v === null || v === undefined ? '-' : v.toFixed(d));
  $('readout').textContent =
    `t       ${f.t.toFixed(3)} s\n` +
    `alpha   ${deg(f.machine && f.machine.alpha)} deg machine   ${deg(f.model && f.model.alpha)} deg model\n` +
    `x       ${num(mm(f.machine && f.machine.x), 1).padStart(6)} mm  machine   ${num(mm(f.model && f.model.x), 1).padStart(6)} mm  model\n` +
    `f_est   ${num(f.f_est)} N   f_ext ${num(f.f_ext)} N   f_reflect ${num(f.f_reflect, 2)} N`;
  showControls(f);
}

function showControls(f) {
  if (view.mode === 'replay' && !seeking) {
    $('seek').value = f.t;
    $('time').textContent = `${f.t.toFixed(2)} s`;
    $('play').textContent = f.playing ? 'pause' : 'play';
  }
}

function onMessage(ev) {
  const msg = JSON.parse(ev.data);
  if (msg.type === 'hello') {
    view.hello = msg; view.mode = msg.mode;
    $('source').textContent = `${msg.mode}: ${msg.source}`;
    $('controls').classList.toggle('live', msg.mode !== 'replay');
    if (msg.duration !== null) { $('seek').min = msg.t0; $('seek').max = msg.t0 + msg.duration; }
    const kind = msg.scene.kind || 'boom';
    if (!three.geo || three.kind !== kind) { buildScene(msg.scene); last = null; }
    if (plots.kind !== kind) buildPlots(kind);
    if (wanted && msg.mode === 'replay') {            // back after a dropped connection: resume there
      send({ cmd: 'speed', value: Number($('speed').value) });
      if (!wanted.playing) send({ cmd: 'pause' });
      send({ cmd: 'seek', t: wanted.t });
      if (wanted.playing) send({ cmd: 'play' });
    }
  } else if (msg.type === 'history') {
    plotReset(msg.frames);
  } else if (msg.type === 'frame') {
    view.framesReceived++;
    const now = performance.now();
    view._arrivals.push(now);
    while (view._arrivals.length && now - view._arrivals[0] > 2000) view._arrivals.shift();
    if (last && f_back(msg)) plotReset([]);
    show(msg);
    plotPush(msg);
  } else if (msg.type === 'error') {
    console.warn('boomfmi view:', msg.message);
    view.errors.push(msg.message);
  }
}

function f_back(f) { return last && f.t < last.t - 1e-9 && view.mode === 'live'; }   // a new live run

function connect() {
  const status = $('status');
  socket = new WebSocket(`ws://${location.host}/ws`);
  socket.onopen = () => {
    view.connected = true; view.connections++; retry = 500;
    status.textContent = 'connected'; status.className = 'up';
  };
  socket.onmessage = onMessage;
  socket.onclose = (ev) => {
    view.closeCode = ev.code;          // 1001: the server is stopping
    if (view.connected) wanted = last ? { t: last.t, playing: !!last.playing } : wanted;
    view.connected = false;
    status.textContent = 'reconnecting'; status.className = 'down';
    setTimeout(connect, retry);
    retry = Math.min(2000, retry * 2);   // a local server: back within 2 s of its return
  };
  socket.onerror = () => {};       // onclose follows and retries; nothing to report twice
}

// -- controls, sizing, the loop --------------------------------------------------------------
let seeking = false;
$('play').addEventListener('click', () => send({ cmd: view.playing ? 'pause' : 'play' }));
$('seek').addEventListener('input', () => {
  seeking = true;
  $('time').textContent = `${Number($('seek').value).toFixed(2)} s`;
  send({ cmd: 'seek', t: Number($('seek').value) });
});
$('seek').addEventListener('change', () => { seeking = false; });
$('speed').addEventListener('change', () => send({ cmd: 'speed', value: Number($('speed').value) }));

function resize() {
  const host = $('scene');
  if (three.renderer && three.camera) {
    three.renderer.setSize(host.clientWidth, host.clientHeight);
    three.camera.aspect = host.clientWidth / Math.max(1, host.clientHeight);
    three.camera.updateProjectionMatrix();
    three.dirty = true;
  }
  document.querySelectorAll('#plots .plot').forEach((div, i) => {
    const c = plots.charts[i];
    if (!c) return;
    // the chart's canvas (its axes and their labels) gets what its box leaves beside the
    // title and the legend: nothing spills into the plot below
    const title = c.root.querySelector('.u-title'), legend = c.root.querySelector('.u-legend');
    const rest = (title ? title.offsetHeight : 0) + (legend ? legend.offsetHeight : 0) + 4;
    c.setSize({ width: div.clientWidth, height: Math.max(40, div.clientHeight - rest) });
  });
}
window.addEventListener('resize', resize);

let lastPlot = 0;
function loop(now) {
  requestAnimationFrame(loop);
  if (three.renderer && three.dirty) { three.renderer.render(three.scene, three.camera); three.dirty = false; }
  if (plots.dirty && now - lastPlot > 33) {            // plots at 30 Hz at most
    plots.charts.forEach((c, i) => c.setData(plots.data[i]));
    plots.dirty = false; lastPlot = now;
  }
}

buildPlots('boom');
connect();
requestAnimationFrame(loop);
