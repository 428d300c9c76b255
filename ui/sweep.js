// The sweep view: one number per film of a job (a pixel's, or the film's
// mean) against one coordinate of its contexts, with ±1 standard error
// bars, one line per value of a second coordinate, the others held at a
// chosen value. Plain SVG, drawn from the films the job's results list.
import { filmPlanes, fmt, ticks } from './plot.js';

const SVG = 'http://www.w3.org/2000/svg';
const COLORS = ['#1f77b4', '#d62728', '#2ca02c', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2', '#7f7f7f', '#bcbd22', '#17becf']; // matplotlib's tab10, reordered

// The coordinates of a job's results: each result's coords, plus its
// wavelength (mono) when no coord already carries it. Returns
// {names: [numeric coordinate names], of(r) → {name: value}}.
export function resultCoords(results) {
  const of = (r) => {
    const c = Object.assign({}, r.coords || {});
    if (r.wavelength !== undefined && r.wavelength !== null && c.wavelength === undefined) c.wavelength = r.wavelength;
    return c;
  };
  const names = [];
  for (const r of results) {
    for (const [k, v] of Object.entries(of(r))) if (typeof v === 'number' && !names.includes(k)) names.push(k);
  }
  return { names, of };
}

// The value and standard error of one film for plane `quantity` (radiance,
// brf or brdf), channel position ch in that plane, at pixel k (or the
// film's mean with k < 0). The error is the film's radiance_stderr plane,
// scaled as the quantity is to the radiance (brf = π L / E_h: E_h is the
// same for every pixel); for a mean, sqrt(Σ se²) / n. err is null without
// a radiance_stderr plane.
export function filmValue(film, quantity, ch, k) {
  const planes = filmPlanes(film);
  const q = planes.find((p) => p.name === quantity);
  if (!q) return null;
  const rad = planes[0], se = planes.find((p) => p.name === 'radiance_stderr');
  const c = film.channels.length, n = film.width * film.height, d = film.data;
  const i = Math.min(ch, q.idx.length - 1);
  let sum = 0, var2 = 0, count = 0;
  for (let p = k < 0 ? 0 : k; p < (k < 0 ? n : k + 1); p++) {
    const v = d[p * c + q.idx[i]];
    if (v === null || !Number.isFinite(v)) continue;
    sum += v;
    count++;
    if (se) {
      const L = d[p * c + rad.idx[i]], s = d[p * c + se.idx[i]];
      const ratio = quantity === 'radiance' ? 1 : L > 0 ? v / L : 0;
      var2 += (s * ratio) ** 2;
    }
  }
  if (!count) return null;
  return { value: sum / count, err: se ? Math.sqrt(var2) / count : null };
}

// points: [{x, y, err, series, context}]; opts: {xName, yName, seriesName}.
// Draws into the <svg> el; each point is a <circle> with data-x, data-y,
// data-err, data-series and data-context (for the hover read-out and the
// tests), each error bar a <line class="err">, each series a <path
// class="series"> with data-series.
export function drawSweep(el, points, opts) {
  const W = 620, H = 360, L = 70, R = 130, T = 16, B = 46;
  const w = W - L - R, h = H - T - B;
  el.setAttribute('viewBox', `0 0 ${W} ${H}`);
  el.setAttribute('width', W);
  el.setAttribute('height', H);
  el.replaceChildren();
  const mk = (tag, attrs, text) => {
    const e = document.createElementNS(SVG, tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    el.append(e);
    return e;
  };
  if (!points.length) {
    mk('text', { x: W / 2, y: H / 2, 'text-anchor': 'middle', class: 'empty' }, 'no film to plot yet');
    return;
  }
  let x0 = Infinity, x1 = -Infinity, y0 = 0, y1 = -Infinity;
  for (const p of points) {
    x0 = Math.min(x0, p.x);
    x1 = Math.max(x1, p.x);
    y0 = Math.min(y0, p.y - (p.err || 0));
    y1 = Math.max(y1, p.y + (p.err || 0));
  }
  if (!(x1 > x0)) (x0 -= 1), (x1 += 1);
  if (!(y1 > y0)) y1 = y0 + 1;
  const pad = (x1 - x0) * 0.04;
  x0 -= pad;
  x1 += pad;
  y1 += (y1 - y0) * 0.05;
  const X = (x) => L + ((x - x0) / (x1 - x0)) * w, Y = (y) => T + h * (1 - (y - y0) / (y1 - y0));
  for (const t of ticks(x0, x1, 6)) {
    mk('line', { x1: X(t), x2: X(t), y1: T, y2: T + h, class: 'grid' });
    mk('text', { x: X(t), y: T + h + 16, 'text-anchor': 'middle' }, fmt(t));
  }
  for (const t of ticks(y0, y1, 5)) {
    mk('line', { x1: L, x2: L + w, y1: Y(t), y2: Y(t), class: 'grid' });
    mk('text', { x: L - 6, y: Y(t) + 4, 'text-anchor': 'end' }, fmt(t));
  }
  mk('rect', { x: L, y: T, width: w, height: h, class: 'frame' });
  mk('text', { x: L + w / 2, y: H - 6, 'text-anchor': 'middle', class: 'axis-label' }, opts.xName);
  mk('text', { x: 14, y: T + h / 2, 'text-anchor': 'middle', transform: `rotate(-90 14 ${T + h / 2})`, class: 'axis-label' }, opts.yName);
  const groups = new Map();
  for (const p of points) {
    if (!groups.has(p.series)) groups.set(p.series, []);
    groups.get(p.series).push(p);
  }
  const keys = [...groups.keys()].sort((a, b) => (typeof a === 'number' && typeof b === 'number' ? a - b : String(a).localeCompare(String(b))));
  keys.forEach((key, gi) => {
    const color = COLORS[gi % COLORS.length];
    const pts = groups.get(key).sort((a, b) => a.x - b.x);
    mk('path', {
      d: pts.map((p, i) => `${i ? 'L' : 'M'}${X(p.x).toFixed(2)},${Y(p.y).toFixed(2)}`).join(' '),
      class: 'series', stroke: color, 'data-series': String(key),
    });
    for (const p of pts) {
      if (p.err) {
        mk('line', { x1: X(p.x), x2: X(p.x), y1: Y(p.y - p.err), y2: Y(p.y + p.err), class: 'err', stroke: color });
        for (const yy of [p.y - p.err, p.y + p.err]) mk('line', { x1: X(p.x) - 3, x2: X(p.x) + 3, y1: Y(yy), y2: Y(yy), class: 'err', stroke: color });
      }
      const c = mk('circle', {
        cx: X(p.x), cy: Y(p.y), r: 3.2, fill: color,
        'data-x': p.x, 'data-y': p.y, 'data-err': p.err === null ? '' : p.err, 'data-series': String(key), 'data-context': p.context,
      });
      c.append(Object.assign(document.createElementNS(SVG, 'title'), {
        textContent: `${p.context}: ${opts.xName} ${fmt(p.x)}, ${fmt(p.y)}${p.err ? ` ± ${fmt(p.err)}` : ''}`,
      }));
    }
    if (opts.seriesName) {
      const ly = T + 10 + gi * 16;
      mk('line', { x1: L + w + 12, x2: L + w + 30, y1: ly, y2: ly, stroke: color, class: 'legend' });
      mk('text', { x: L + w + 34, y: ly + 4 }, `${opts.seriesName} ${typeof key === 'number' ? fmt(key) : key}`);
    }
  });
  el.dataset.x0 = X(x0 + pad); // for the tests: where the data's first and last x are, in SVG units
  el.dataset.points = points.length;
}
