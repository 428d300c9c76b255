// Drawing films: tone mapping, a false-colour map, the colour bar, the
// polar plot of a hemisphere (hdistant) and the line plot of a principal
// plane (mdistant). Plain 2-D canvas.

// viridis (matplotlib's default map), 9 stops, interpolated linearly.
const VIRIDIS = [
  [68, 1, 84], [72, 40, 120], [62, 73, 137], [49, 104, 142], [38, 130, 142],
  [31, 158, 137], [53, 183, 121], [110, 206, 88], [253, 231, 37],
];

export function viridis(t) {
  t = Math.min(1, Math.max(0, t));
  const x = t * (VIRIDIS.length - 1);
  const i = Math.min(VIRIDIS.length - 2, Math.floor(x));
  const f = x - i;
  const a = VIRIDIS[i], b = VIRIDIS[i + 1];
  return [a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f, a[2] + (b[2] - a[2]) * f];
}

// Linear [0,1] → 8-bit sRGB (IEC 61966-2-1).
function srgb8(v) {
  if (!(v > 0)) return 0;
  if (v >= 1) return 255;
  const e = v <= 0.0031308 ? 12.92 * v : 1.055 * Math.pow(v, 1 / 2.4) - 0.055;
  return Math.round(e * 255);
}

// The Stokes component a channel's short name starts with: 0..3 for S0..S3
// and S0.Y, S2.R, ... (docs/polarization.md), else -1.
function stokesComponent(c) {
  return /^S[0-3](\.|$)/.test(c) ? Number(c[1]) : -1;
}

// A plane's Stokes layout: {nColor, colors} when its short names are
// S0..S3, S0.Y..S3.Y or S0.R S0.G S0.B S1.R .. S3.B (component-major),
// else null.
export function stokesLayout(names) {
  const n = names.length, nc = n / 4;
  if (n < 4 || n % 4 || nc > 4) return null;
  const colors = names.slice(0, nc).map((c) => (c.length > 3 ? c.slice(3) : ''));
  for (let k = 0; k < n; k++) {
    const want = `S${Math.floor(k / nc)}${colors[k % nc] ? '.' + colors[k % nc] : ''}`;
    if (names[k] !== want) return null;
  }
  return { nColor: nc, colors };
}

// A film's planes: its radiance (the channels without a dot: R, G, B or
// Y; S0..S3, S0.Y.., S0.R.. for Stokes films) and each plane the render
// added (brf.Y, radiance_stderr.R, brf.S0.Y, ...), as [{name, idx: channel
// indices, names: the channels' short names, stokes: stokesLayout}], the
// radiance first. A mono film with BRF and error planes is three planes of
// one channel each, not an RGB film.
export function filmPlanes(film) {
  const out = [{ name: 'radiance', idx: [], names: [] }];
  const by = new Map([['radiance', out[0]]]);
  film.channels.forEach((c, i) => {
    const dot = stokesComponent(c) >= 0 ? -1 : c.indexOf('.');
    const name = dot < 0 ? 'radiance' : c.slice(0, dot);
    if (!by.has(name)) {
      by.set(name, { name, idx: [], names: [] });
      out.push(by.get(name));
    }
    by.get(name).idx.push(i);
    by.get(name).names.push(dot < 0 ? c : c.slice(dot + 1));
  });
  for (const p of out) p.stokes = stokesLayout(p.names);
  return out;
}

// DoLP = sqrt(S1² + S2²) / S0 (0 where S0 = 0) and AoLP = ½ atan2(S2, S1)
// in degrees, in (-90, 90] (0 where S1 = S2 = 0): docs/polarization.md.
export function dolp(s0, s1, s2) {
  return s0 === 0 ? 0 : Math.hypot(s1, s2) / s0;
}
export function aolp(s1, s2) {
  if (s1 === 0 && s2 === 0) return 0;
  const a = (0.5 * Math.atan2(s2, s1) * 180) / Math.PI;
  return a <= -90 ? a + 180 : a;
}

