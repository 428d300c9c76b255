/* `gridvolume`: values on a regular grid over the unit cube under
 * to_world (Mitsuba's gridvolume).
 *
 * The grid comes from exactly one of
 *   - `data` (a list of numbers, or a string of them) with `shape`
 *     [Z, Y, X] or [Z, Y, X, C]: Mitsuba's tensor layout, x fastest, so
 *     Eradiate's 1-D layers along z are shape [N, 1, 1];
 *   - `filename`: a Mitsuba .vol binary grid (through the scene's
 *     resolver: a path or a `sha256:` blob): "VOL", version 3, int32
 *     encoding 1 (float32), int32 xres, yres, zres, channels, six float32
 *     of bounding box (min xyz, max xyz), then the values, x fastest.
 * C (channels) is 1 or 3. In mono, `wavelengths` (nm, increasing) makes
 * every cell a tabulated spectrum: data then holds Z Y X K values, K =
 * len(wavelengths), the spectral axis last (shape [Z, Y, X] or
 * [Z, Y, X, K]); prepare() interpolates each cell at the render's
 * wavelength (outside the table is an error, as for every spectrum): for
 * a spectral bundle (render_ctx.bundle > 1) into 3 channels, channel c at
 * the bundle's c-th wavelength, and for a bundle of pages one such grid
 * per page (volume_ops.page_data; eval answers at the page rsw_page
 * names). A 3-channel grid in mono is seen as its luminance, as rgb
 * spectra are.
 *
 * Evaluation: `filter_type` "trilinear" (default; cell centres at
 * (i + 1/2) / res) or "nearest"; `wrap_mode` "clamp" (default), "repeat"
 * or "mirror" for points outside the box. `use_grid_bbox` (default
 * false) places the file's bounding box under to_world. `max_value`
 * fixes `max` (what majorants use) instead of the largest value; every
 * value must then stay at or below it (checked at load and on update).
 * Mitsuba's `raw` and `accel` are accepted and change nothing here (they
 * act in spectral and CUDA variants only).
 *
 * Parameters: `data` (the values as given, a spectral update of fixed
 * length, each in the range the slots holding the volume allow:
 * sigma_t >= 0, albedo in [0, 1]) and `to_world`; parameters_changed
 * refreshes the evaluated grid and max.
 *
 * Source: mitsuba3 src/volumes/grid.cpp, include/mitsuba/render/
 * volumegrid.h (.vol layout); eradiate's piecewise tests (layers as
 * [N, 1, 1]). */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "rsw_file.h"
#include "volume.h"

typedef enum grid_filter {
  FILTER_TRILINEAR,
  FILTER_NEAREST
} grid_filter;
typedef enum grid_wrap {
  WRAP_CLAMP = VOLUME_WRAP_CLAMP,
  WRAP_REPEAT = VOLUME_WRAP_REPEAT,
  WRAP_MIRROR = VOLUME_WRAP_MIRROR
} grid_wrap;

typedef struct gridvolume {
  volume base;
  double *src; /* the values as given: cells x src_ch (owned) */
  size_t n_src;
  uint32_t src_ch; /* channels, or K with wavelengths */
  double *wl;      /* K wavelengths (owned), or NULL */
  size_t n_wl;
  /* The evaluated grid (tables, luminance), or NULL: data is src. Tables:
   * `pages` grids of cells x channels, page p's channel c at
   * prepared_wl[3 p + c] (channels 1: prepared_wl[0]). */
  double *grid;
  size_t grid_cap; /* doubles allocated for grid */
  grid_filter filter;
  grid_wrap wrap;
  double prepared_wl[3 * RENDER_MAX_PAGES]; /* (NAN: never evaluated) */
  int pages;
  double fixed_max; /* max_value, or NAN */
  char *where;      /* the document location of the values (owned) */
} gridvolume;

static size_t cells_of(const volume *v) {
  return (size_t)v->res[0] * v->res[1] * v->res[2];
}

static int wrap_index(int i, int n, grid_wrap w) {
  return volume_wrap_index(i, n, (int)w);
}

