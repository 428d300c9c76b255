// raysweep viewer: scenes and their parameters, renders, jobs and films,
// over the public API only (api.js).
import { api, ApiError, followEvents, getToken, setToken } from './api.js';
import {
  autoWhite, displayModel, drawColorbar, drawFilm, filmPlanes, fmt, fmtDuration, PlanePlot, PolarPlot, stokesViews,
} from './plot.js';
import { drawSweep, filmValue, resultCoords } from './sweep.js';

const $ = (id) => document.getElementById(id);
const el = (tag, attrs = {}, ...kids) => {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'class') e.className = v;
    else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else if (k === 'dataset') Object.assign(e.dataset, v);
    else e.setAttribute(k, v);
  }
  for (const k of kids) if (k !== null && k !== undefined) e.append(k);
  return e;
};
const short = (id) => (id && id.length > 16 ? id.slice(0, 12) + '…' : id);
// A job's id as people tell jobs apart: raysweepd's ids are
// job-<instance>-<number>, the same instance for every job of a daemon, so
// the number is the distinguishing part ("#12"); another form is shown whole.
const jobLabel = (id) => {
  const m = /^job-[0-9a-f]{8}-0*(\d+)$/.exec(id || '');
  return m ? `#${m[1]}` : id;
};
// A scene as people name it: the name it was pushed under when the daemon
// records one (`name`), else the start of its id.
const sceneLabel = (id) => {
  const s = state.scenes.find((x) => x.id === id);
  return (s && s.name) || (id ? id.slice(0, 8) + '…' : '');
};

const state = {
  scenes: [],
  scene: null, // SceneInfo of the selected scene
  opening: 0, // the number of the latest selectScene: only its answers are shown
  params: [], // its ParamEntry list
  revision: 0,
  sensorTypes: new Map(), // scene id → Map(sensor id → plugin type)
  film: null,
  filmTitle: '',
  plot: null,
  jobs: new Map(), // id → Job
  following: new Map(), // id → AbortController
  events: new Map(), // id → events received
  selectedJob: null,
  sweep: null, // {job, results, films: Map(href → film | Promise)}
};

// ---- messages ------------------------------------------------------------------
function banner(text, kind = 'error') {
  const b = $('banner');
  b.textContent = text;
  b.className = kind === 'info' ? 'info' : '';
  b.hidden = !text;
}

function report(e, what) {
  if (e instanceof ApiError && e.status === 401) {
    document.body.dataset.auth = 'required';
    banner(getToken()
      ? 'The server refused the token (401): enter the right one above.'
      : 'This server requires a bearer token: enter it above (raysweepd serve --token-file).');
    return;
  }
  banner(`${what}: ${e.message}${e.code ? ` (${e.code})` : ''}`);
}

// ---- server, scenes --------------------------------------------------------------
async function loadServer() {
  try {
    const { data } = await api('GET', '/v1');
    $('server').textContent = `${data.name} ${data.version} · API ${data.api_version}`;
    document.body.dataset.auth = 'ok';
    return true;
  } catch (e) {
    $('server').textContent = 'not connected';
    report(e, 'GET /v1');
    return false;
  }
}

async function loadScenes() {
  try {
    const { data } = await api('GET', '/v1/scenes');
    state.scenes = data.scenes;
  } catch (e) {
    state.scenes = [];
    report(e, 'listing scenes');
  }
  const ul = $('scenes');
  ul.replaceChildren();
  for (const s of state.scenes) {
    ul.append(el('li', {
      class: state.scene && state.scene.id === s.id ? 'selected' : '',
      dataset: { scene: s.id },
      title: s.id,
      onclick: () => selectScene(s.id),
    }, el('div', { class: 'id' }, s.name ? el('span', { class: 'label' }, s.name) : short(s.id)),
    el('div', { class: 'meta' }, `${s.variant} · ${s.sensors.join(', ')} · rev ${s.revision} · ${s.params} params`)));
  }
  if (!state.scenes.length) ul.append(el('li', { class: 'muted' }, 'no scene resident'));
  if (!state.scene && state.scenes.length) await selectScene(state.scenes[0].id);
}

function typesFrom(params) {
  const m = new Map();
  for (const p of params) if (p.object_class === 'sensor' && p.object_id) m.set(p.object_id, p.object_type);
  return m;
}

// Opening a scene takes two requests. Each opening has a number, and only
// the latest one is shown: a click on a scene while the page still opens the
// first one by itself (or while an edit reloads the table) wins, whichever
// answers arrive last.
async function selectScene(id) {
  const opening = ++state.opening;
  let info, table;
  try {
    ({ data: info } = await api('GET', `/v1/scenes/${encodeURIComponent(id)}`));
    table = await fetchParams(id);
  } catch (e) {
    if (opening === state.opening) report(e, 'opening the scene');
    return;
  }
  if (opening !== state.opening) return;
  state.scene = info;
  showParams(table);
  for (const li of $('scenes').children) li.classList.toggle('selected', li.dataset.scene === id);
  const sel = $('r-sensor');
  const types = state.sensorTypes.get(id) || new Map();
  const opts = () => state.scene.sensors.map((s) => el('option', { value: s }, types.has(s) ? `${s} (${types.get(s)})` : s));
  sel.replaceChildren(...opts());
  $('j-sensors').replaceChildren(...opts());
  if ($('j-sensors').options.length) $('j-sensors').options[0].selected = true;
  $('r-wl-label').hidden = state.scene.variant !== 'mono';
}