// Cyclic hue for an AoLP in [-90, 90] (-90 and 90 are one axis, one
// colour): hue (aolp + 90) / 180 of the circle, full saturation and value.
export function hue(a) {
  const h = ((((a + 90) / 180) % 1) + 1) % 1 * 6, i = Math.floor(h) % 6, f = h - Math.floor(h);
  const q = Math.round(255 * (1 - f)), t = Math.round(255 * f);
  return [[255, t, 0], [q, 255, 0], [0, 255, t], [0, q, 255], [t, 0, 255], [255, 0, q]][i];
}

// Diverging blue-white-red for signed values (S1..S3), t in [0, 1], 0.5 white.
function diverging(t) {
  t = Math.min(1, Math.max(0, t));
  const lo = [59, 76, 192], mid = [240, 240, 240], hi = [180, 4, 38];
  const [a, b, f] = t < 0.5 ? [lo, mid, 2 * t] : [mid, hi, 2 * t - 1];
  return [a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f, a[2] + (b[2] - a[2]) * f];
}

// A Stokes plane's views: 'rgb' (S0 in colour, rgb films), S0..S3 (the
// colours' luminance for rgb films), DoLP, AoLP; as [value, label].
export function stokesViews(plane) {
  const v = plane.stokes.nColor === 3 ? [['rgb', 'S0 (RGB)']] : [];
  return v.concat([['s0', 'S0'], ['s1', 'S1'], ['s2', 'S2'], ['s3', 'S3'], ['dolp', 'DoLP'], ['aolp', 'AoLP']]);
}

// A Stokes plane in display form (view: stokesViews's value): S0 as any
// one-channel film, S1..S3 signed over [-white, white] (diverging), DoLP
// greyscale over [0, 1] (linear 8-bit grey: 0.5 is 128), AoLP as a cyclic
// hue over [-90, 90] degrees. An rgb film's Stokes vector is its colours'
// luminance-weighted sum (linear, so DoLP and AoLP are those of that sum).
function stokesModel(film, plane, view, white, scale) {
  const n = film.width * film.height, c = film.channels.length, d = film.data, nc = plane.stokes.nColor;
  const sc = scale || plane.idx.map(() => 1);
  const lum = nc === 3 ? [0.212671, 0.71516, 0.072169] : [1];
  const comp = (k, s) => {
    let v = 0;
    for (let j = 0; j < nc; j++) v += lum[j] * (d[k * c + plane.idx[s * nc + j]] ?? NaN) * sc[s * nc + j];
    return v;
  };
  const values = new Float64Array(n);
  const inv = white > 0 ? 1 / white : 0;
  if (view === 'dolp' || view === 'aolp') {
    for (let k = 0; k < n; k++) values[k] = view === 'dolp' ? dolp(comp(k, 0), comp(k, 1), comp(k, 2)) : aolp(comp(k, 1), comp(k, 2));
    if (view === 'dolp') {
      const g = (k) => Math.round(255 * Math.min(1, Math.max(0, values[k])));
      return { values, color: (k) => [g(k), g(k), g(k)], rgb: false, kind: 'dolp', lo: 0, hi: 1, ramp: (t) => [255 * t, 255 * t, 255 * t] };
    }
    return { values, color: (k) => (Number.isFinite(values[k]) ? hue(values[k]) : [0, 0, 0]), rgb: false, kind: 'aolp', lo: -90, hi: 90, ramp: (t) => hue(180 * t - 90) };
  }
  const s = Number(view.slice(1));
  for (let k = 0; k < n; k++) values[k] = comp(k, s);
  if (s === 0) return { values, color: (k) => viridis(values[k] * inv), rgb: false, kind: 'false-colour', lo: 0, hi: white, ramp: viridis };
  return { values, color: (k) => diverging(0.5 + 0.5 * values[k] * inv), rgb: false, kind: 'signed', lo: -white, hi: white, ramp: diverging };
}

