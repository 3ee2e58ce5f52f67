// The page `gaia sim serve` serves at /: drive a session with the keyboard and watch the world model answer.
#include "gaia/sim/server.h"

namespace gaia::sim {

const std::string& driving_page() {
  static const std::string page = R"HTML(<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>gaia sim</title>
<style>
 body { font: 14px system-ui, sans-serif; margin: 16px; background: #111; color: #ddd; }
 #frame { width: 768px; height: 432px; image-rendering: pixelated; background: #222; display: block; }
 .row { display: flex; gap: 16px; align-items: flex-start; }
 .panel { background: #1b1b1b; padding: 10px; border-radius: 6px; }
 canvas { background: #181818; display: block; margin-top: 6px; }
 kbd { background: #333; padding: 1px 5px; border-radius: 3px; }
 input { width: 260px; }
 .err { color: #f77; }
</style></head>
<body>
<h2>gaia sim: drive inside the world model</h2>
<div class="row">
 <div><img id="frame" alt="the world model's frame"></div>
 <div class="panel">
  <div><kbd>&larr;</kbd> <kbd>&rarr;</kbd> steer (hold; <kbd>Shift</kbd> harder), <kbd>&uarr;</kbd> speed up,
   <kbd>&darr;</kbd> brake, <kbd>Space</kbd> pause, <kbd>R</kbd> restart</div>
  <p>text prompt <input id="text" placeholder="e.g. night, heavy rain"> <button id="apply">apply</button></p>
  <p>prompt episode <input id="episode" placeholder="none: start from nothing" style="width:150px"></p>
  <p id="stats">starting&hellip;</p>
  <div>curvature (1/km, + = left): commanded, read back dashed</div><canvas id="curv" width="360" height="110"></canvas>
  <div>speed (m/s): commanded, read back dashed</div><canvas id="speed" width="360" height="110"></canvas>
  <p id="error" class="err"></p>
 </div>
</div>
<script>
const state = { session: null, speed: 8, steer: 0, running: true, text: null, curv: [], spd: [], rcurv: [], rspd: [],
                times: [], step: 0 };
const keys = {};
// ?text=...&episode=...: the prompt; ?guidance=S: action guidance (default the weights'); ?hold=ArrowLeft,Shift: keys
// held from the start; ?frames=N: stop after N frames (a scripted drive: what the tests run in a headless browser).
const params = new URLSearchParams(location.search);
for (const k of (params.get('hold') || '').split(',')) if (k) keys[k] = true;
const limit = Number(params.get('frames') || 0);
if (params.get('text')) document.getElementById('text').value = params.get('text');
if (params.get('episode')) document.getElementById('episode').value = params.get('episode');
let frames = 0;
async function api(op, body) {
  const r = await fetch('/api/' + op, { method: 'POST', body: JSON.stringify(body || {}) });
  const j = await r.json();
  if (r.status !== 200) throw new Error(j.error || ('HTTP ' + r.status));
  return j;
}
// Commanded (solid) and read back from the frames (dashed, null where the probe has not read yet).
function plot(id, commanded, read, lo, hi, color) {
  const c = document.getElementById(id), g = c.getContext('2d');
  g.clearRect(0, 0, c.width, c.height);
  g.strokeStyle = '#444'; g.setLineDash([]); g.beginPath();
  const y0 = c.height * hi / (hi - lo); g.moveTo(0, y0); g.lineTo(c.width, y0); g.stroke();
  [[commanded, []], [read, [4, 3]]].forEach(([values, dash]) => {
    g.strokeStyle = color; g.setLineDash(dash); g.beginPath();
    let on = false;
    values.forEach((v, i) => {
      if (v === null) { on = false; return; }
      const x = c.width * i / 119, y = c.height * (hi - Math.max(lo, Math.min(hi, v))) / (hi - lo);
      on ? g.lineTo(x, y) : g.moveTo(x, y); on = true;
    });
    g.stroke();
  });
}
let stream = null, sent = null;
async function start() {
  document.getElementById('error').textContent = '';
  if (stream) { stream.close(); stream = null; }
  if (state.session !== null) { try { await api('close', { session: state.session }); } catch (e) {} }
  const req = {};
  if (params.get('guidance')) req.guidance = Number(params.get('guidance'));
  const text = document.getElementById('text').value.trim();
  if (text) req.text = text;
  const ep = document.getElementById('episode').value.trim();
  if (ep) req.prompt = { episode: /^[0-9]+$/.test(ep) ? Number(ep) : ep };
  const j = await api('create', req);
  state.session = j.session; state.step = j.steps; state.curv = []; state.spd = []; state.rcurv = []; state.rspd = [];
  state.times = []; sent = null;
  await steer();
  open();
}
function command() {
  const hard = keys.Shift ? 3 : 1;
  state.steer = keys.ArrowLeft ? 0.01 * hard : keys.ArrowRight ? -0.01 * hard : 0;
  if (keys.ArrowUp) state.speed = Math.min(30, state.speed + 0.5);
  if (keys.ArrowDown) state.speed = Math.max(0, state.speed - 1);
  return { speed: state.speed, curvature: state.steer };
}
// The session's standing command, sent when it changes (or a new text is to apply): the stream steps with it.
async function steer() {
  const a = command();
  if (state.text === null && sent && sent.speed === a.speed && sent.curvature === a.curvature) return;
  const req = { session: state.session, speed: a.speed, curvature: a.curvature };
  if (state.text !== null) { req.text = state.text; state.text = null; }
  sent = a;
  await api('command', req);
}
// Frames arrive as server-sent events (GET /api/stream), one per step of the standing command.
function open() {
  if (stream || state.session === null || !state.running || (limit && frames >= limit)) return;
  const left = limit ? '&frames=' + (limit - frames) : '';
  stream = new EventSource('/api/stream?session=' + state.session + '&frame=1&tokens=0' + left);
  stream.onmessage = ev => {
    const j = JSON.parse(ev.data), a = j.command;
    document.getElementById('frame').src = j.frame;
    state.step = j.step;
    ++frames;
    state.curv.push(1000 * a.curvature); state.spd.push(a.speed); state.times.push(performance.now());
    const rb = j.read_back;
    state.rcurv.push(rb ? 1000 * rb.curvature : null); state.rspd.push(rb ? rb.speed : null);
    for (const k of ['curv', 'spd', 'rcurv', 'rspd']) if (state[k].length > 120) state[k].shift();
    if (state.times.length > 20) state.times.shift();
    const n = state.times.length, fps = n > 1 ? 1000 * (n - 1) / (state.times[n - 1] - state.times[0]) : 0;
    document.getElementById('stats').textContent =
      `step ${j.step}  ${fps.toFixed(2)} frames/s  ${j.ms.toFixed(0)} ms a step  speed ${a.speed.toFixed(1)} m/s` +
      `  curvature ${(1000 * a.curvature).toFixed(0)} 1/km  text "${j.text}"` +
      (rb ? `  read back: ${rb.speed.toFixed(1)} m/s, ${(1000 * rb.curvature).toFixed(1)} 1/km` : '');
    plot('curv', state.curv, state.rcurv, -35, 35, '#6cf'); plot('speed', state.spd, state.rspd, 0, 30, '#fc6');
    if (limit && frames >= limit) { stream.close(); stream = null; document.body.dataset.done = frames; return; }
    steer().catch(e => { document.getElementById('error').textContent = e.message; });
  };
  stream.addEventListener('error', ev => {  // a step failed (an "error" event), or the connection dropped
    const message = ev.data ? JSON.parse(ev.data).error : 'the stream was interrupted';
    document.getElementById('error').textContent = message;
    if (stream) stream.close();
    stream = null;
    setTimeout(() => (/no session/.test(message) ? start() : Promise.resolve(open())).catch(() => {}), 1000);
  });
}
addEventListener('keydown', e => {
  if (e.target.tagName === 'INPUT') return;  // typing a prompt
  keys[e.key] = true;
  if (e.key === ' ') {
    state.running = !state.running;
    if (!state.running && stream) { stream.close(); stream = null; }
    open();
  }
  if (e.key === 'r' || e.key === 'R') start();
  if (e.key.startsWith('Arrow') || e.key === ' ') e.preventDefault();
});
addEventListener('keyup', e => { keys[e.key] = false; });
document.getElementById('apply').onclick = () => { state.text = document.getElementById('text').value; };
start().catch(e => { document.getElementById('error').textContent = e.message; });
</script></body></html>
)HTML";
  return page;
}

}  // namespace gaia::sim