async function fetchParams(id) {
  const { data } = await api('GET', `/v1/scenes/${encodeURIComponent(id)}/params`);
  return data;
}

function showParams(data, flashKey) {
  const id = state.scene.id;
  state.params = data.params;
  state.revision = data.revision;
  state.sensorTypes.set(id, typesFrom(data.params));
  $('params').dataset.revision = data.revision;
  $('scene-title').textContent = `${sceneLabel(id)} · ${state.scene.variant} · revision ${data.revision}`;
  renderParams(flashKey);
}

// Reload the open scene's table (after an edit); dropped if another scene
// was opened meanwhile.
async function loadParams(flashKey) {
  const opening = state.opening;
  const data = await fetchParams(state.scene.id);
  if (opening === state.opening) showParams(data, flashKey);
}

// ---- the parameter table -----------------------------------------------------------
function valueText(v) {
  const s = JSON.stringify(v);
  return s.length > 160 ? s.slice(0, 157) + '…' : s;
}

function renderParams(flashKey) {
  const words = $('param-search').value.toLowerCase().split(/\s+/).filter(Boolean);
  const cls = $('param-class').value;
  const tbody = $('params').tBodies[0];
  tbody.replaceChildren();
  let shown = 0;
  for (const p of state.params) {
    const hay = `${p.key} ${p.type} ${p.class} ${p.object_type} ${p.object_class} ${p.object_id} ${p.aliases.join(' ')}`.toLowerCase();
    if (cls && p.class !== cls) continue;
    if (!words.every((w) => hay.includes(w))) continue;
    shown++;
    const readonly = p.type === 'buffer' && p.value && typeof p.value === 'object' && 'length' in p.value && !Array.isArray(p.value);
    const td = el('td', { class: 'value' + (readonly ? ' readonly' : ''), title: readonly ? 'a long buffer: edit it with PATCH from a client' : 'click to edit' }, valueText(p.value));
    if (!readonly) td.addEventListener('click', () => editParam(td, p));
    const tr = el('tr', { dataset: { key: p.key }, class: p.key === flashKey ? 'changed' : '' },
      el('td', { class: 'key', title: p.aliases.length ? 'aliases: ' + p.aliases.join(', ') : '' }, p.key),
      el('td', {}, p.type + (p.shape && p.shape.length ? ` [${p.shape.join('×')}]` : '')),
      el('td', {}, p.class),
      el('td', {}, `${p.object_class} ${p.object_type}${p.object_id ? ' “' + p.object_id + '”' : ''}`),
      td);
    tbody.append(tr);
  }
  $('param-count').textContent = `${shown} of ${state.params.length}`;
}

function editParam(td, p) {
  if (td.querySelector('input')) return;
  const input = el('input', { type: 'text', spellcheck: 'false', 'aria-label': `new value of ${p.key}` });
  input.value = JSON.stringify(p.value);
  td.replaceChildren(input);
  input.focus();
  input.select();
  let done = false;
  const cancel = () => {
    if (done) return;
    done = true;
    td.textContent = valueText(p.value);
  };
  input.addEventListener('blur', cancel);
  input.addEventListener('keydown', async (ev) => {
    if (ev.key === 'Escape') cancel();
    if (ev.key !== 'Enter') return;
    ev.preventDefault();
    let value;
    try {
      value = JSON.parse(input.value);
    } catch (e) {
      banner(`${p.key}: the value is not JSON (${e.message}); e.g. 0.3, [0.1, 0.2, 0.3]`);
      return;
    }
    done = true;
    input.disabled = true;
    try {
      const { data } = await api('PATCH', `/v1/scenes/${encodeURIComponent(state.scene.id)}/params`, {
        body: { [p.key]: value },
        headers: { 'If-Match': `"${state.revision}"` },
      });
      banner(`${p.key} set: revision ${data.revision}, ${data.changed} changed (${data.classes.join(', ') || 'no class'}) in ${fmtDuration(data.seconds)}`, 'info');
    } catch (e) {
      if (e.status === 412) banner(`${p.key}: the scene changed meanwhile (another client): the table is reloaded, try again`);
      else report(e, `setting ${p.key}`);
    }
    try {
      await loadParams(p.key);
      await loadScenes(); // their revisions
    } catch (e) {
      report(e, 'reloading the parameters');
    }
  });
}

// ---- renders -----------------------------------------------------------------------------
async function render(ev) {
  ev.preventDefault();
  if (!state.scene) return;
  const body = { sensor: $('r-sensor').value, seed: Number($('r-seed').value || 0) };
  if ($('r-spp').value) body.spp = Number($('r-spp').value);
  if (state.scene.variant === 'mono' && $('r-wl').value) body.wavelength = Number($('r-wl').value);
  const btn = $('render');
  btn.disabled = true;
  $('render-status').textContent = 'rendering…';
  const t0 = performance.now();
  try {
    const { data } = await api('POST', `/v1/scenes/${encodeURIComponent(state.scene.id)}:render`, { body });
    const s = fmtDuration((performance.now() - t0) / 1000);
    $('render-status').textContent = `${data.width}×${data.height}, ${data.meta.spp} spp, seed ${data.meta.seed}: ${s}`;
    await showFilm(data, `render of ${data.meta.sensor} · revision ${data.meta.revision}`);
  } catch (e) {
    $('render-status').textContent = '';
    report(e, 'render');
  } finally {
    btn.disabled = false;
  }
}