// The film in display form, for the channels idx of one plane (each times
// scale[i]; default 1). mode: 'rgb' (three channels as sRGB), 'lum'
// (their luminance) or a position in idx, shown in false colour. white is
// the value shown at full scale (2^-EV: at 0 EV a value of 1 is white, as
// in Mitsuba's 8-bit sRGB conversion). Returns {values: Float64Array per
// pixel (the displayed quantity), color(k) → [r,g,b] for pixel k, rgb}.
export function displayModel(film, idx, mode, white, scale, plane) {
  if (plane && plane.stokes && mode !== 'rgb') return stokesModel(film, plane, mode, white, scale);
  if (plane && plane.stokes) {
    // S0 of an rgb Stokes film in colour.
    idx = idx.slice(0, 3);
    scale = scale && scale.slice(0, 3);
  }
  const n = film.width * film.height, c = film.channels.length, d = film.data, m = idx.length;
  const sc = scale || idx.map(() => 1);
  const at = (k, i) => (d[k * c + idx[i]] ?? NaN) * sc[i];
  const values = new Float64Array(n);
  const rgbMode = mode === 'rgb' && m === 3;
  for (let k = 0; k < n; k++) {
    if (mode === 'lum' || rgbMode) values[k] = m === 3 ? 0.212671 * at(k, 0) + 0.71516 * at(k, 1) + 0.072169 * at(k, 2) : at(k, 0);
    else values[k] = at(k, Math.min(m - 1, mode | 0));
  }
  const inv = white > 0 ? 1 / white : 0;
  const color = rgbMode
    ? (k) => [srgb8(at(k, 0) * inv), srgb8(at(k, 1) * inv), srgb8(at(k, 2) * inv)]
    : (k) => viridis(values[k] * inv);
  const ramp = rgbMode ? (t) => [srgb8(t), srgb8(t), srgb8(t)] : viridis;
  return { values, color, rgb: rgbMode, kind: rgbMode ? 'rgb' : 'false-colour', lo: 0, hi: white, ramp };
}

// The automatic full scale: the 99.5th percentile (nearest rank) of the
// finite values > 0, not the maximum (a lamp or a glint clips instead of
// darkening the rest), or 1 when there are none. The PNG quick-looks'
// `auto` exposure uses the same rule (common/image_png.h).
export function autoWhite(values) {
  const v = Array.from(values).filter((x) => Number.isFinite(x) && x > 0).sort((a, b) => a - b);
  if (!v.length) return 1;
  const rank = Math.min(v.length, Math.max(1, Math.ceil(0.995 * v.length)));
  return v[rank - 1];
}

// Seconds as people read them: 188 µs, 42.1 ms, 3.2 s, 2 min 05 s, 1 h 02 min.
export function fmtDuration(s) {
  if (!Number.isFinite(s) || s < 0) return '—';
  if (s < 1e-3) return `${Math.round(s * 1e6)} µs`;
  if (s < 1) return `${Number((s * 1e3).toPrecision(3))} ms`;
  if (s < 60) return `${Number(s.toPrecision(3))} s`;
  const m = Math.floor(s / 60);
  if (m < 60) return `${m} min ${String(Math.floor(s - 60 * m)).padStart(2, '0')} s`;
  return `${Math.floor(m / 60)} h ${String(m % 60).padStart(2, '0')} min`;
}

export function drawFilm(canvas, film, model, maxCss) {
  canvas.width = film.width;
  canvas.height = film.height;
  const ctx = canvas.getContext('2d');
  const img = ctx.createImageData(film.width, film.height);
  for (let k = 0; k < film.width * film.height; k++) {
    const [r, g, b] = model.color(k);
    img.data[4 * k] = r;
    img.data[4 * k + 1] = g;
    img.data[4 * k + 2] = b;
    img.data[4 * k + 3] = 255;
  }
  ctx.putImageData(img, 0, 0);
  // Whole screen pixels per film pixel where that fits, so pixels stay square.
  const fit = maxCss / Math.max(film.width, film.height);
  const scale = fit >= 1 ? Math.floor(fit) : fit;
  canvas.style.width = film.width * scale + 'px';
  canvas.style.height = Math.max(film.height * scale, film.height === 1 ? 28 : 0) + 'px';
}

// Nice tick values for [lo, hi] (about n of them).
export function ticks(lo, hi, n) {
  if (!(hi > lo)) return [lo];
  const raw = (hi - lo) / n, mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 2.5, 5, 10].map((s) => s * mag).find((s) => s >= raw) || raw;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(Math.abs(v) < step * 1e-9 ? 0 : v);
  return out;
}

export function fmt(v) {
  if (!Number.isFinite(v)) return String(v);
  const a = Math.abs(v);
  if (a !== 0 && (a < 1e-3 || a >= 1e5)) return v.toExponential(3);
  return String(Number(v.toPrecision(5)));
}