/* The values at page p (volume_ops.page_data): a table's grid of that
 * page; other grids hold the same values at every wavelength. */
static const double *gridvolume_page_data(const volume *v, int p) {
  const gridvolume *g = (const gridvolume *)v;
  if (!g->wl || p <= 0 || p >= g->pages) return v->data;
  return g->grid + (size_t)p * cells_of(v) * v->channels;
}

static color cell(const volume *v, int ix, int iy, int iz) {
  const double *d = rsw_page ? gridvolume_page_data(v, rsw_page) : v->data;
  d += (((size_t)iz * v->res[1] + iy) * v->res[0] + ix) * v->channels;
  return v->channels == 3 ? col(d[0], d[1], d[2]) : col1(d[0]);
}

/* A coordinate far outside the box is brought back before the float ->
 * int conversion (clamp: any index past the end is the end; repeat and
 * mirror: periodic in 2 res). */
static double fold(double x, int n, grid_wrap w) {
  if (fabs(x) < 1e9) return x;
  if (w == WRAP_CLAMP) return x < 0 ? -1.0 : (double)n;
  return fmod(x, 2.0 * n);
}

/* A nearest-filtered [1, 1, N] profile (Eradiate's layers, blendphase's
 * weight) under an affine to_world: its x and y indices are 0 whatever
 * the point (one cell: every wrap mode gives 0), and xf_inv_point's z is
 * the inverse's third row applied to p (its w is exactly 1 for a finite
 * p), so only z is computed; the cell is gridvolume_eval's, bit for bit.
 * False: not such a grid or point. */
static bool layer_cell(const gridvolume *g, vec3 p, color *out) {
  const volume *v = &g->base;
  const double(*m)[4] = v->to_world.inv;
  if (g->filter != FILTER_NEAREST || v->res[0] != 1 || v->res[1] != 1 || m[3][0] != 0.0 || m[3][1] != 0.0 ||
      m[3][2] != 0.0 || m[3][3] != 1.0 || !isfinite(p.x) || !isfinite(p.y) || !isfinite(p.z))
    return false;
  int n = (int)v->res[2];
  double z = m[2][0] * p.x + m[2][1] * p.y + m[2][2] * p.z + m[2][3];
  double c = fold(z * n, n, g->wrap);
  *out = cell(v, 0, 0, wrap_index((int)floor(isfinite(c) ? c : 0.0), n, g->wrap));
  return true;
}

static color gridvolume_eval(const volume *v, vec3 p) {
  const gridvolume *g = (const gridvolume *)v;
  color lc;
  if (layer_cell(g, p, &lc)) return lc;
  vec3 q = xf_inv_point(&v->to_world, p);
  double x[3] = {q.x, q.y, q.z};
  int n[3] = {(int)v->res[0], (int)v->res[1], (int)v->res[2]};
  if (g->filter == FILTER_NEAREST) {
    int i[3];
    for (int a = 0; a < 3; a++) {
      double c = fold(x[a] * n[a], n[a], g->wrap);
      i[a] = wrap_index((int)floor(isfinite(c) ? c : 0.0), n[a], g->wrap);
    }
    return cell(v, i[0], i[1], i[2]);
  }
  int i0[3], i1[3];
  double f[3];
  for (int a = 0; a < 3; a++) {
    if (n[a] == 1) { /* one cell along a (a [1, 1, N] profile): weight 1 on it, exactly */
      f[a] = 0.0;
      i0[a] = i1[a] = 0;
      continue;
    }
    double c = fold(x[a] * n[a] - 0.5, n[a], g->wrap);
    if (!isfinite(c)) c = 0.0;
    double fl = floor(c);
    f[a] = c - fl;
    i0[a] = wrap_index((int)fl, n[a], g->wrap);
    i1[a] = wrap_index((int)fl + 1, n[a], g->wrap);
  }
  color r = col1(0.0);
  for (int k = 0; k < 8; k++) {
    double w = (k & 1 ? f[0] : 1 - f[0]) * (k & 2 ? f[1] : 1 - f[1]) * (k & 4 ? f[2] : 1 - f[2]);
    if (w == 0.0) continue;
    color c = cell(v, k & 1 ? i1[0] : i0[0], k & 2 ? i1[1] : i0[1], k & 4 ? i1[2] : i0[2]);
    r = col_add(r, col_scale(c, w));
  }
  return r;
}

