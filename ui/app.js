// raysweep viewer: scenes and their parameters, renders, jobs and films,
// over the public API only (api.js).
import { api, ApiError, followEvents, getToken, setToken } from './api.js';
import { autoWhite, displayModel, drawColorbar, drawFilm, fmt, PlanePlot, PolarPlot } from './plot.js';

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

const state = {
  scenes: [],
  scene: null, // SceneInfo of the selected scene
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
    }, el('div', { class: 'id' }, short(s.id)),
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

async function selectScene(id) {
  try {
    const { data: info } = await api('GET', `/v1/scenes/${encodeURIComponent(id)}`);
    state.scene = info;
    await loadParams();
  } catch (e) {
    report(e, 'opening the scene');
    return;
  }
  for (const li of $('scenes').children) li.classList.toggle('selected', li.dataset.scene === id);
  $('scene-title').textContent = `${short(id)} · ${state.scene.variant}`;
  const sel = $('r-sensor');
  const types = state.sensorTypes.get(id) || new Map();
  sel.replaceChildren(...state.scene.sensors.map((s) => el('option', { value: s }, types.has(s) ? `${s} (${types.get(s)})` : s)));
  $('r-wl-label').hidden = state.scene.variant !== 'mono';
}

async function loadParams(flashKey) {
  const id = state.scene.id;
  const { data } = await api('GET', `/v1/scenes/${encodeURIComponent(id)}/params`);
  state.params = data.params;
  state.revision = data.revision;
  state.sensorTypes.set(id, typesFrom(data.params));
  $('params').dataset.revision = data.revision;
  $('scene-title').textContent = `${short(id)} · ${state.scene.variant} · revision ${data.revision}`;
  renderParams(flashKey);
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
      banner(`${p.key} set: revision ${data.revision}, ${data.changed} changed (${data.classes.join(', ') || 'no class'}) in ${fmt(data.seconds)} s`, 'info');
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
    const s = ((performance.now() - t0) / 1000).toFixed(2);
    $('render-status').textContent = `${data.width}×${data.height}, ${data.meta.spp} spp, seed ${data.meta.seed}: ${s} s`;
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

async function showFilm(film, title) {
  state.film = film;
  state.filmType = await sensorType(film);
  state.filmTitle = title;
  const m = film.meta;
  const bits = [title, m.wavelength ? `${m.wavelength} nm` : m.variant, state.filmType].filter(Boolean);
  $('film-title').textContent = bits.join(' · ');
  const ch = $('channel');
  const opts = film.channels.length === 3
    ? [['rgb', 'RGB'], ['lum', 'luminance'], ['0', 'R'], ['1', 'G'], ['2', 'B']]
    : film.channels.map((c, i) => [String(i), c]);
  const keep = ch.value;
  ch.replaceChildren(...opts.map(([v, t]) => el('option', { value: v }, t)));
  if (opts.some(([v]) => v === keep)) ch.value = keep;
  $('quantity-label').hidden = state.filmType !== 'mdistant';
  $('film-empty').hidden = true;
  document.querySelector('.film-row').hidden = false;
  $('hover').textContent = 'move the pointer over the film or the plot for its values';
  $('exposure').value = 0;
  redraw();
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
  const c = film.channels.length, eh = new Array(c).fill(0);
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

function redraw() {
  const film = state.film;
  if (!film) return;
  const mode = $('channel').value;
  const ev = Number($('exposure').value);
  $('exposure-out').textContent = `${ev > 0 ? '+' : ''}${ev} EV`;
  const probe = displayModel(film, mode, 1);
  const white = autoWhite(probe.values) / Math.pow(2, ev);
  const model = displayModel(film, mode, white);
  drawFilm($('film'), film, model, 320);
  $('film').dataset.ready = '1';
  drawColorbar($('colorbar'), white, model.rgb, 'radiance');
  $('colorbar-unit').textContent = model.rgb ? 'radiance (sRGB, clipped)' : 'radiance';
  const fig = $('plot-fig');
  state.plot = null;
  const type = state.filmType;
  const m = film.meta;
  if (m.zenith_deg && (type === 'hdistant' || type === 'distantflux') && film.height > 1) {
    state.plot = new PolarPlot($('plot'), film, model);
    state.plot.draw();
    $('plot-caption').textContent = `${type}: zenith θ as radius (0° centre, 90° rim), azimuth φ east-right (0° = +x, counter-clockwise)`;
    fig.hidden = false;
  } else if (m.zenith_deg && type === 'mdistant') {
    const colors = film.channels.length === 3 ? ['#d62728', '#2ca02c', '#1f77b4'] : ['#26828e'];
    const n = film.width * film.height, c = film.channels.length;
    let unit = 'radiance';
    let scale = new Array(c).fill(1);
    const q = $('quantity');
    const eh = horizontalIrradiance(film);
    q.options[1].disabled = !eh;
    if (q.value === 'brf' && eh) {
      scale = eh.map((e) => Math.PI / e);
      unit = 'BRF = π L / E_h';
    } else q.value = 'radiance';
    const series = film.channels.map((name, i) => ({
      name, color: colors[i], values: Array.from({ length: n }, (_, k) => film.data[k * c + i] * scale[i]),
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
  $('hover').textContent = `${where} pixel (${ix}, ${iy})  ${vals}${ang}`;
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

function renderJobs() {
  const ul = $('jobs');
  ul.replaceChildren();
  const jobs = [...state.jobs.values()].sort((a, b) => (a.created < b.created ? 1 : a.created > b.created ? -1 : 0));
  for (const j of jobs) {
    const live = j.state === 'queued' || j.state === 'running';
    const pct = j.renders_total ? (100 * j.renders_done) / j.renders_total : 0;
    const bar = el('div', { class: 'progress' }, el('div'));
    bar.firstChild.style.width = pct.toFixed(1) + '%';
    ul.append(el('li', {
      class: state.selectedJob === j.id ? 'selected' : '',
      dataset: { job: j.id, state: j.state, done: j.renders_done, total: j.renders_total, events: state.events.get(j.id) || 0 },
      onclick: () => showResults(j.id),
    },
    el('div', { class: 'job-row' },
      el('span', { class: 'id grow', title: j.id }, j.id),
      el('span', { class: `state-${j.state}` }, j.state),
      live ? el('button', { type: 'button', class: 'small danger', title: 'POST :cancel', onclick: (ev) => cancelJob(j.id, ev) }, 'cancel') : null),
    bar,
    el('div', { class: 'meta' }, `${j.renders_done}/${j.renders_total} renders` +
      (j.renders_failed ? `, ${j.renders_failed} failed` : '') + ` · scene ${j.scene.slice(0, 8)}…` +
      (j.seconds !== undefined ? ` · ${fmt(j.seconds)} s` : '') + (j.error ? ` · ${j.error}` : '')),
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
    await showFilm(data, `job ${id} · ${r.context}`);
  } catch (e) {
    report(e, `film ${r.context}/${r.sensor}`);
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
    $('exposure').value = 0;
    redraw();
  });
  $('channel').addEventListener('change', redraw);
  $('quantity').addEventListener('change', redraw);
  $('film').addEventListener('mousemove', hoverFilm);
  $('plot').addEventListener('mousemove', hoverPlot);
  // New jobs (submitted by other clients) show up within two seconds.
  setInterval(() => {
    if (document.visibilityState === 'visible' && document.body.dataset.auth === 'ok') loadJobs();
  }, 2000);
}

wire();
start();