// ---- films ----------------------------------------------------------------------------------
async function sensorType(film) {
  const scene = film.meta.scene;
  if (!state.sensorTypes.has(scene)) {
    try {
      const { data } = await api('GET', `/v1/scenes/${encodeURIComponent(scene)}/params`);
      state.sensorTypes.set(scene, typesFrom(data.params));
    } catch (e) {
      state.sensorTypes.set(scene, new Map());
    }
  }
  const t = state.sensorTypes.get(scene).get(film.meta.sensor);
  if (t) return t;
  if (!film.meta.zenith_deg) return '';
  return film.height === 1 ? 'mdistant' : 'hdistant'; // a scene since unloaded: guess from the shape
}

const PLANE_LABELS = {
  radiance: 'radiance', brf: 'BRF', brdf: 'BRDF (sr⁻¹)', radiance_stderr: 'radiance stderr', 'brf*': 'BRF = π L / E_h',
};
// Stokes films' derived views (docs/polarization.md).
const VIEW_LABELS = { dolp: 'DoLP', aolp: 'AoLP (°)' };
const DISTANT = new Set(['hdistant', 'mdistant', 'distant', 'distantflux', 'multi_distant']);

async function showFilm(film, title) {
  delete $('film-title').dataset.job;
  state.film = film;
  state.filmType = await sensorType(film);
  state.filmTitle = title;
  const m = film.meta;
  const bits = [title, m.wavelength ? `${m.wavelength} nm` : m.variant, state.filmType].filter(Boolean);
  $('film-title').textContent = bits.join(' · ');
  // The planes this film has (radiance, brf, radiance_stderr, ...), and a
  // BRF computed from the scene's sun where the film has no brf plane
  // (distant-family sensors: the BRF toggle). Every new film starts from
  // its radiance and default channel: no choice is carried over from the
  // film shown before, whose planes and channels may differ.
  state.planes = filmPlanes(film);
  const eh = DISTANT.has(state.filmType) && !state.planes.some((p) => p.name === 'brf') ? horizontalIrradiance(film) : null;
  if (eh) state.planes.push({ name: 'brf*', idx: state.planes[0].idx, names: state.planes[0].names, stokes: state.planes[0].stokes, scale: eh.map((e) => Math.PI / e) });
  $('plane').replaceChildren(...state.planes.map((p) => el('option', { value: p.name }, PLANE_LABELS[p.name] || p.name)));
  $('plane').value = 'radiance';
  $('plane-label').hidden = state.planes.length < 2;
  fillChannels();
  $('film-empty').hidden = true;
  document.querySelector('.film-row').hidden = false;
  $('hover').textContent = 'move the pointer over the film or the plot for its values';
  $('exposure').value = 0;
  redraw();
}

function currentPlane() {
  return state.planes.find((p) => p.name === $('plane').value) || state.planes[0];
}

function fillChannels() {
  const p = currentPlane();
  const opts = p.stokes ? stokesViews(p) : p.idx.length === 3
    ? [['rgb', 'RGB'], ['lum', 'luminance'], ['0', p.names[0]], ['1', p.names[1]], ['2', p.names[2]]]
    : p.names.map((c, i) => [String(i), c]);
  $('channel').replaceChildren(...opts.map(([v, t]) => el('option', { value: v }, t)));
  $('channel').value = opts[0][0];
  $('channel-label').hidden = opts.length < 2;
}

// Horizontal irradiance E_h of the scene's directional emitters, per
// channel of the film: E_h = Σ E_i cos θ_i over every directional
// emitter (Eradiate's BRF = π L / E_h), from the scene's base parameters.
// null when it cannot be had (no directional emitter, or a value the
// viewer cannot evaluate).
function horizontalIrradiance(film) {
  if (!state.scene || state.scene.id !== film.meta.scene) return null;
  const by = new Map();
  for (const p of state.params) {
    if (p.object_class === 'emitter' && p.object_type === 'directional' && p.key.endsWith('.direction')) {
      by.set(p.key.slice(0, -'.direction'.length), { dir: p.value });
    }
  }
  const c = filmPlanes(film)[0].idx.length, eh = new Array(c).fill(0);
  for (const [pre, e] of by) {
    const irr = state.params.find((p) => p.key === `${pre}.irradiance.value` || p.key === `${pre}.irradiance`);
    if (!irr) return null;
    const d = e.dir, n = Math.hypot(d[0], d[1], d[2]);
    const cos = n > 0 ? Math.max(0, -d[2] / n) : 0;
    let v = irr.value;
    if (typeof v === 'number') v = new Array(c).fill(v);
    else if (Array.isArray(v) && v.length === 3 && c === 3) v = v.slice();
    else if (Array.isArray(v) && v.length === 3 && c === 1) v = [0.212671 * v[0] + 0.71516 * v[1] + 0.072169 * v[2]];
    else return null;
    for (let i = 0; i < c; i++) eh[i] += v[i] * cos;
  }
  return by.size && eh.every((x) => x > 0) ? eh : null;
}