static void gridvolume_value_range(const volume *v, double *lo, double *hi) {
  const gridvolume *g = (const gridvolume *)v;
  *lo = INFINITY, *hi = -INFINITY;
  for (size_t i = 0; i < g->n_src; i++) *lo = fmin(*lo, g->src[i]), *hi = fmax(*hi, g->src[i]);
}

static const volume_ops gridvolume_ops = {
    .eval = gridvolume_eval, .value_range = gridvolume_value_range, .page_data = gridvolume_page_data};

/* The tables at wavelength wl into channel c of the cells x ch values at
 * out. wl must lie in the table. */
static void evaluate_at(const gridvolume *g, double wl, double *out, size_t ch, size_t c) {
  size_t cells = cells_of(&g->base);
  size_t lo = 0, hi = g->n_wl - 1;
  while (hi - lo > 1) {
    size_t mid = (lo + hi) / 2;
    if (g->wl[mid] <= wl)
      lo = mid;
    else
      hi = mid;
  }
  double t = (wl - g->wl[lo]) / (g->wl[hi] - g->wl[lo]);
  for (size_t i = 0; i < cells; i++) {
    const double *s = g->src + i * g->src_ch;
    out[i * ch + c] = s[lo] + t * (s[hi] - s[lo]);
  }
}

/* The evaluated grid: the tables at prepared_wl (each page's grid, each
 * channel's wavelength; never prepared: nothing to do) or the luminance
 * (3 channels in mono), then max over every page. */
static void evaluate(gridvolume *g) {
  size_t cells = cells_of(&g->base);
  size_t n = cells * g->base.channels;
  if (g->wl) {
    if (isnan(g->prepared_wl[0])) {
      g->base.revision++;
      return;
    }
    for (int p = 0; p < g->pages; p++)
      for (uint32_t c = 0; c < g->base.channels; c++)
        evaluate_at(g, g->prepared_wl[3 * p + c], g->grid + (size_t)p * n, g->base.channels, c);
    n *= (size_t)g->pages;
  } else if (g->grid) {
    for (size_t i = 0; i < cells; i++) {
      const double *s = g->src + 3 * i;
      g->grid[i] = col_luminance(col(s[0], s[1], s[2]));
    }
  }
  const double *d = g->grid ? g->grid : g->base.data;
  double m = -INFINITY;
  for (size_t i = 0; i < n; i++) m = fmax(m, d[i]);
  g->base.max = isnan(g->fixed_max) ? m : g->fixed_max;
  g->base.revision++;
}

static rsw_status gridvolume_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  gridvolume *g = (gridvolume *)o;
  if (!g->wl) return RSW_OK; /* luminance and plain grids follow the values (parameters_changed) */
  /* One channel at the render's wavelength, or a bundle's 3 channels per
   * page (render_ctx: channel c of page p at rc_page(rc, p).wl[c]). */
  int pages = rc_pages(rc);
  uint32_t ch = rc->bundle > 1 ? 3 : 1;
  double wl[3 * RENDER_MAX_PAGES];
  for (int p = 0; p < pages; p++) {
    render_ctx pc = rc_page(rc, p);
    for (uint32_t c = 0; c < 3; c++) {
      double w = wl[3 * p + c] = ch == 3 ? rc_channel_wavelength(&pc, (int)c) : rc->wavelength;
      if (!(w >= g->wl[0] && w <= g->wl[g->n_wl - 1]))
        return rsw_fail(err, RSW_ERR_RANGE, g->where,
                        "wavelength %g nm lies outside the grid's spectral table [%g, %g] nm", w, g->wl[0],
                        g->wl[g->n_wl - 1]);
    }
  }
  if (ch == g->base.channels && pages == g->pages && memcmp(wl, g->prepared_wl, 3 * pages * sizeof *wl) == 0)
    return RSW_OK;
  size_t need = cells_of(&g->base) * ch * (size_t)pages;
  if (need > g->grid_cap) {
    double *grid = realloc(g->grid, need * sizeof *grid);
    if (!grid) return rsw_fail(err, RSW_ERR_NOMEM, g->where, "out of memory for the grid at its wavelengths");
    g->grid = grid;
    g->grid_cap = need;
    g->base.data = grid;
  }
  g->base.channels = ch;
  g->pages = pages;
  memcpy(g->prepared_wl, wl, 3 * pages * sizeof *wl);
  evaluate(g);
  return RSW_OK;
}

