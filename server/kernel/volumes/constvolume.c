/* `constvolume`: one value everywhere (Mitsuba's constvolume; also what
 * ld_volume makes of a number or spectrum). `value` is a spectrum (number,
 * rgb, uniform or, in mono, tabulated), default 1; its parameter key is
 * `value.value` (the uniform spectrum's `value`), so a homogeneous
 * medium's extinction is `<medium>.sigma_t.value.value` as in Mitsuba.
 *
 * As a grid it is one cell (res 1 x 1 x 1) of 1 (mono) or 3 (rgb)
 * channels, refreshed by prepare() at the render's wavelength.
 *
 * Source: mitsuba3 src/volumes/const.cpp. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "../textures/texture.h"
#include "volume.h"

typedef struct constvolume {
  volume base;
  texture *value; /* a uniform texture */
  double cell[3];
  /* A bundle of pages: pages 1.. (prepare; volume_ops.page_data) */
  double cellp[RENDER_MAX_PAGES - 1][3];
  int pages;
} constvolume;

static color constvolume_eval(const volume *v, vec3 p) {
  (void)p;
  return tex_eval(((const constvolume *)v)->value, NULL);
}

static void constvolume_value_range(const volume *v, double *lo, double *hi) {
  const spectrum *s = uniform_texture_spectrum(((const constvolume *)v)->value);
  const double *x = &s->value;
  size_t n = 1;
  if (s->kind == SPEC_RGB) x = s->rgb, n = 3;
  if (s->kind == SPEC_TABLE) x = s->val, n = s->n;
  *lo = INFINITY, *hi = -INFINITY;
  for (size_t i = 0; i < n; i++) *lo = fmin(*lo, x[i]), *hi = fmax(*hi, x[i]);
}

static const double *constvolume_page_data(const volume *v, int p) {
  const constvolume *c = (const constvolume *)v;
  return p > 0 && p < c->pages ? c->cellp[p - 1] : c->cell;
}

static const volume_ops constvolume_ops = {
    .eval = constvolume_eval, .value_range = constvolume_value_range, .page_data = constvolume_page_data};

/* The cell and max from the texture's current value (prepared before the
 * volume: a texture is created, and so prepared, before its holder). */
static void constvolume_refresh(constvolume *c) {
  color x = tex_eval(c->value, NULL);
  double m = c->base.channels == 3 ? col_max(x) : x.c[0];
  if (memcmp(c->cell, x.c, sizeof c->cell) != 0 || m != c->base.max) c->base.revision++;
  for (int k = 0; k < 3; k++) c->cell[k] = x.c[k];
  c->base.max = m;
}

static rsw_status constvolume_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  (void)err;
  constvolume *c = (constvolume *)o;
  c->base.channels = rc->variant == VARIANT_RGB || rc->bundle > 1 ? 3 : 1;
  constvolume_refresh(c);
  c->pages = rc_pages(rc);
  for (int p = 1; p < c->pages; p++) { /* (the texture answers at rsw_page) */
    rsw_page = p;
    color x = tex_eval(c->value, NULL);
    rsw_page = 0;
    for (int k = 0; k < 3; k++) c->cellp[p - 1][k] = x.c[k];
    c->base.max = fmax(c->base.max, c->base.channels == 3 ? col_max(x) : x.c[0]);
  }
  return RSW_OK;
}

/* Its value depends on the wavelength where its spectrum does. */
static bool constvolume_spectral(const object *o) {
  const texture *t = ((const constvolume *)o)->value;
  return t->base.plugin && t->base.plugin->spectral && t->base.plugin->spectral(&t->base);
}

static void constvolume_traverse(object *o, param_visitor *v) {
  constvolume *c = (constvolume *)o;
  pv_object(v, "value", &c->value->base, c->base.lo, c->base.hi);
  volume_traverse_to_world(&c->base, v);
}

static void constvolume_parameters_changed(object *o) {
  volume_update_bbox((volume *)o);
}

/* A bundle of pages: eval answers at the page rsw_page names (its uniform
 * texture keeps a value per page), page_data gives each page's cell, and
 * max is the largest over the pages. */
DEFINE_PLUGIN(constvolume, CLS_VOLUME, .prepare = constvolume_prepare, .ops = &constvolume_ops,
              .traverse = constvolume_traverse, .parameters_changed = constvolume_parameters_changed,
              .spectral = constvolume_spectral, .pages = plugin_pages_any);

static volume *constvolume_make(texture *value, rsw_variant variant, const xform *to_world, const char *id) {
  constvolume *c = PLUGIN_NEW(constvolume, constvolume);
  if (!c) return NULL;
  volume_init(&c->base, &constvolume_ops, to_world);
  c->base.base.id = id;
  c->value = value;
  c->base.res[0] = c->base.res[1] = c->base.res[2] = 1;
  c->base.channels = variant == VARIANT_RGB ? 3 : 1;
  c->base.data = c->cell;
  c->pages = 1;
  const spectrum *s = uniform_texture_spectrum(value);
  if (s && s->kind != SPEC_TABLE) constvolume_refresh(c); /* a table waits for prepare() */
  return &c->base;
}

