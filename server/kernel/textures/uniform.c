/* `uniform` texture: one spectral value everywhere. Every spectrum property
 * of the document (number, rgb, uniform, tabulated) becomes one of these, as
 * in Mitsuba (docs/kernel-conventions.md#spectra-and-textures); prepare() evaluates it at the
 * render's wavelength (mono) or takes the rgb triple (rgb). */
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "texture.h"

typedef struct uniform_tex {
  texture base;
  spectrum spec; /* owned copy */
  color value;   /* current value (after prepare) */
  /* A bundle of pages (render_ctx.bundle > 3): the value at pages 1.. of
   * the last such prepare (page 0's is `value`), what eval answers while
   * rsw_page names one; allocated by the first (owned). */
  color *page;
  char *where; /* document location of the property it came from (owned) */
} uniform_tex;

static inline color uniform_at_page(const uniform_tex *u) {
  int p = rsw_page;
  return p ? u->page[p - 1] : u->value;
}

static color uniform_eval(const texture *t, const surface_interaction *si) {
  (void)si;
  return uniform_at_page((const uniform_tex *)t);
}

static color uniform_mean(const texture *t) {
  return uniform_at_page((const uniform_tex *)t);
}

static const texture_ops uniform_ops = {.eval = uniform_eval, .mean = uniform_mean};

static void uniform_destroy(object *o) {
  uniform_tex *u = (uniform_tex *)o;
  spectrum_free(&u->spec);
  free(u->where);
  free(u->page);
  free(u);
}

static rsw_status uniform_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  uniform_tex *u = (uniform_tex *)o;
  const char *where = u->where ? u->where : o->id;
  render_ctx pc = rc_page(rc, 0);
  rsw_status st = spectrum_eval(&u->spec, &pc, &u->value, err, where);
  if (!st && rc_pages(rc) > 1 && !u->page && !(u->page = malloc((RENDER_MAX_PAGES - 1) * sizeof *u->page)))
    return rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory");
  for (int p = 1; p < rc_pages(rc) && !st; p++) {
    pc = rc_page(rc, p);
    st = spectrum_eval(&u->spec, &pc, &u->page[p - 1], err, where);
  }
  return st;
}

static bool spectrum_copy(spectrum *dst, const spectrum *src);
/* A table whose values are not all equal. */
static bool uniform_spectral(const object *o) {
  const spectrum *s = &((const uniform_tex *)o)->spec;
  for (size_t i = 1; s->kind == SPEC_TABLE && i < s->n; i++)
    if (s->val[i] != s->val[0]) return true;
  return false;
}

/* Mitsuba's uniform spectrum reports its value as `value`. */
static void uniform_traverse(object *o, param_visitor *v) {
  pv_spectrum(v, "value", (texture *)o);
}

DEFINE_PLUGIN(uniform, CLS_TEXTURE, .destroy = uniform_destroy, .prepare = uniform_prepare,
              .ops = &uniform_ops, .traverse = uniform_traverse, .spectral = uniform_spectral,
              .pages = plugin_pages_any);

static bool spectrum_copy(spectrum *dst, const spectrum *src) {
  *dst = *src;
  dst->wl = dst->val = NULL;
  if (src->kind == SPEC_TABLE) {
    dst->wl = malloc(src->n * sizeof(double));
    dst->val = malloc(src->n * sizeof(double));
    if (!dst->wl || !dst->val) {
      spectrum_free(dst);
      return false;
    }
    memcpy(dst->wl, src->wl, src->n * sizeof(double));
    memcpy(dst->val, src->val, src->n * sizeof(double));
  }
  return true;
}

texture *uniform_texture_new(const spectrum *s, const char *id) {
  uniform_tex *u = calloc(1, sizeof *u);
  if (!u) return NULL;
  u->base.base.plugin = &plugin_uniform;
  u->base.base.id = id;
  u->base.ops = &uniform_ops;
  if (!spectrum_copy(&u->spec, s)) {
    free(u);
    return NULL;
  }
  if (s->kind == SPEC_UNIFORM) u->value = col1(s->value);
  if (s->kind == SPEC_RGB) u->value = col(s->rgb[0], s->rgb[1], s->rgb[2]);
  return &u->base;
}

texture *uniform_texture_const(double v, const char *id) {
  spectrum s = {.kind = SPEC_UNIFORM, .value = v};
  return uniform_texture_new(&s, id);
}

const spectrum *uniform_texture_spectrum(const texture *t) {
  if (t->base.plugin != &plugin_uniform) return NULL;
  return &((const uniform_tex *)t)->spec;
}

bool uniform_texture_set_spectrum(texture *t, const spectrum *s) {
  if (t->base.plugin != &plugin_uniform) return false;
  uniform_tex *u = (uniform_tex *)t;
  spectrum copy;
  if (!spectrum_copy(&copy, s)) return false;
  spectrum_free(&u->spec);
  u->spec = copy;
  if (s->kind == SPEC_UNIFORM) u->value = col1(s->value);
  if (s->kind == SPEC_RGB) u->value = col(s->rgb[0], s->rgb[1], s->rgb[2]);
  return true;
}

bool uniform_spectrum_copy(spectrum *out, const spectrum *s) {
  return spectrum_copy(out, s);
}

bool uniform_texture_swap_spectrum(texture *t, spectrum *s) {
  if (t->base.plugin != &plugin_uniform) return false;
  uniform_tex *u = (uniform_tex *)t;
  spectrum tmp = u->spec;
  u->spec = *s;
  *s = tmp;
  if (u->spec.kind == SPEC_UNIFORM) u->value = col1(u->spec.value);
  if (u->spec.kind == SPEC_RGB) u->value = col(u->spec.rgb[0], u->spec.rgb[1], u->spec.rgb[2]);
  return true;
}

bool uniform_texture_set_where(texture *t, const char *where) {
  if (t->base.plugin != &plugin_uniform) return false;
  uniform_tex *u = (uniform_tex *)t;
  free(u->where);
  u->where = rsw_strdup(where);
  return u->where != NULL;
}

bool uniform_texture_value(const texture *t, color *out) {
  if (t->base.plugin != &plugin_uniform) return false;
  *out = uniform_at_page((const uniform_tex *)t);
  return true;
}

/* {"type": "uniform", "value": x} as an object (Mitsuba's uniform spectrum
 * plugin); the JSON reader turns the common form into a spectrum property
 * already, this handles an explicit nested texture object. */
static rsw_status uniform_create(loader *ld, node *n, object **out) {
  prop *p = node_find(n, "value");
  if (!p) return ld_fail(ld, n, NULL, RSW_ERR_MISSING, "uniform: missing property 'value'");
  spectrum s = {.kind = SPEC_UNIFORM};
  if (p->kind == PROP_NUMBER) {
    s.value = p->num;
  } else if (p->kind == PROP_SPECTRUM) {
    s = p->spec; /* shallow: copied below */
  } else {
    return ld_fail(ld, n, "value", RSW_ERR_TYPE, "uniform: 'value' must be a number or a spectrum");
  }
  p->used = true;
  texture *t = uniform_texture_new(&s, n->id);
  if (!t) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  *out = &t->base;
  return RSW_OK;
}
