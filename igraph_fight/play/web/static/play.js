// The game page of `igraph-fight play`: draws the two fighters streamed by the server (joint
// positions at 30 frames a second, interpolated here), sends the player's commands, and shows
// the HUD. Everything the page learns is kept in window.__play (the tests read it).
import * as THREE from '/vendor/three/three.module.js';

const S = {
  hello: null, status: {}, frame: null, framesReceived: 0, rendered: 0, fps: 0,
  decisions: [], policies: [], errors: [], saved: null, bouts: null, replayEnd: null,
  hud: {}, connected: false, flashing: [false, false],
};
window.__play = S;
S.send = (type, fields) => send(type, fields);

const $ = (id) => document.getElementById(id);
const KEY_NAMES = { ArrowUp: '\u2191', ArrowDown: '\u2193', ArrowLeft: '\u2190', ArrowRight: '\u2192', Space: 'Space' };
const keyName = (code) => KEY_NAMES[code] || code.replace(/^Key/, '');

// ----- the connection ------------------------------------------------------------------------
const ws = new WebSocket((location.protocol === 'https:' ? 'wss://' : 'ws://') + location.host + '/game');
const send = (type, fields = {}) => {
  if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ v: 1, type, ...fields }));
};
ws.onopen = () => { S.connected = true; };
ws.onclose = () => { S.connected = false; $('mode').textContent = 'disconnected (restart igraph-fight play and reload)'; };
ws.onmessage = (ev) => {
  const m = JSON.parse(ev.data);
  switch (m.type) {
    case 'hello': onHello(m); break;
    case 'frame': onFrame(m); break;
    case 'decision': onDecision(m); break;
    case 'status': onStatus(m); break;
    case 'policy': S.policies.push(m); say(`B now plays ${m.style}, depth ${m.depth} ` +
      `(best action changed in ${(100 * (m.changed_share || 0)).toFixed(1)}% of the graph's states)`); break;
    case 'saved': S.saved = m; say(`saved as ${m.name}`); send('list_bouts'); break;
    case 'bouts': onBouts(m.bouts); break;
    case 'replay_end': S.replayEnd = m; say(`replay over: hits ${m.hits.join(' : ')} ` +
      (m.matches_log ? '(as in the log)' : `(the log says ${m.log_hits.join(' : ')})`)); break;
    case 'error': S.errors.push(m); say(`error: ${m.message}`); break;
    default: break;
  }
};
const say = (text) => { $('msg').textContent = text; };