function hiDpi(canvas, w, h) {
  const dpr = window.devicePixelRatio || 1;
  canvas.width = Math.round(w * dpr);
  canvas.height = Math.round(h * dpr);
  canvas.style.width = w + 'px';
  canvas.style.height = h + 'px';
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  return ctx;
}

// The colour bar of a display model: its ramp from lo to hi, with ticks.
export function drawColorbar(canvas, model, unit) {
  const { lo, hi } = model;
  const W = 78, H = 260, x0 = 6, bw = 16, y0 = 8, y1 = H - 8;
  const ctx = hiDpi(canvas, W, H);
  ctx.clearRect(0, 0, W, H);
  for (let y = y0; y <= y1; y++) {
    const t = (y1 - y) / (y1 - y0);
    const c = model.ramp(t);
    ctx.fillStyle = `rgb(${c[0]},${c[1]},${c[2]})`;
    ctx.fillRect(x0, y, bw, 1.5);
  }
  ctx.strokeStyle = '#888';
  ctx.strokeRect(x0 + 0.5, y0 + 0.5, bw, y1 - y0);
  ctx.fillStyle = '#1d232b';
  ctx.font = '11px system-ui, sans-serif';
  ctx.textBaseline = 'middle';
  for (const v of ticks(lo, hi, 5)) {
    const y = y1 - ((v - lo) / (hi - lo)) * (y1 - y0);
    ctx.fillRect(x0 + bw, y, 4, 1);
    ctx.fillText(fmt(v), x0 + bw + 7, y);
  }
  canvas.title = `${fmt(lo)} … ${fmt(hi)} ${unit}${model.kind === 'aolp' ? ' (cyclic)' : ' (values beyond are clipped)'}`;
}

// ---- polar plot of a hemisphere --------------------------------------------
// Zenith θ as the radius (linear, 0° at the centre, 90° on the rim) and
// azimuth φ as the polar angle, 0° to the right (+x, east) and growing
// counter-clockwise (+y, north, at the top): Eradiate's east_right
// convention, as matplotlib's polar axes draw it. Each point of the disk
// takes the film pixel whose centre direction (the film's own zenith_deg,
// azimuth_deg) is nearest on the plot.
export class PolarPlot {
  constructor(canvas, film, model) {
    this.canvas = canvas;
    this.film = film;
    this.model = model;
    this.size = 420;
    this.R = 160; // room around the rim for the azimuth labels
    this.cx = this.size / 2;
    this.cy = this.size / 2;
    const m = film.meta, n = film.width * film.height;
    this.px = new Float64Array(n);
    this.py = new Float64Array(n);
    for (let k = 0; k < n; k++) {
      const r = m.zenith_deg[k] / 90, phi = (m.azimuth_deg[k] * Math.PI) / 180;
      this.px[k] = r * Math.cos(phi);
      this.py[k] = r * Math.sin(phi);
    }
    // A uniform grid over [-1,1]² of the pixel centres, for nearest look-ups.
    this.G = Math.max(1, Math.ceil(Math.sqrt(n)));
    this.cells = Array.from({ length: this.G * this.G }, () => []);
    for (let k = 0; k < n; k++) this.cells[this.cell(this.px[k]) + this.G * this.cell(this.py[k])].push(k);
  }

  cell(u) {
    return Math.min(this.G - 1, Math.max(0, Math.floor(((u + 1) / 2) * this.G)));
  }

  // The film pixel nearest to plot point (u, v) in unit-disk coordinates.
  nearest(u, v) {
    const G = this.G, cu = this.cell(u), cv = this.cell(v);
    let best = -1, bd = Infinity;
    for (let ring = 0; ring < G; ring++) {
      for (let j = cv - ring; j <= cv + ring; j++) {
        if (j < 0 || j >= G) continue;
        for (let i = cu - ring; i <= cu + ring; i++) {
          if (i < 0 || i >= G || (Math.abs(i - cu) !== ring && Math.abs(j - cv) !== ring)) continue;
          for (const k of this.cells[i + G * j]) {
            const d = (this.px[k] - u) ** 2 + (this.py[k] - v) ** 2;
            if (d < bd) (bd = d), (best = k);
          }
        }
      }
      // Anything in the next ring is at least `ring` cells away.
      const reach = (ring * 2) / G;
      if (best >= 0 && reach * reach >= bd) break;
    }
    return best;
  }