volume *constvolume_new(texture *value, rsw_variant variant, const char *id) {
  xform id_xf = xf_identity();
  return constvolume_make(value, variant, &id_xf, id);
}

static rsw_status constvolume_create(loader *ld, node *n, object **out) {
  texture *t;
  rsw_status st = ld_texture(ld, n, "value", 1.0, -INFINITY, &t);
  if (st) return st;
  if (!uniform_texture_spectrum(t))
    return ld_fail(ld, n, "value", RSW_ERR_TYPE,
                   "property 'value' must be a spectrum (number, rgb, spectrum), not the texture plugin '%s'",
                   t->base.plugin->name);
  xform xf;
  st = volume_read_to_world(ld, n, &xf);
  if (st) return st;
  volume *v = constvolume_make(t, ld->variant, &xf, n->id);
  return plugin_created(ld, n, v ? &v->base : NULL, out);
}

/* ---- ld_volume (scene/loader.h) ------------------------------------------------ */

/* Mitsuba's props.volume(): a number, an rgb triple or a spectrum (or a
 * nested uniform texture) becomes a constvolume; a nested or referenced
 * volume is taken as it is. */
static const char *range_text(double lo, double hi, char *buf, size_t len) {
  if (isinf(hi))
    snprintf(buf, len, ">= %g", lo);
  else if (isinf(lo))
    snprintf(buf, len, "<= %g", hi);
  else
    snprintf(buf, len, "in [%g, %g]", lo, hi);
  return buf;
}

static rsw_status get_volume(loader *ld, node *n, const char *name, double def, double lo, double hi,
                             bool mapped, volume **out) {
  prop *p = node_find(n, name);
  volume *v = NULL;
  bool nested_texture = false;
  if (p && p->kind == PROP_NODE) {
    const plugin *pl = ld_find_plugin(ld, p->child->type);
    nested_texture = pl && pl->cls == CLS_TEXTURE;
  }
  if (p && (p->kind == PROP_NODE || p->kind == PROP_REF) && !nested_texture) {
    object *o;
    rsw_status st = ld_child(ld, n, name, CLS_VOLUME, &o);
    if (st) return st;
    v = (volume *)o;
    if (!v->box_grid && !mapped)
      return ld_fail(
          ld, n, name, RSW_ERR_TYPE,
          "property '%s' reads a grid over a box (a gridvolume, a constvolume or a number), not the "
          "%s '%s' (a heterogeneous medium's sigma_t or albedo, or a blend weight, takes it)",
          name, o->plugin->name, o->id ? o->id : "");
  } else {
    /* A constant: a uniform texture wrapped in a constvolume. ld_texture
     * checks the lower bound of constants and the type. */
    texture *t;
    rsw_status st = ld_texture(ld, n, name, def, isinf(lo) ? -INFINITY : lo, &t);
    if (st) return st;
    if (!uniform_texture_spectrum(t))
      return ld_fail(
          ld, n, name, RSW_ERR_TYPE,
          "property '%s' must be a number, a spectrum or a volume (a constvolume holds spectra, not "
          "the texture plugin '%s')",
          name, t->base.plugin->name);
    v = constvolume_new(t, ld->variant, n->id);
    if (!v) return ld_fail(ld, n, name, RSW_ERR_NOMEM, "out of memory");
    st = ld_adopt(ld, &v->base);
    if (st) return st;
  }
  double vlo, vhi;
  v->ops->value_range(v, &vlo, &vhi);
  char want[96];
  if (vlo < lo || vhi > hi) {
    if (vlo == vhi)
      return ld_fail(ld, n, name, RSW_ERR_RANGE, "property '%s' must be %s (got %g)", name,
                     range_text(lo, hi, want, sizeof want), vlo);
    return ld_fail(ld, n, name, RSW_ERR_RANGE, "property '%s': values must be %s (the volume holds %g to %g)",
                   name, range_text(lo, hi, want, sizeof want), vlo, vhi);
  }
  /* A volume shared by several slots must satisfy all of them, now and
   * on every update. */
  for (volume *w = v; w; w = w->inner) { /* (and the volumes it reads through) */
    w->lo = fmax(w->lo, lo);
    w->hi = fmin(w->hi, hi);
  }
  *out = v;
  return RSW_OK;
}

rsw_status ld_volume(loader *ld, node *n, const char *name, double def, double lo, double hi, volume **out) {
  return get_volume(ld, n, name, def, lo, hi, false, out);
}

rsw_status ld_volume_mapped(loader *ld, node *n, const char *name, double def, double lo, double hi,
                            volume **out) {
  return get_volume(ld, n, name, def, lo, hi, true, out);
}