// The exposure is Mitsuba's: linear values times 2^EV, clamped to [0, 1]
// (sRGB for an RGB film, viridis for one channel); `auto` sets EV so that
// the film's 99.5th percentile is full scale.
function redraw() {
  const film = state.film;
  if (!film) return;
  const plane = currentPlane();
  const mode = $('channel').value;
  const ev = Number($('exposure').value);
  $('exposure-out').textContent = `${ev > 0 ? '+' : ''}${Number(ev.toFixed(2))} EV`;
  const white = Math.pow(2, -ev);
  const model = displayModel(film, plane.idx, mode, white, plane.scale, plane);
  state.model = model;
  drawFilm($('film'), film, model, 320);
  const f = $('film');
  f.dataset.ready = '1';
  f.dataset.plane = plane.name;
  f.dataset.mode = model.kind; /* rgb, false-colour; Stokes: signed, dolp, aolp */
  f.dataset.white = white;
  const unit = VIEW_LABELS[model.kind] || PLANE_LABELS[plane.name] || plane.name;
  drawColorbar($('colorbar'), model, unit);
  $('colorbar-unit').textContent = model.rgb ? `${unit} (sRGB, clipped)` : unit;
  const fig = $('plot-fig');
  state.plot = null;
  const type = state.filmType;
  const m = film.meta;
  if (m.zenith_deg && (type === 'hdistant' || type === 'distantflux') && film.height > 1) {
    state.plot = new PolarPlot($('plot'), film, model);
    state.plot.draw();
    $('plot-caption').textContent = `${type}, ${unit}: zenith θ as radius (0° centre, 90° rim), azimuth φ east-right (0° = +x, counter-clockwise)`;
    fig.hidden = false;
  } else if (m.zenith_deg && type === 'mdistant') {
    const colors = plane.idx.length === 3 ? ['#d62728', '#2ca02c', '#1f77b4'] : ['#26828e'];
    const n = film.width * film.height, c = film.channels.length;
    const sc = plane.scale || plane.idx.map(() => 1);
    const series = plane.idx.map((ci, i) => ({
      name: plane.names[i], color: colors[i], values: Array.from({ length: n }, (_, k) => film.data[k * c + ci] * sc[i]),
    }));
    state.plot = new PlanePlot($('plot'), film, series, unit);
    state.plot.draw();
    $('plot-caption').textContent = state.plot.inPlane
      ? `mdistant principal plane: ${unit} against viewing zenith`
      : `mdistant: ${unit} against viewing zenith (the directions are not all in one plane)`;
    fig.hidden = false;
  } else {
    fig.hidden = true;
  }
}

function describePixel(k, where) {
  const film = state.film, c = film.channels.length, m = film.meta;
  const ix = k % film.width, iy = Math.floor(k / film.width);
  const vals = film.channels.map((name, i) => `${name} ${fmt(film.data[k * c + i])}`).join('  ');
  const ang = m.zenith_deg ? `  θ ${fmt(m.zenith_deg[k])}°  φ ${fmt(m.azimuth_deg[k])}°` : '';
  const plane = currentPlane();
  const label = VIEW_LABELS[state.model && state.model.kind] || PLANE_LABELS[plane.name] || plane.name;
  const shown = state.model ? `  ${label}: ${fmt(state.model.values[k])}` : '';
  $('hover').textContent = `${where} pixel (${ix}, ${iy})  ${vals}${ang}${shown}`;
}

function hoverFilm(ev) {
  const film = state.film;
  if (!film) return;
  const r = ev.target.getBoundingClientRect();
  const ix = Math.floor(((ev.clientX - r.left) / r.width) * film.width);
  const iy = Math.floor(((ev.clientY - r.top) / r.height) * film.height);
  if (ix < 0 || iy < 0 || ix >= film.width || iy >= film.height) return;
  describePixel(iy * film.width + ix, 'film');
}

function hoverPlot(ev) {
  if (!state.plot) return;
  const r = ev.target.getBoundingClientRect();
  const k = state.plot.pick(ev.clientX - r.left, ev.clientY - r.top);
  if (k >= 0) describePixel(k, 'plot:');
}

// ---- jobs -------------------------------------------------------------------------------------------
async function loadJobs() {
  let jobs;
  try {
    ({ data: { jobs } } = await api('GET', '/v1/jobs'));
  } catch (e) {
    report(e, 'listing jobs');
    return;
  }
  const seen = new Set();
  for (const j of jobs) {
    seen.add(j.id);
    state.jobs.set(j.id, j);
    if ((j.state === 'queued' || j.state === 'running') && !state.following.has(j.id)) follow(j.id);
  }
  for (const id of [...state.jobs.keys()]) if (!seen.has(id)) state.jobs.delete(id);
  renderJobs();
}