  draw() {
    const { size, R, cx, cy } = this;
    const ctx = hiDpi(this.canvas, size, size);
    const dpr = window.devicePixelRatio || 1;
    ctx.clearRect(0, 0, size, size);
    // The disk, one device pixel at a time.
    const D = Math.ceil(2 * R * dpr);
    const off = document.createElement('canvas');
    off.width = off.height = D;
    const octx = off.getContext('2d');
    const img = octx.createImageData(D, D);
    for (let j = 0; j < D; j++) {
      const v = 1 - (2 * (j + 0.5)) / D; // up is +v
      for (let i = 0; i < D; i++) {
        const u = (2 * (i + 0.5)) / D - 1;
        if (u * u + v * v > 1) continue;
        const k = this.nearest(u, v);
        if (k < 0) continue;
        const c = this.model.color(k), o = 4 * (i + D * j);
        img.data[o] = c[0];
        img.data[o + 1] = c[1];
        img.data[o + 2] = c[2];
        img.data[o + 3] = 255;
      }
    }
    octx.putImageData(img, 0, 0);
    ctx.drawImage(off, cx - R, cy - R, 2 * R, 2 * R);
    // Grid: zenith rings every 30°, azimuth spokes every 45°.
    ctx.strokeStyle = 'rgba(255,255,255,0.55)';
    ctx.lineWidth = 1;
    for (const th of [30, 60]) {
      ctx.beginPath();
      ctx.arc(cx, cy, (R * th) / 90, 0, 2 * Math.PI);
      ctx.stroke();
    }
    for (let a = 0; a < 360; a += 45) {
      const t = (a * Math.PI) / 180;
      ctx.beginPath();
      ctx.moveTo(cx, cy);
      ctx.lineTo(cx + R * Math.cos(t), cy - R * Math.sin(t));
      ctx.stroke();
    }
    ctx.strokeStyle = '#555';
    ctx.beginPath();
    ctx.arc(cx, cy, R, 0, 2 * Math.PI);
    ctx.stroke();
    ctx.fillStyle = '#1d232b';
    ctx.font = '11px system-ui, sans-serif';
    ctx.textAlign = 'center';
    ctx.textBaseline = 'middle';
    const names = { 0: '0° (+x)', 90: '90° (+y)', 180: '180°', 270: '270°' };
    for (let a = 0; a < 360; a += 45) {
      const t = (a * Math.PI) / 180, rr = R + 22;
      ctx.fillText(names[a] || a + '°', cx + rr * Math.cos(t), cy - rr * Math.sin(t));
    }
    ctx.fillStyle = 'rgba(255,255,255,0.9)';
    ctx.textAlign = 'left';
    for (const th of [30, 60, 90]) ctx.fillText(`θ ${th}°`, cx + (R * th) / 90 + 3, cy + 8);
    // For the tests and the hover read-out: where the plot is, in CSS pixels.
    this.canvas.dataset.cx = cx;
    this.canvas.dataset.cy = cy;
    this.canvas.dataset.r = R;
    this.canvas.dataset.kind = 'polar';
  }

  // Film pixel under a pointer at CSS (x, y), or -1 outside the disk.
  pick(x, y) {
    const u = (x - this.cx) / this.R, v = (this.cy - y) / this.R;
    return u * u + v * v > 1 ? -1 : this.nearest(u, v);
  }
}