static void gridvolume_parameters_changed(object *o) {
  gridvolume *g = (gridvolume *)o;
  volume_update_bbox(&g->base);
  /* The data changed (or only to_world: then this recomputes the same
   * grid). Tables are re-evaluated at the wavelengths of the last
   * prepare(), or wait for the next one. */
  evaluate(g);
}

/* The slot's range (lo, hi of the volume) travels with the key. */
/* A grid with a wavelength axis (values along it are not compared: the
 * axis is there to be read). */
static bool gridvolume_spectral(const object *o) {
  return ((const gridvolume *)o)->n_wl > 1;
}

static void gridvolume_traverse(object *o, param_visitor *v) {
  gridvolume *g = (gridvolume *)o;
  double hi = isnan(g->fixed_max) ? g->base.hi : fmin(g->base.hi, g->fixed_max);
  pv_buffer(v, "data", g->src, g->n_src, UPDATE_SPECTRAL, g->base.lo, hi, NULL);
  volume_traverse_to_world(&g->base, v);
}

static void gridvolume_destroy(object *o) {
  gridvolume *g = (gridvolume *)o;
  if (!g) return;
  free(g->src);
  free(g->wl);
  free(g->grid);
  free(g->where);
  free(g);
}

/* ---- loading ------------------------------------------------------------------ */