function follow(id) {
  const ctl = new AbortController();
  state.following.set(id, ctl);
  state.events.set(id, state.events.get(id) || 0);
  followEvents(`/v1/jobs/${encodeURIComponent(id)}/events`, (ev) => {
    const j = state.jobs.get(id);
    if (!j) return;
    if (ev.event === 'context') {
      state.events.set(id, state.events.get(id) + 1);
      j.state = 'running';
      j.renders_done = Math.max(j.renders_done, ev.data.done);
      j.renders_total = ev.data.total;
      if (ev.data.state === 'failed') j.renders_failed = (j.renders_failed || 0) + 1;
    } else if (ev.event === 'end') {
      j.state = ev.data.state;
    }
    renderJobs();
  }, ctl.signal).catch((e) => report(e, `events of ${id}`)).finally(async () => {
    state.following.delete(id);
    try {
      const { data } = await api('GET', `/v1/jobs/${encodeURIComponent(id)}`);
      state.jobs.set(id, data);
      renderJobs();
      if (state.selectedJob === id) showResults(id);
    } catch (e) {
      /* deleted meanwhile */
    }
  });
}

async function cancelJob(id, ev) {
  ev.stopPropagation();
  try {
    const { data } = await api('POST', `/v1/jobs/${encodeURIComponent(id)}:cancel`);
    state.jobs.set(id, Object.assign(state.jobs.get(id) || {}, data));
    renderJobs();
  } catch (e) {
    report(e, `cancelling ${id}`);
  }
}

// A job's progress in renders, counting the render under way by its
// samples (the job's `render`: samples traced of width × height × spp), so
// a job of long renders moves during its first one.
function jobProgress(j) {
  if (!j.renders_total) return 0;
  let done = j.renders_done;
  const r = j.render;
  if ((j.state === 'running') && r && r.samples_total > 0) done += Math.min(1, r.samples_done / r.samples_total);
  return Math.min(1, done / j.renders_total);
}

function renderJobs() {
  const ul = $('jobs');
  ul.replaceChildren();
  const jobs = [...state.jobs.values()].sort((a, b) => (a.created < b.created ? 1 : a.created > b.created ? -1 : 0));
  for (const j of jobs) {
    const live = j.state === 'queued' || j.state === 'running';
    const frac = jobProgress(j);
    const bar = el('div', { class: 'progress' }, el('div'));
    bar.firstChild.style.width = (100 * frac).toFixed(1) + '%';
    const r = j.state === 'running' && j.render && j.render.samples_total > 0 ? j.render : null;
    const within = r ? ` · ${r.context}: ${Math.floor((100 * r.samples_done) / r.samples_total)}% of ${r.samples_total.toLocaleString('en')} samples` : '';
    ul.append(el('li', {
      class: state.selectedJob === j.id ? 'selected' : '',
      dataset: {
        job: j.id, state: j.state, done: j.renders_done, total: j.renders_total, events: state.events.get(j.id) || 0,
        progress: frac.toFixed(4),
      },
      onclick: () => showResults(j.id),
    },
    el('div', { class: 'job-row' },
      el('span', { class: 'id grow', title: j.id }, el('span', { class: 'label' }, jobLabel(j.id)), ` · ${sceneLabel(j.scene)}`),
      el('span', { class: `state-${j.state}` }, j.state),
      live ? el('button', { type: 'button', class: 'small danger', title: 'POST :cancel', onclick: (ev) => cancelJob(j.id, ev) }, 'cancel') : null),
    bar,
    el('div', { class: 'meta' }, `${j.renders_done}/${j.renders_total} renders` +
      (j.renders_failed ? `, ${j.renders_failed} failed` : '') + within +
      (j.seconds !== undefined ? ` · ${fmtDuration(j.seconds)}` : '') + (j.error ? ` · ${j.error}` : '')),
    // A sweep that changes nothing along a coordinate (docs/experiments.md "Templates").
    ...(j.warnings || []).map((w) => el('div', { class: 'meta warning', title: w.detail }, `warning: ${w.code} (${w.coordinate})`))));
  }
  if (!jobs.length) ul.append(el('li', { class: 'muted' }, 'no job'));
}

async function showResults(id) {
  state.selectedJob = id;
  renderJobs();
  const box = $('results');
  try {
    const { data } = await api('GET', `/v1/jobs/${encodeURIComponent(id)}/results`);
    const ok = data.results.filter((r) => r.state === 'succeeded');
    setupSweep(id, data.results);
    box.dataset.job = id;
    box.replaceChildren(el('div', { class: 'muted' }, `${ok.length} film(s) of ${data.results.length}; click one to show it`),
      ...data.results.map((r) => el('div', { dataset: { context: r.context, sensor: r.sensor } },
        r.state === 'succeeded'
          ? el('a', { onclick: () => showResult(id, r) }, `${r.context} / ${r.sensor}`)
          : el('span', { class: `state-${r.state}` }, `${r.context} / ${r.sensor}: ${r.state}${r.error ? ' — ' + r.error : ''}`),
        el('span', { class: 'muted' }, r.wavelength ? `  ${r.wavelength} nm` : ''))));
  } catch (e) {
    box.replaceChildren();
    report(e, `results of ${id}`);
  }
}

async function showResult(id, r) {
  try {
    const { data } = await api('GET', `/v1/jobs/${encodeURIComponent(id)}/results/${encodeURIComponent(r.context)}/${encodeURIComponent(r.sensor)}`);
    await showFilm(data, `job ${jobLabel(id)} · ${r.context}`);
    $('film-title').dataset.job = id;
  } catch (e) {
    report(e, `film ${r.context}/${r.sensor}`);
  }
}