// ----- the scene -----------------------------------------------------------------------------
const canvas = $('view');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, powerPreference: 'high-performance' });
renderer.setPixelRatio(1);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x14161b);
const camera = new THREE.PerspectiveCamera(50, 1, 0.05, 100);
camera.position.set(0, 1.8, 5);
scene.add(new THREE.HemisphereLight(0xdfe8ff, 0x2a2420, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
sun.position.set(3, 8, 4);
scene.add(sun);

function buildRing() {
  const half = 3.5;
  const floor = new THREE.Mesh(new THREE.BoxGeometry(2 * half + 1, 0.2, 2 * half + 1),
    new THREE.MeshBasicMaterial({ color: 0x2c3749 }));
  floor.position.y = -0.1;
  scene.add(floor);
  const canvasMat = new THREE.Mesh(new THREE.PlaneGeometry(2 * half, 2 * half),
    new THREE.MeshBasicMaterial({ color: 0xbdb4a3 }));
  canvasMat.rotation.x = -Math.PI / 2;
  canvasMat.position.y = 0.002;
  scene.add(canvasMat);
  const postMat = new THREE.MeshLambertMaterial({ color: 0xb0b4bc });
  const ropeMat = [new THREE.MeshLambertMaterial({ color: 0xd64541 }), new THREE.MeshLambertMaterial({ color: 0xf0f0f0 }),
    new THREE.MeshLambertMaterial({ color: 0x3e6fd1 })];
  const corners = [[-half, -half], [half, -half], [half, half], [-half, half]];
  for (const [x, z] of corners) {
    const post = new THREE.Mesh(new THREE.CylinderGeometry(0.07, 0.07, 1.4, 8), postMat);
    post.position.set(x, 0.7, z);
    scene.add(post);
  }
  for (let k = 0; k < 4; k++) {
    const [x0, z0] = corners[k];
    const [x1, z1] = corners[(k + 1) % 4];
    const len = Math.hypot(x1 - x0, z1 - z0);
    for (let r = 0; r < 3; r++) {
      const rope = new THREE.Mesh(new THREE.CylinderGeometry(0.02, 0.02, len, 6), ropeMat[r]);
      rope.position.set((x0 + x1) / 2, 0.5 + 0.35 * r, (z0 + z1) / 2);
      rope.rotation.z = Math.PI / 2;
      rope.rotation.y = Math.atan2(-(z1 - z0), x1 - x0);
      scene.add(rope);
    }
  }
}
buildRing();

const UP = new THREE.Vector3(0, 1, 0);
const COLORS = [{ body: 0xd9574a, glove: 0x8e1b12 }, { body: 0x4a80d9, glove: 0x14306e }];

class Fighter {
  constructor(drawing, positions, who) {
    this.d = drawing;
    this.group = new THREE.Group();
    this.mat = new THREE.MeshLambertMaterial({ color: COLORS[who].body });
    this.gloveMat = new THREE.MeshLambertMaterial({ color: COLORS[who].glove });
    this.headMat = new THREE.MeshLambertMaterial({ color: 0xe8c4a0 });
    this.bones = drawing.bones.map(([i, j], k) => {
      const len = dist(positions, i, j);
      const r = drawing.radii[k];
      const mesh = new THREE.Mesh(new THREE.CapsuleGeometry(r, Math.max(len - r, 0.01), 3, 10), this.mat);
      this.group.add(mesh);
      return { i, j, mesh };
    });
    this.head = null;
    if (drawing.head >= 0) {
      this.head = new THREE.Mesh(new THREE.SphereGeometry(drawing.head_radius, 14, 10), this.headMat);
      this.group.add(this.head);
    }
    this.fists = drawing.fists.filter((f) => f >= 0).map((f) => {
      const m = new THREE.Mesh(new THREE.SphereGeometry(drawing.fist_radius, 12, 8), this.gloveMat);
      this.group.add(m);
      return { f, m };
    });
    this.flashUntil = 0;
    scene.add(this.group);
  }

  update(P) {
    const a = new THREE.Vector3();
    const b = new THREE.Vector3();
    for (const bone of this.bones) {
      a.set(P[3 * bone.i], P[3 * bone.i + 1], P[3 * bone.i + 2]);
      b.set(P[3 * bone.j], P[3 * bone.j + 1], P[3 * bone.j + 2]);
      bone.mesh.position.addVectors(a, b).multiplyScalar(0.5);
      const dir = b.sub(a);
      const n = dir.length();
      if (n > 1e-6) bone.mesh.quaternion.setFromUnitVectors(UP, dir.multiplyScalar(1 / n));
    }
    if (this.head) {
      const h = this.d.head;
      const nk = this.d.neck;
      a.set(P[3 * h], P[3 * h + 1], P[3 * h + 2]);
      if (nk >= 0) {
        b.set(P[3 * nk], P[3 * nk + 1], P[3 * nk + 2]);
        const up = a.clone().sub(b);
        if (up.length() > 1e-6) a.add(up.normalize().multiplyScalar(0.6 * this.d.head_radius));
      }
      this.head.position.copy(a);
    }
    for (const { f, m } of this.fists) m.position.set(P[3 * f], P[3 * f + 1], P[3 * f + 2]);
  }

  flash(now) {
    const on = now < this.flashUntil;
    const e = on ? 0xffffff : 0x000000;
    this.mat.emissive.setHex(e);
    this.headMat.emissive.setHex(e);
    this.mat.emissiveIntensity = on ? 0.8 : 0;
    this.headMat.emissiveIntensity = on ? 0.8 : 0;
  }
}
const dist = (P, i, j) => Math.hypot(P[3 * i] - P[3 * j], P[3 * i + 1] - P[3 * j + 1], P[3 * i + 2] - P[3 * j + 2]);

let fighters = null;
let prev = null;
let cur = null;
let arrived = 0;
let framePeriod = 1000 / 30;
const camTarget = new THREE.Vector3(0, 1.1, 0);

// ----- messages ------------------------------------------------------------------------------
function onHello(m) {
  S.hello = m;
  framePeriod = 1000 / m.fps;
  const table = $('key-table');
  table.innerHTML = '';
  for (const c of m.commands) {
    const tr = document.createElement('tr');
    tr.dataset.command = c.command;
    tr.innerHTML = `<td class="k">${c.keys.map(keyName).join(' / ')}</td><td>${c.command.replace('_', ' ')}</td>`;
    table.appendChild(tr);
  }
  const sel = $('style-select');
  sel.innerHTML = '';
  for (const s of [...m.styles, 'style file\u2026']) {
    const o = document.createElement('option');
    o.value = s.endsWith('\u2026') ? '__file__' : s;
    o.textContent = s;
    sel.appendChild(o);
  }
  $('depth').min = m.depth_range[0];
  $('depth').max = m.depth_range[1];
  send('list_bouts');
}

function onFrame(m) {
  S.framesReceived += 1;
  if (S.frozen) return;  // a still view: neither the bodies nor the HUD move
  S.frame = m;
  const P = [Float32Array.from(m.pose[0]), Float32Array.from(m.pose[1])];
  if (!fighters) fighters = [new Fighter(S.hello.drawing, P[0], 0), new Fighter(S.hello.drawing, P[1], 1)];
  prev = cur && (m.i - S.lastIndex === 1) ? cur : P;
  cur = P;
  S.lastIndex = m.i;
  arrived = performance.now();
  for (const h of m.hit_events || []) fighters[h.victim].flashUntil = arrived + 180;
  S.hud = { hits: m.hits, score: m.score, distance: m.distance, labels: m.labels, time_left: m.time_left };
  $('hits-a').textContent = m.hits[0];
  $('hits-b').textContent = m.hits[1];
  $('score').textContent = (m.score >= 0 ? '+' : '') + m.score;
  $('distance').textContent = m.distance.toFixed(2);
  $('label-a').textContent = m.labels[0].replace('_', ' ');
  $('label-b').textContent = m.labels[1].replace('_', ' ');
  $('time-left').textContent = m.time_left.toFixed(1);
  if (m.assist_mg && S.status.physics) {
    const down = m.down || [false, false];
    $('physics').textContent = `${S.status.physics} \u00b7 assist now A ${m.assist_mg[0].toFixed(2)} mg, B ${m.assist_mg[1].toFixed(2)} mg`
      + (down[0] || down[1] ? ` \u00b7 down: ${down[0] ? 'A' : ''}${down[1] ? 'B' : ''}` : '');
  }
}

function onDecision(m) {
  m.at = performance.now();
  S.decisions.push(m);
  if (S.decisions.length > 2000) S.decisions.splice(0, 1000);
  if (m.player === 0 && !S.frozen) {
    const how = m.source === 'idle' || !m.command ? 'no command' : m.command.replace('_', ' ');
    $('cmd-a').textContent = `${how} \u2192 ${m.label.replace('_', ' ')}` + (m.level > 0 ? ' (nearest)' : m.level < 0 ? ' (best)' : '')
      + (m.replay ? ' (replay)' : '');
  }
}

function onStatus(m) {
  S.status = m;
  $('style-b').textContent = m.style;
  $('depth-b').textContent = m.depth;
  if (m.physics) { $('physics').textContent = m.physics; $('physics').hidden = false; }
  if (m.mode !== 'replay') { $('depth').value = m.depth; $('depth-value').textContent = m.depth; }
  $('mode').textContent = { live: 'live bout', over: 'bout over', replay: `replay of ${m.bout}`, paused: 'paused' }[m.mode] || m.mode;
  const banner = $('banner');
  if (m.mode === 'replay') { banner.textContent = 'REPLAY'; banner.hidden = false; }
  else if (m.mode === 'over') { banner.textContent = 'BOUT OVER'; banner.hidden = false; }
  else if (m.mode === 'paused') { banner.textContent = 'PAUSED'; banner.hidden = false; }
  else banner.hidden = true;
  $('pause').textContent = m.mode === 'paused' ? 'resume' : 'pause';
}

function onBouts(list) {
  S.bouts = list;
  const sel = $('bouts');
  sel.innerHTML = '<option value="">saved bouts\u2026</option>';
  for (const b of list) {
    const o = document.createElement('option');
    o.value = b.name;
    const h = (b.hits || []).join(':');
    o.textContent = `${b.name} (${h})`;
    sel.appendChild(o);
  }
}

// ----- input ---------------------------------------------------------------------------------
const commandOf = (code) => (S.hello ? (S.hello.commands.find((c) => c.keys.includes(code)) || {}).command : undefined);
const markKey = (cmd, on) => {
  const tr = document.querySelector(`#key-table tr[data-command="${cmd}"]`);
  if (tr) tr.classList.toggle('on', on);
};
window.addEventListener('keydown', (e) => {
  if (e.target instanceof HTMLInputElement || e.target instanceof HTMLSelectElement) return;
  const cmd = commandOf(e.code);
  if (!cmd) return;
  e.preventDefault();
  if (e.repeat) return;
  send('command', { command: cmd, held: true });
  markKey(cmd, true);
});
window.addEventListener('keyup', (e) => {
  const cmd = commandOf(e.code);
  if (!cmd) return;
  send('release', { command: cmd });
  markKey(cmd, false);
});
$('style-select').addEventListener('change', (e) => {
  const v = e.target.value;
  $('style-file-row').hidden = v !== '__file__';
  if (v !== '__file__') send('set_style', { style: v });
});
$('style-file').addEventListener('change', (e) => { if (e.target.value) send('set_style', { style: e.target.value }); });
$('depth').addEventListener('input', (e) => { $('depth-value').textContent = e.target.value; });
$('depth').addEventListener('change', (e) => send('set_depth', { depth: parseInt(e.target.value, 10) }));
$('new-bout').addEventListener('click', () => send('new_bout'));
$('pause').addEventListener('click', () => send('pause', { paused: S.status.mode !== 'paused' }));
$('save').addEventListener('click', () => send('save'));
$('refresh').addEventListener('click', () => send('list_bouts'));
$('replay').addEventListener('click', () => {
  const b = $('bouts').value;
  if (b) send('replay', { bout: b, speed: parseFloat($('speed').value) });
});
for (const id of ['new-bout', 'pause', 'save', 'refresh', 'replay']) $(id).addEventListener('keydown', (e) => e.preventDefault());

// ----- the render loop -----------------------------------------------------------------------
let fpsCount = 0;
let fpsSince = performance.now();
function resize() {
  const w = window.innerWidth;
  const h = window.innerHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
}
window.addEventListener('resize', resize);
resize();

// Dynamic resolution: where the machine cannot draw full-size frames at 30 a second (software
// WebGL), the page renders fewer pixels (down to half the width and height) rather than drop frames;
// it never scales back up (no oscillation), a reload starts at full size.
// `?scale=0.5` (0.25-1) fixes the resolution instead.
const fixedScale = parseFloat(new URLSearchParams(location.search).get('scale'));
S.scale = fixedScale >= 0.25 && fixedScale <= 1 ? fixedScale : 1;
renderer.setPixelRatio(S.scale);
let slowSeconds = 0;
function adaptScale() {
  if (fixedScale) return;
  if (S.fps < 30 && S.scale > 0.5) slowSeconds += 1; else slowSeconds = 0;
  if (slowSeconds >= 2) {
    S.scale = Math.max(0.5, S.scale - 0.125);
    renderer.setPixelRatio(S.scale);
    resize();
    slowSeconds = 0;
  }
}

function render(now) {
  requestAnimationFrame(render);
  fpsCount += 1;
  if (now - fpsSince >= 1000) {
    S.fps = (1000 * fpsCount) / (now - fpsSince);
    adaptScale();
    $('fps-value').textContent = S.fps.toFixed(0);
    $('fps-scale').textContent = S.scale < 1 ? ` at ${Math.round(100 * S.scale)}% resolution` : '';
    fpsCount = 0;
    fpsSince = now;
  }
  const drawn = [null, null];
  if (fighters && cur && !S.frozen) {  // S.frozen (set from the console or a test) holds the view still
    const a = Math.min(Math.max((now - arrived) / framePeriod, 0), 1);
    const pel = S.hello.drawing.pelvis;
    for (let k = 0; k < 2; k++) {
      const P = new Float32Array(cur[k].length);
      for (let i = 0; i < P.length; i++) P[i] = prev[k][i] + (cur[k][i] - prev[k][i]) * a;
      fighters[k].update(P);
      fighters[k].flash(now);
      S.flashing[k] = now < fighters[k].flashUntil;  // drawn white this frame (a hit's flash)
      if (k === 0) S.pa = [P[3 * pel], P[3 * pel + 2]];
      else S.pb = [P[3 * pel], P[3 * pel + 2]];
      drawn[k] = P;
    }
    followCamera();
  }
  const t0 = performance.now();
  renderer.render(scene, camera);
  S.renderMs = 0.9 * (S.renderMs || 0) + 0.1 * (performance.now() - t0);
  S.rendered += 1;
  if (drawn[0]) S.trunk = [trunkOnScreen(drawn[0]), trunkOnScreen(drawn[1])];
}

// Where each fighter's trunk is on the screen (CSS pixels: pelvis, belly, chest): the tests look there.
S.trunk = [[], []];
function trunkOnScreen(P) {
  const d = S.hello.drawing;
  const v = new THREE.Vector3();
  const out = [];
  const p = d.pelvis;
  const n = d.neck >= 0 ? d.neck : d.head;
  for (const f of [0.3, 0.5, 0.7]) {
    v.set(P[3 * p] + f * (P[3 * n] - P[3 * p]), P[3 * p + 1] + f * (P[3 * n + 1] - P[3 * p + 1]),
      P[3 * p + 2] + f * (P[3 * n + 2] - P[3 * p + 2]));
    v.project(camera);
    out.push([(v.x + 1) / 2 * window.innerWidth, (1 - v.y) / 2 * window.innerHeight]);
  }
  return out;
}

function followCamera() {
  const [ax, az] = S.pa;
  const [bx, bz] = S.pb;
  const mx = (ax + bx) / 2;
  const mz = (az + bz) / 2;
  let dx = bx - ax;
  let dz = bz - az;
  const r = Math.hypot(dx, dz) || 1;
  dx /= r; dz /= r;
  let nx = -dz;
  let nz = dx;
  if (nx * (camera.position.x - mx) + nz * (camera.position.z - mz) < 0) { nx = -nx; nz = -nz; }
  const back = 2.6 + 0.7 * r;
  const goal = new THREE.Vector3(mx + nx * back, 2.2, mz + nz * back);
  camera.position.lerp(goal, 0.06);
  camTarget.lerp(new THREE.Vector3(mx, 0.95, mz), 0.15);
  camera.lookAt(camTarget);
}
requestAnimationFrame(render);