// ---- principal plane: value against signed viewing zenith ------------------
// Directions whose azimuth lies within 90° of φ₀ (the azimuth of the first
// off-nadir pixel) get +θ, the others -θ: the usual BRF plot of a
// principal plane, -90° … 90°.
export class PlanePlot {
  constructor(canvas, film, series, unit) {
    this.canvas = canvas;
    this.film = film;
    this.series = series; // [{name, color, values: per pixel}]
    this.unit = unit;
    const m = film.meta, n = film.width * film.height;
    let phi0 = null;
    for (let k = 0; k < n && phi0 === null; k++) if (m.zenith_deg[k] > 1e-6) phi0 = m.azimuth_deg[k];
    this.phi0 = phi0 || 0;
    this.x = new Float64Array(n);
    this.inPlane = true;
    for (let k = 0; k < n; k++) {
      const d = ((m.azimuth_deg[k] - this.phi0) * Math.PI) / 180;
      this.x[k] = Math.cos(d) >= 0 ? m.zenith_deg[k] : -m.zenith_deg[k];
      if (m.zenith_deg[k] > 1e-6 && Math.abs(Math.sin(d)) > 0.02) this.inPlane = false;
    }
    this.order = Array.from({ length: n }, (_, k) => k).sort((a, b) => this.x[a] - this.x[b]);
  }

  draw() {
    const W = 560, H = 360, L = 64, Rm = 16, T = 16, B = 44;
    this.box = { L, T, w: W - L - Rm, h: H - T - B };
    const ctx = hiDpi(this.canvas, W, H);
    ctx.clearRect(0, 0, W, H);
    let hi = 0;
    for (const s of this.series) for (const v of s.values) if (Number.isFinite(v)) hi = Math.max(hi, v);
    if (!(hi > 0)) hi = 1;
    const yt = ticks(0, hi * 1.05, 5);
    this.ymax = yt[yt.length - 1] < hi ? hi * 1.05 : yt[yt.length - 1];
    const X = (x) => L + ((x + 90) / 180) * this.box.w, Y = (y) => T + this.box.h * (1 - y / this.ymax);
    this.X = X;
    this.Y = Y;
    ctx.font = '11px system-ui, sans-serif';
    ctx.strokeStyle = '#e3e6ea';
    ctx.fillStyle = '#1d232b';
    ctx.textAlign = 'center';
    ctx.textBaseline = 'top';
    for (let x = -90; x <= 90; x += 30) {
      ctx.beginPath();
      ctx.moveTo(X(x), T);
      ctx.lineTo(X(x), T + this.box.h);
      ctx.stroke();
      ctx.fillText(x + '°', X(x), T + this.box.h + 5);
    }
    ctx.textAlign = 'right';
    ctx.textBaseline = 'middle';
    for (const y of yt) {
      if (y > this.ymax) continue;
      ctx.beginPath();
      ctx.moveTo(L, Y(y));
      ctx.lineTo(L + this.box.w, Y(y));
      ctx.stroke();
      ctx.fillText(fmt(y), L - 6, Y(y));
    }
    ctx.strokeStyle = '#555';
    ctx.strokeRect(L + 0.5, T + 0.5, this.box.w, this.box.h);
    ctx.textAlign = 'center';
    ctx.textBaseline = 'bottom';
    ctx.fillText(`signed viewing zenith θ (°), + towards φ = ${fmt(this.phi0)}°`, L + this.box.w / 2, H - 2);
    ctx.save();
    ctx.translate(12, T + this.box.h / 2);
    ctx.rotate(-Math.PI / 2);
    ctx.textBaseline = 'middle';
    ctx.fillText(this.unit, 0, 0);
    ctx.restore();
    for (const s of this.series) {
      ctx.strokeStyle = s.color;
      ctx.fillStyle = s.color;
      ctx.lineWidth = 1.6;
      ctx.beginPath();
      this.order.forEach((k, i) => (i ? ctx.lineTo(X(this.x[k]), Y(s.values[k])) : ctx.moveTo(X(this.x[k]), Y(s.values[k]))));
      ctx.stroke();
      for (const k of this.order) {
        ctx.beginPath();
        ctx.arc(X(this.x[k]), Y(s.values[k]), 2.5, 0, 2 * Math.PI);
        ctx.fill();
      }
    }
    this.canvas.dataset.kind = 'plane';
    this.canvas.dataset.x0 = X(-90); // for the tests: where -90° and +90° are, in CSS pixels
    this.canvas.dataset.x1 = X(90);
  }

  pick(x) {
    let best = -1, bd = Infinity;
    for (let k = 0; k < this.x.length; k++) {
      const d = Math.abs(this.X(this.x[k]) - x);
      if (d < bd) (bd = d), (best = k);
    }
    return bd < 12 ? best : -1;
  }
}