static uint32_t rd_u32(const unsigned char *b) {
  return (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
}
static float rd_f32(const unsigned char *b) {
  uint32_t u = rd_u32(b);
  float f;
  memcpy(&f, &u, sizeof f);
  return f;
}

/* Read a .vol file: res, channels, its bbox and the values as doubles. */
static rsw_status read_vol(loader *ld, node *n, const char *path, gridvolume *g, double bbox[6]) {
  const char *name = "filename";
  FILE *f = rsw_fopen_regular(path, "rb");
  if (!f)
    return ld_fail(ld, n, name, RSW_ERR_FILE, "cannot open the volume file '%s': %s", path,
                   rsw_open_strerror(errno));
  unsigned char h[48] = {0};
  rsw_status st = RSW_OK;
  if (fread(h, 1, sizeof h, f) != sizeof h) {
    st =
        ld_fail(ld, n, name, RSW_ERR_PARSE, "'%s' is not a .vol grid: shorter than its 48-byte header", path);
  } else if (memcmp(h, "VOL", 3) != 0 || h[3] != 3) {
    st = ld_fail(ld, n, name, RSW_ERR_PARSE,
                 "'%s' is not a .vol grid (version 3): it does not start with \"VOL\\3\"", path);
  } else if (rd_u32(h + 4) != 1) {
    st = ld_fail(ld, n, name, RSW_ERR_UNSUPPORTED,
                 "'%s': .vol encoding %u is not supported (1, float32, is; as in Mitsuba 3)", path,
                 rd_u32(h + 4));
  }
  uint32_t res[3] = {rd_u32(h + 8), rd_u32(h + 12), rd_u32(h + 16)}, ch = rd_u32(h + 20);
  size_t cells = 0;
  if (!st) {
    if (!res[0] || !res[1] || !res[2] || res[0] > (1u << 24) || res[1] > (1u << 24) || res[2] > (1u << 24))
      st = ld_fail(ld, n, name, RSW_ERR_PARSE, "'%s': bad resolution %u x %u x %u", path, res[0], res[1],
                   res[2]);
    else if (ch != 1 && ch != 3)
      st = ld_fail(ld, n, name, RSW_ERR_UNSUPPORTED, "'%s': %u channels (a volume holds 1 or 3)", path, ch);
  }
  if (!st) {
    cells = (size_t)res[0] * res[1] * res[2];
    if (cells > VOLUME_MAX_VALUES / ch)
      st = ld_fail(ld, n, name, RSW_ERR_LIMIT, "'%s': %zu values (at most %zu)", path, cells * ch,
                   VOLUME_MAX_VALUES);
  }
  if (!st) {
    for (int k = 0; k < 6; k++) bbox[k] = rd_f32(h + 24 + 4 * k);
    if (fseek(f, 0, SEEK_END) != 0 || ftell(f) != (long)(48 + 4 * cells * ch))
      st = ld_fail(ld, n, name, RSW_ERR_PARSE,
                   "'%s': %ld bytes, but its header announces %zu (48 + 4 x %zu values)", path, ftell(f),
                   48 + 4 * cells * ch, cells * ch);
    else
      fseek(f, 48, SEEK_SET);
  }
  if (!st) {
    g->n_src = cells * ch;
    g->src = malloc(g->n_src * sizeof(double));
    unsigned char *buf = malloc(g->n_src * 4);
    if (!g->src || !buf)
      st = ld_fail(ld, n, name, RSW_ERR_NOMEM, "out of memory");
    else if (fread(buf, 4, g->n_src, f) != g->n_src)
      st = ld_fail(ld, n, name, RSW_ERR_IO, "'%s': read error", path);
    for (size_t i = 0; !st && i < g->n_src; i++) {
      g->src[i] = rd_f32(buf + 4 * i);
      if (!isfinite(g->src[i]))
        st = ld_fail(ld, n, name, RSW_ERR_INVALID, "'%s': value %zu (cell %zu, channel %zu) is not finite",
                     path, i, i / ch, i % ch);
    }
    free(buf);
    for (int k = 0; k < 3; k++) g->base.res[k] = res[k];
    g->src_ch = ch;
  }
  fclose(f);
  return st;
}

/* `data` + `shape` (+ `wavelengths`). */
static rsw_status read_inline(loader *ld, node *n, gridvolume *g) {
  double *shp;
  size_t ns;
  bool has_shape;
  rsw_status st = volume_read_numbers(ld, n, "shape", &shp, &ns, &has_shape);
  if (st) return st;
  if (!has_shape)
    return ld_fail(ld, n, NULL, RSW_ERR_MISSING,
                   "gridvolume '%s': 'data' needs 'shape' ([Z, Y, X] or [Z, Y, X, C])", n->id);
  if (ns != 3 && ns != 4) {
    free(shp);
    return ld_fail(ld, n, "shape", RSW_ERR_INVALID,
                   "property 'shape' must be [Z, Y, X] or [Z, Y, X, C], got %zu numbers", ns);
  }
  size_t dims[4] = {0, 0, 0, 1};
  for (size_t k = 0; k < ns; k++) {
    if (!(shp[k] >= 1 && shp[k] <= (1 << 24)) || shp[k] != floor(shp[k])) {
      double bad = shp[k];
      free(shp);
      return ld_fail(ld, n, "shape", RSW_ERR_INVALID,
                     "property 'shape': %g is not a positive whole number (entry %zu)", bad, k);
    }
    dims[k] = (size_t)shp[k];
  }
  free(shp);
  /* Mitsuba's [Z, Y, X, C] -> res (x, y, z). */
  g->base.res[0] = (uint32_t)dims[2];
  g->base.res[1] = (uint32_t)dims[1];
  g->base.res[2] = (uint32_t)dims[0];
  size_t cells = dims[0] * dims[1] * dims[2];
  if (cells > VOLUME_MAX_VALUES)
    return ld_fail(ld, n, "shape", RSW_ERR_LIMIT, "property 'shape': %zu cells (at most %zu)", cells,
                   VOLUME_MAX_VALUES);
  bool has_wl;
  st = volume_read_numbers(ld, n, "wavelengths", &g->wl, &g->n_wl, &has_wl);
  if (st) return st;
  if (has_wl) {
    if (ns == 4 && dims[3] != g->n_wl)
      return ld_fail(ld, n, "shape", RSW_ERR_INVALID,
                     "property 'shape': the last axis (%zu) must match the %zu wavelengths", dims[3],
                     g->n_wl);
    g->src_ch = (uint32_t)g->n_wl;
  } else {
    if (dims[3] != 1 && dims[3] != 3)
      return ld_fail(ld, n, "shape", RSW_ERR_UNSUPPORTED,
                     "property 'shape': %zu channels (a volume holds 1 or 3)", dims[3]);
    g->src_ch = (uint32_t)dims[3];
  }
  st = volume_read_numbers(ld, n, "data", &g->src, &g->n_src, NULL);
  if (st) return st;
  if (g->n_src != cells * g->src_ch)
    return ld_fail(ld, n, "data", RSW_ERR_INVALID,
                   "property 'data' holds %zu values, but shape %zu x %zu x %zu%s takes %zu", g->n_src,
                   dims[0], dims[1], dims[2],
                   has_wl           ? " with one value per wavelength"
                   : g->src_ch == 3 ? " x 3"
                                    : "",
                   cells * g->src_ch);
  return RSW_OK;
}

static rsw_status read_choice(loader *ld, node *n, const char *name, const char *const *names, int count,
                              int def, int *out) {
  const char *s;
  rsw_status st = ld_string(ld, n, name, names[def], &s);
  if (st) return st;
  for (int i = 0; i < count; i++)
    if (strcmp(s, names[i]) == 0) {
      *out = i;
      return RSW_OK;
    }
  return ld_fail(ld, n, name, RSW_ERR_INVALID, "property '%s': unknown value '%s' (%s, %s%s%s)", name, s,
                 names[0], names[1], count > 2 ? ", " : "", count > 2 ? names[2] : "");
}

static rsw_status gridvolume_fill(loader *ld, node *n, gridvolume *g) {
  bool has_data = ld_has(n, "data"), has_file = ld_has(n, "filename");
  if (has_data == has_file)
    return ld_fail(ld, n, NULL, has_data ? RSW_ERR_INVALID : RSW_ERR_MISSING,
                   "gridvolume '%s': give exactly one of 'data' (with 'shape') and 'filename'", n->id);
  static const char *const filters[] = {"trilinear", "nearest"};
  static const char *const wraps[] = {"clamp", "repeat", "mirror"};
  int f = 0, w = 0;
  rsw_status st = read_choice(ld, n, "filter_type", filters, 2, 0, &f);
  if (!st) st = read_choice(ld, n, "wrap_mode", wraps, 3, 0, &w);
  if (st) return st;
  g->filter = (grid_filter)f;
  g->wrap = (grid_wrap)w;
  g->base.wrap = w;
  g->base.trilinear = g->filter == FILTER_TRILINEAR;
  xform to_world;
  st = volume_read_to_world(ld, n, &to_world);
  if (st) return st;
  bool use_bbox, raw, accel;
  st = ld_bool(ld, n, "use_grid_bbox", false, &use_bbox);
  if (!st) st = ld_bool(ld, n, "raw", false, &raw);
  if (!st) st = ld_bool(ld, n, "accel", true, &accel);
  if (st) return st;
  g->fixed_max = NAN;
  if (ld_has(n, "max_value")) {
    st = ld_float(ld, n, "max_value", 0.0, &g->fixed_max);
    if (st) return st;
  }
  double bbox[6] = {0, 0, 0, 1, 1, 1};
  const prop *vp = node_find(n, has_data ? "data" : "filename");
  g->where = rsw_strdup(vp->loc);
  if (!g->where) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  if (has_file) {
    char *path;
    st = ld_path(ld, n, "filename", &path);
    if (st) return st;
    st = read_vol(ld, n, path, g, bbox);
    free(path);
    if (st) return st;
    if (ld_has(n, "wavelengths"))
      return ld_fail(ld, n, "wavelengths", RSW_ERR_UNSUPPORTED,
                     "property 'wavelengths' goes with inline 'data' (a .vol file holds 1 or 3 channels)");
  } else {
    if (use_bbox)
      return ld_fail(ld, n, "use_grid_bbox", RSW_ERR_INVALID,
                     "property 'use_grid_bbox' needs a .vol 'filename' (inline data has no bounding box)");
    st = read_inline(ld, n, g);
    if (st) return st;
  }
  if (use_bbox) {
    vec3 lo = v3(bbox[0], bbox[1], bbox[2]),
         ext = v3(bbox[3] - bbox[0], bbox[4] - bbox[1], bbox[5] - bbox[2]);
    if (!(ext.x > 0 && ext.y > 0 && ext.z > 0))
      return ld_fail(ld, n, "use_grid_bbox", RSW_ERR_INVALID,
                     "the .vol file's bounding box is empty or not finite");
    xform t = xf_translate(lo), s = xf_scale(ext);
    xform ts = xf_mul(&t, &s);
    to_world = xf_mul(&to_world, &ts);
  }
  if (g->wl) {
    if (ld->variant != VARIANT_MONO)
      return ld_fail(ld, n, "wavelengths", RSW_ERR_UNSUPPORTED,
                     "property 'wavelengths': tabulated spectra per cell need the mono variant");
    if (g->n_wl < 2)
      return ld_fail(ld, n, "wavelengths", RSW_ERR_INVALID,
                     "property 'wavelengths' needs at least 2 wavelengths (a table per cell)");
    for (size_t i = 0; i < g->n_wl; i++)
      if (!(g->wl[i] > 0) || (i && !(g->wl[i] > g->wl[i - 1])))
        return ld_fail(ld, n, "wavelengths", RSW_ERR_INVALID,
                       "property 'wavelengths' must be positive and strictly increasing");
  }
  if (!isnan(g->fixed_max)) {
    double lo, hi;
    gridvolume_value_range(&g->base, &lo, &hi);
    if (hi > g->fixed_max)
      return ld_fail(
          ld, n, "max_value", RSW_ERR_RANGE,
          "property 'max_value' (%g) is below the grid's largest value (%g): majorants would be wrong",
          g->fixed_max, hi);
  }
  volume_init(&g->base, &gridvolume_ops, &to_world);
  size_t cells = cells_of(&g->base);
  bool derived = g->wl || (ld->variant == VARIANT_MONO && g->src_ch == 3);
  if (derived) {
    g->grid = calloc(cells, sizeof(double));
    if (!g->grid) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
    g->grid_cap = cells;
  }
  g->base.channels = derived ? 1 : g->src_ch;
  g->base.data = derived ? g->grid : g->src;
  g->prepared_wl[0] = NAN;
  g->pages = 1;
  if (!g->wl) evaluate(g); /* tables wait for prepare() */
  return RSW_OK;
}

DEFINE_PLUGIN(gridvolume, CLS_VOLUME, .destroy = gridvolume_destroy, .prepare = gridvolume_prepare,
              .ops = &gridvolume_ops, .traverse = gridvolume_traverse, .spectral = gridvolume_spectral,
              .parameters_changed = gridvolume_parameters_changed, .pages = plugin_pages_any);

static rsw_status gridvolume_create(loader *ld, node *n, object **out) {
  gridvolume *g = PLUGIN_NEW(gridvolume, gridvolume);
  if (!g) return plugin_created(ld, n, NULL, out);
  rsw_status st = gridvolume_fill(ld, n, g);
  if (st) {
    gridvolume_destroy(&g->base.base);
    return st;
  }
  return plugin_created(ld, n, &g->base.base, out);
}
