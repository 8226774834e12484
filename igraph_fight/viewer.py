"""A self-contained HTML page that plays two skeletons in a ring (no server, no downloads).

The page holds the joint positions as JSON and draws them on a <canvas> with a small perspective
camera written in plain JavaScript: drag to orbit, wheel to zoom, space to pause, a time slider,
hits flashed on the struck fighter and listed under the view.
"""
from __future__ import annotations

import json
import os

import numpy as np

from motion_graph.atomic import atomic_write_text

_TEMPLATE = r"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>__TITLE__</title>
<style>
 body{margin:0;background:#15171c;color:#ddd;font:14px system-ui,sans-serif}
 #wrap{display:flex;flex-direction:column;align-items:center;padding:8px}
 canvas{background:#20232b;border-radius:6px;cursor:grab}
 #bar{display:flex;gap:10px;align-items:center;width:960px;margin-top:6px}
 #t{flex:1} .a{color:#e4572e} .b{color:#3fa7d6} #log{width:960px;max-height:150px;overflow:auto;font-size:12px;color:#aaa}
 button{background:#333;color:#eee;border:1px solid #555;border-radius:4px;padding:3px 10px}
</style></head><body><div id="wrap">
<div><b>__TITLE__</b> &mdash; <span class="a">A: __NAME_A__</span> vs <span class="b">B: __NAME_B__</span>
 &nbsp; score <span id="score"></span></div>
<canvas id="c" width="960" height="540"></canvas>
<div id="bar"><button id="play">pause</button><input id="t" type="range" min="0" max="1" step="1" value="0">
<span id="clock"></span><label><input id="follow" type="checkbox" checked> follow</label></div>
<div id="log"></div></div>
<script>
const D = __DATA__;
const cv = document.getElementById('c'), g = cv.getContext('2d');
const slider = document.getElementById('t'); slider.max = D.n - 1;
let f = 0, playing = true, yaw = 0.6, pitch = 0.3, dist = 4.5, last = null, acc = 0;
const J = D.parents.length;
function P(k, i, j) { const a = D.pos[k]; const o = (i * J + j) * 3; return [a[o], a[o + 1], a[o + 2]]; }
function centre(i) {
  if (!document.getElementById('follow').checked) return [0, 1, 0];
  const a = P(0, i, D.pelvis), b = P(1, i, D.pelvis); return [(a[0] + b[0]) / 2, 1.0, (a[2] + b[2]) / 2];
}
function project(p, c) {
  let x = p[0] - c[0], y = p[1] - c[1], z = p[2] - c[2];
  const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
  let x1 = cy * x - sy * z, z1 = sy * x + cy * z;
  let y2 = cp * y - sp * z1, z2 = sp * y + cp * z1;
  const depth = dist - z2; if (depth < 0.1) return null;
  const s = 520 / depth; return [cv.width / 2 - x1 * s, cv.height * 0.55 - y2 * s, depth];
}
function line(a, b, col, w) { if (!a || !b) return; g.strokeStyle = col; g.lineWidth = w; g.beginPath(); g.moveTo(a[0], a[1]); g.lineTo(b[0], b[1]); g.stroke(); }
function draw() {
  const c = centre(f);
  g.clearRect(0, 0, cv.width, cv.height);
  // ring floor grid
  for (let k = -4; k <= 4; k++) {
    line(project([k, 0, -4], c), project([k, 0, 4], c), '#2f3440', 1);
    line(project([-4, 0, k], c), project([4, 0, k], c), '#2f3440', 1);
  }
  const hitNow = [0, 0];
  for (const h of D.hits) if (f >= h.frame && f < h.frame + D.fps * 0.25) hitNow[h.victim] = 1;
  for (let k = 0; k < 2; k++) {
    const col = k == 0 ? '#e4572e' : '#3fa7d6';
    for (let j = 1; j < J; j++) {
      const p = D.parents[j]; if (p < 0) continue;
      line(project(P(k, f, p), c), project(P(k, f, j), c), col, 3);
    }
    const hd = project(P(k, f, D.head), c);
    if (hd) { g.fillStyle = hitNow[k] ? '#ffe066' : col; g.beginPath(); g.arc(hd[0], hd[1], hitNow[k] ? 14 : 8, 0, 6.3); g.fill(); }
    const pel = project(P(k, f, D.pelvis), c), top = project([P(k, f, D.pelvis)[0], 2.05, P(k, f, D.pelvis)[2]], c);
    if (top) { g.fillStyle = col; g.fillText(k == 0 ? 'A' : 'B', top[0] - 4, top[1]); }
  }
  const t = f / D.fps; document.getElementById('clock').textContent = t.toFixed(2) + ' s / ' + ((D.n - 1) / D.fps).toFixed(1) + ' s';
  let ha = 0, hb = 0; for (const h of D.hits) if (h.frame <= f) { if (h.victim == 1) ha++; else hb++; }
  document.getElementById('score').textContent = 'hits A ' + ha + ' : ' + hb + ' B';
  let lab = ''; for (const s of D.labels) if (s.frame <= f) lab = s; 
  slider.value = f;
}
function tick(ts) {
  if (last === null) last = ts; const dt = (ts - last) / 1000; last = ts;
  if (playing) { acc += dt * D.fps; while (acc >= 1) { f = (f + 1) % D.n; acc -= 1; } }
  draw(); requestAnimationFrame(tick);
}
slider.oninput = () => { f = +slider.value; };
document.getElementById('play').onclick = () => { playing = !playing; document.getElementById('play').textContent = playing ? 'pause' : 'play'; };
document.addEventListener('keydown', e => { if (e.code == 'Space') { document.getElementById('play').click(); e.preventDefault(); } });
let drag = null;
cv.onmousedown = e => drag = [e.clientX, e.clientY, yaw, pitch];
window.onmouseup = () => drag = null;
window.onmousemove = e => { if (!drag) return; yaw = drag[2] + (e.clientX - drag[0]) * 0.01; pitch = Math.max(-0.2, Math.min(1.4, drag[3] + (e.clientY - drag[1]) * 0.01)); };
cv.onwheel = e => { dist = Math.max(2, Math.min(20, dist * (e.deltaY > 0 ? 1.1 : 0.9))); e.preventDefault(); };
const log = document.getElementById('log');
log.innerHTML = D.events.map(e => '<div>' + (e.frame / D.fps).toFixed(2) + ' s &nbsp; ' + e.text + '</div>').join('');
f = Math.min(D.start || 0, D.n - 1);
draw(); requestAnimationFrame(tick);
</script></body></html>
"""


def write_bout_html(path: str | os.PathLike, pos_a: np.ndarray, pos_b: np.ndarray, parents: np.ndarray,
                    fps: float, pelvis: int, head: int, hits: list[dict] | None = None,
                    events: list[dict] | None = None, title: str = "igraph-fight bout",
                    name_a: str = "A", name_b: str = "B", start_frame: int = 0) -> None:
    """Write the viewer page.

    Args:
        pos_a, pos_b: (T, J, 3) joint positions in metres (Y up) of the two fighters.
        parents: (J,) parent index per joint (-1 root).
        hits: [{"frame": f, "victim": 0|1}] flashed on the struck fighter's head.
        events: [{"frame": f, "text": "..."}] listed under the view.
    """
    T = min(len(pos_a), len(pos_b))
    data = {
        "n": int(T), "fps": float(fps), "parents": [int(p) for p in parents], "pelvis": int(pelvis), "head": int(head),
        "pos": [np.round(pos_a[:T], 3).reshape(-1).tolist(), np.round(pos_b[:T], 3).reshape(-1).tolist()],
        "hits": hits or [], "events": events or [], "labels": [], "start": int(start_frame),
    }
    html = (_TEMPLATE.replace("__DATA__", json.dumps(data, separators=(",", ":")))
            .replace("__TITLE__", title).replace("__NAME_A__", name_a).replace("__NAME_B__", name_b))
    atomic_write_text(path, html)