// ---- the sweep view --------------------------------------------------------------------------------------
// A job's results against its coordinates: setupSweep fills the controls
// from the results index (sensors, coordinates, the planes of the films),
// drawSweepView fetches the films it needs (each once) and plots them.
const SWEEP_Q = { radiance: 'radiance', brf: 'BRF', brdf: 'BRDF (sr⁻¹)' };

function option(v, t) {
  return el('option', { value: v }, t);
}

function setupSweep(id, results) {
  const panel = $('sweep-panel');
  const ok = results.filter((r) => r.state === 'succeeded' && r.href);
  const keepFilms = state.sweep && state.sweep.job === id ? state.sweep.films : new Map();
  state.sweep = { job: id, results, films: keepFilms };
  if (!ok.length) {
    panel.hidden = true;
    return;
  }
  panel.hidden = false;
  $('sweep-title').textContent = `job ${jobLabel(id)} · ${ok.length} film(s)`;
  // A choice the user made on this job's sweep stays when the results are
  // reloaded (more films done); the defaults are chosen again otherwise,
  // from the results there are now.
  const keep = (sel, opts, dflt) => {
    if (sel.dataset.job !== id) delete sel.dataset.user;
    const old = sel.dataset.user ? sel.value : null;
    sel.replaceChildren(...opts.map(([v, t]) => option(v, t)));
    sel.value = opts.some(([v]) => v === old) ? old : dflt !== undefined ? dflt : opts.length ? opts[0][0] : '';
    sel.dataset.job = id;
  };
  const sensors = [...new Set(ok.map((r) => r.sensor))];
  keep($('sw-sensor'), sensors.map((x) => [x, x]));
  const first = ok.find((r) => r.sensor === $('sw-sensor').value);
  const planes = filmPlanes({ channels: first.channels });
  keep($('sw-quantity'), planes.filter((p) => SWEEP_Q[p.name]).map((p) => [p.name, SWEEP_Q[p.name]]),
    planes.some((p) => p.name === 'brf') ? 'brf' : 'radiance');
  const names = planes[0].names;
  keep($('sw-channel'), names.map((n, i) => [String(i), n]));
  $('sw-channel-label').hidden = names.length < 2;
  const px = [['-1', 'film mean']];
  if (first.width * first.height <= 64 && first.width * first.height > 1) {
    for (let k = 0; k < first.width * first.height; k++) px.push([String(k), `(${k % first.width}, ${Math.floor(k / first.width)})`]);
  }
  keep($('sw-pixel'), px);
  const { names: coords, of } = resultCoords(ok);
  const xs = coords.length ? coords.map((c) => [c, c]) : [['#', 'context (index)']];
  // Against the coordinate that varies most, by default.
  const distinct = (c) => new Set(ok.map((r) => of(r)[c])).size;
  const best = coords.slice().sort((a, b) => distinct(b) - distinct(a))[0];
  keep($('sw-x'), xs, best);
  const x = $('sw-x').value;
  keep($('sw-series'), [['', 'none'], ...coords.map((c) => [c, c])], coords.find((c) => c !== x && distinct(c) > 1) || '');
  for (const o of $('sw-series').options) o.disabled = o.value !== '' && o.value === x;
  if ($('sw-series').value === x) $('sw-series').value = '';
  sweepFixed();
  drawSweepView();
}

// The coordinates neither plotted nor a line of their own: each held at
// one of its values (a select per coordinate).
function sweepFixed() {
  const { results } = state.sweep;
  const ok = results.filter((r) => r.state === 'succeeded' && r.href);
  const { names, of } = resultCoords(ok);
  const box = $('sw-fixed');
  const old = new Map([...box.querySelectorAll('select')].map((e) => [e.dataset.coord, e.value]));
  box.replaceChildren();
  for (const c of names) {
    if (c === $('sw-x').value || c === $('sw-series').value) continue;
    const vals = [...new Set(ok.map((r) => of(r)[c]))].sort((a, b) => a - b);
    if (vals.length < 2) continue;
    const sel = el('select', { dataset: { coord: c }, onchange: drawSweepView }, ...vals.map((v) => option(String(v), fmt(v))));
    if (old.has(c) && vals.map(String).includes(old.get(c))) sel.value = old.get(c);
    box.append(el('label', {}, `${c} = `, sel));
  }
}

async function sweepFilm(r) {
  const films = state.sweep.films;
  if (!films.has(r.href)) {
    // A failed fetch is forgotten, so that the next draw tries again.
    films.set(r.href, api('GET', r.href).then(({ data }) => data, (e) => {
      films.delete(r.href);
      throw e;
    }));
  }
  return films.get(r.href);
}

async function drawSweepView() {
  const sw = state.sweep;
  if (!sw) return;
  const svg = $('sweep');
  svg.dataset.ready = '';
  const job = sw.job;
  const sensor = $('sw-sensor').value, quantity = $('sw-quantity').value;
  const ch = Number($('sw-channel').value || 0), pixel = Number($('sw-pixel').value);
  const xName = $('sw-x').value, sName = $('sw-series').value;
  const fixed = [...$('sw-fixed').querySelectorAll('select')].map((e) => [e.dataset.coord, Number(e.value)]);
  const ok = sw.results.filter((r) => r.state === 'succeeded' && r.href && r.sensor === sensor);
  const { of } = resultCoords(ok);
  const chosen = ok.filter((r) => fixed.every(([c, v]) => of(r)[c] === v));
  let films;
  try {
    // A few at a time: a sweep of hundreds of films should not open hundreds of requests.
    films = new Array(chosen.length);
    let next = 0;
    await Promise.all(Array.from({ length: Math.min(4, chosen.length) }, async () => {
      while (next < chosen.length) {
        const i = next++;
        films[i] = await sweepFilm(chosen[i]);
      }
    }));
  } catch (e) {
    report(e, 'fetching the films of the sweep');
    return;
  }
  if (!state.sweep || state.sweep.job !== job) return; // another job was clicked meanwhile
  const points = [];
  let bars = true;
  chosen.forEach((r, i) => {
    const v = filmValue(films[i], quantity, ch, pixel);
    if (!v) return;
    if (v.err === null) bars = false;
    const c = of(r);
    points.push({ x: xName === '#' ? sw.results.indexOf(r) : c[xName], y: v.value, err: v.err, series: sName ? c[sName] : '', context: r.context });
  });
  const yName = `${SWEEP_Q[quantity] || quantity}${$('sw-channel-label').hidden ? '' : ' ' + $('sw-channel').selectedOptions[0].textContent}`;
  drawSweep(svg, points.filter((p) => Number.isFinite(p.x)), { xName: xName === '#' ? 'context' : xName, yName, seriesName: sName });
  $('sweep-caption').textContent = `${yName} (${pixel < 0 ? 'film mean' : 'pixel ' + $('sw-pixel').selectedOptions[0].textContent}) against ${xName === '#' ? 'the context' : xName}` +
    (sName ? `, one line per ${sName}` : '') + (fixed.length ? `; ${fixed.map(([c, v]) => `${c} = ${fmt(v)}`).join(', ')}` : '') +
    (bars ? '; error bars: ±1 standard error (the films\' radiance_stderr)' : '; no error bars: the films have no radiance_stderr (submit with error bars)');
  svg.dataset.ready = '1';
  svg.dataset.job = job;
}

// ---- the job form ------------------------------------------------------------------------------------------
function addGridRow(name = '', values = '') {
  const row = el('div', { class: 'grid-row' },
    el('input', { class: 'g-name', type: 'text', placeholder: 'wavelength, a parameter key, or a coordinate', spellcheck: 'false', 'aria-label': 'coordinate' }),
    el('input', { class: 'g-values', type: 'text', placeholder: '400:700:50  or  0, 30, 60', spellcheck: 'false', 'aria-label': 'values' }),
    el('button', { type: 'button', class: 'small', title: 'remove', onclick: () => row.remove() }, '×'));
  row.querySelector('.g-name').value = name;
  row.querySelector('.g-values').value = values;
  $('j-grid').append(row);
}

// "START:STOP:STEP" (the end included, as raysweep sweep --grid) or a list
// of numbers; throws with a message naming the coordinate.
function gridValues(name, text) {
  const t = text.trim();
  const range = /^(-?[\d.eE+-]+)\s*:\s*(-?[\d.eE+-]+)\s*:\s*([\d.eE+-]+)$/.exec(t);
  if (range) {
    const [a, b, st] = range.slice(1).map(Number);
    if (![a, b, st].every(Number.isFinite) || !(st > 0) || b < a) throw new Error(`${name}: ${t} is not START:STOP:STEP with STEP > 0 and STOP ≥ START`);
    const n = Math.floor((b - a) / st + 1e-9) + 1;
    if (n > 10000) throw new Error(`${name}: ${n} values`);
    return Array.from({ length: n }, (_, i) => Number((a + i * st).toPrecision(12)));
  }
  const vals = t.split(/[\s,]+/).filter(Boolean).map(Number);
  if (!vals.length || !vals.every(Number.isFinite)) throw new Error(`${name}: "${t}" is neither START:STOP:STEP nor a list of numbers`);
  return vals;
}

// The coordinate a grid row fills, as raysweep sweep --grid names it:
// wavelength, a parameter key's last name that is not "value"
// (plate.bsdf.reflectance.value → reflectance), or the name itself.
function coordName(name) {
  const parts = name.split('.');
  if (parts.length > 1 && parts[parts.length - 1] === 'value') parts.pop();
  let c = parts[parts.length - 1].replace(/[^A-Za-z0-9_]/g, '_');
  if (!/^[A-Za-z]/.test(c)) c = 'p' + c;
  return c;
}

function jobBody() {
  const keys = new Set();
  for (const p of state.params) {
    keys.add(p.key);
    for (const a of p.aliases) keys.add(a);
  }
  const axes = [];
  for (const row of $('j-grid').querySelectorAll('.grid-row')) {
    const name = row.querySelector('.g-name').value.trim();
    const text = row.querySelector('.g-values').value;
    if (!name && !text.trim()) continue;
    if (!name) throw new Error('a coordinate row has values but no name');
    const kind = name === 'wavelength' ? 'wavelength' : keys.has(name) ? 'param' : 'coord';
    axes.push({ name, kind, coord: kind === 'param' ? coordName(name) : name, values: gridValues(name, text) });
  }
  const total = axes.reduce((n, a) => n * a.values.length, 1);
  if (total > 100000) throw new Error(`${total} contexts (at most 100000)`);
  const width = String(Math.max(0, total - 1)).length;
  const contexts = [];
  for (let i = 0; i < total; i++) {
    const ctx = { id: 'c' + String(i).padStart(width, '0') };
    let rest = i;
    const picks = [];
    for (let a = axes.length - 1; a >= 0; a--) {
      picks[a] = axes[a].values[rest % axes[a].values.length];
      rest = Math.floor(rest / axes[a].values.length);
    }
    if (axes.length) ctx.coords = {};
    axes.forEach((a, k) => {
      ctx.coords[a.coord] = picks[k];
      if (a.kind === 'param') (ctx.params = ctx.params || {})[a.name] = picks[k];
    });
    contexts.push(ctx);
  }
  const body = { contexts, seed: Number($('j-seed').value || 0) };
  const sensors = [...$('j-sensors').selectedOptions].map((o) => o.value);
  body.defaults = {};
  if (sensors.length) body.defaults.sensors = sensors;
  if ($('j-spp').value) body.defaults.spp = Number($('j-spp').value);
  const q = ['brf', 'brdf'].filter((x) => $('j-' + x).checked);
  if (q.length) body.quantities = q;
  if ($('j-variance').checked) body.variance = true;
  return body;
}

async function submitJob(ev) {
  ev.preventDefault();
  if (!state.scene) return;
  let body;
  try {
    body = jobBody();
  } catch (e) {
    banner(`job: ${e.message}`);
    return;
  }
  const btn = $('j-submit');
  btn.disabled = true;
  try {
    const { data } = await api('POST', `/v1/scenes/${encodeURIComponent(state.scene.id)}/jobs`, { body });
    $('j-status').textContent = `job ${jobLabel(data.id)}: ${body.contexts.length} context(s) submitted`;
    $('j-status').dataset.job = data.id;
    banner('');
    await loadJobs();
    await showResults(data.id);
  } catch (e) {
    $('j-status').textContent = '';
    report(e, 'submitting the job');
  } finally {
    btn.disabled = false;
  }
}

// ---- start ------------------------------------------------------------------------------------------------
async function start() {
  banner('');
  state.scene = null;
  if (!(await loadServer())) {
    $('scenes').replaceChildren();
    $('jobs').replaceChildren();
    return;
  }
  await loadScenes();
  await loadJobs();
}

function wire() {
  $('token').value = getToken();
  $('token-form').addEventListener('submit', (ev) => {
    ev.preventDefault();
    setToken($('token').value.trim());
    start();
  });
  $('token-clear').addEventListener('click', () => {
    $('token').value = '';
    setToken('');
    start();
  });
  $('scenes-refresh').addEventListener('click', loadScenes);
  $('jobs-refresh').addEventListener('click', loadJobs);
  $('param-search').addEventListener('input', () => renderParams());
  $('param-class').addEventListener('change', () => renderParams());
  $('render-form').addEventListener('submit', render);
  $('exposure').addEventListener('input', redraw);
  $('exposure-auto').addEventListener('click', () => {
    if (!state.model) return;
    // EV such that the 99.5th percentile of what is shown is full scale.
    const p = currentPlane();
    const white = autoWhite(displayModel(state.film, p.idx, $('channel').value, 1, p.scale, p).values.map(Math.abs));
    $('exposure').value = -Math.log2(white);
    redraw();
  });
  $('exposure-zero').addEventListener('click', () => {
    $('exposure').value = 0;
    redraw();
  });
  $('plane').addEventListener('change', () => {
    fillChannels();
    redraw();
  });
  $('channel').addEventListener('change', redraw);
  for (const id of ['sw-sensor', 'sw-quantity', 'sw-channel', 'sw-pixel', 'sw-x', 'sw-series']) {
    $(id).addEventListener('change', () => {
      $(id).dataset.user = '1';
    });
  }
  for (const id of ['sw-sensor', 'sw-quantity', 'sw-channel', 'sw-pixel']) $(id).addEventListener('change', drawSweepView);
  $('sw-x').addEventListener('change', () => {
    // A line per value of any coordinate but the one plotted against.
    const x = $('sw-x').value, ser = $('sw-series');
    for (const o of ser.options) o.disabled = o.value !== '' && o.value === x;
    if (ser.value === x) ser.value = '';
    sweepFixed();
    drawSweepView();
  });
  $('sw-series').addEventListener('change', () => {
    sweepFixed();
    drawSweepView();
  });
  $('j-add').addEventListener('click', () => addGridRow());
  $('job-form').addEventListener('submit', submitJob);
  addGridRow();
  $('film').addEventListener('mousemove', hoverFilm);
  $('plot').addEventListener('mousemove', hoverPlot);
  // New jobs (submitted by other clients) show up within two seconds.
  setInterval(() => {
    if (document.visibilityState === 'visible' && document.body.dataset.auth === 'ok') loadJobs();
  }, 2000);
}

wire();
start();
