/* The scene plugin (what the document's root becomes: its children sorted
 * into shapes, emitters, sensors, the integrator), and what a built scene
 * answers and how it goes: preparing its objects for a render, finding a
 * sensor, freeing it. The assembly that builds it is scene/build.c. */
#include <errno.h>
#include <stdlib.h>
#include <string.h>

#include "../accel.h"
#include "loader.h"
#include "params.h"
#include "periodic.h"
#include "scene.h"

#include "../shapes/instance.h"

/* ---- the scene plugin --------------------------------------------------------------- */

static rsw_status push_ptr(void ***arr, size_t *n, void *p) {
  void **a = realloc(*arr, (*n + 1) * sizeof *a);
  if (!a) return RSW_ERR_NOMEM;
  a[(*n)++] = p;
  *arr = a;
  return RSW_OK;
}

static rsw_status add_emitter(loader *ld, scene *s, emitter *e, const char *where) {
  if (e->flags & EMITTER_INFINITE) {
    if (s->environment)
      return rsw_fail(ld->err, RSW_ERR_INVALID, where,
                      "only one environment emitter per scene ('%s' and '%s')", s->environment->base.id,
                      e->base.id);
    s->environment = e;
  }
  if (push_ptr((void ***)&s->emitters, &s->n_emitters, e))
    return rsw_fail(ld->err, RSW_ERR_NOMEM, where, "out of memory");
  return RSW_OK;
}

/* The scene's children: shapes (and their area emitters), emitters,
 * sensors, the integrator, a periodic boundary; other classes are declared
 * at the top level to be referenced. */
rsw_status scene_create(loader *ld, node *n, object **out) {
  scene *s = ld->scene;
  for (size_t i = 0; i < n->n_props; i++) {
    prop *p = &n->props[i];
    if (p->kind != PROP_NODE && p->kind != PROP_REF) continue;
    if (p->used) continue; /* synthetic defaults */
    node *t;
    obj_class c;
    rsw_status st = ld_prop_class(ld, n, p, &c, &t);
    if (st) return st;
    object *o;
    st = ld->hooks->build(ld, t, c, &o);
    if (st) return st;
    p = &n->props[i]; /* building may have grown the root's property array */
    p->used = true;
    switch (c) {
    case CLS_SHAPE: {
      shape *sh = (shape *)o;
      if (push_ptr((void ***)&s->shapes, &s->n_shapes, sh))
        return rsw_fail(ld->err, RSW_ERR_NOMEM, p->loc, "out of memory");
      if (sh->emitter) {
        st = add_emitter(ld, s, sh->emitter, p->loc);
        if (st) return st;
      }
      break;
    }
    case CLS_EMITTER:
      if (((emitter *)o)->flags & EMITTER_SURFACE)
        return rsw_fail(ld->err, RSW_ERR_INVALID, p->loc, "an area emitter must be nested in a shape");
      st = add_emitter(ld, s, (emitter *)o, p->loc);
      if (st) return st;
      break;
    case CLS_SENSOR:
      if (push_ptr((void ***)&s->sensors, &s->n_sensors, o))
        return rsw_fail(ld->err, RSW_ERR_NOMEM, p->loc, "out of memory");
      break;
    case CLS_INTEGRATOR:
      if (s->integrator) return rsw_fail(ld->err, RSW_ERR_DUPLICATE, p->loc, "a scene takes one integrator");
      s->integrator = (integrator *)o;
      break;
    case CLS_BSDF:
    case CLS_TEXTURE:
    case CLS_MEDIUM:
    case CLS_PHASE:
    case CLS_VOLUME:
    case CLS_EXTREMUM: break; /* declared at the top level to be referenced */
    case CLS_SCENE:
      if (o->plugin == &plugin_periodic) {
        if (s->periodic.on)
          return rsw_fail(ld->err, RSW_ERR_DUPLICATE, p->loc, "a scene takes one periodic boundary");
        s->periodic = *periodic_of(o);
        break;
      }
      return rsw_fail(ld->err, RSW_ERR_INVALID, p->loc, "a scene cannot be a child of the scene");
    default:
      return rsw_fail(ld->err, RSW_ERR_INVALID, p->loc,
                      "a %s cannot be a child of the scene (nest it in a sensor)", obj_class_name(c));
    }
  }
  *out = &s->base;
  return RSW_OK;
}

const plugin plugin_scene = {.name = "scene", .cls = CLS_SCENE, .create = scene_create};

rsw_status scene_prepare(scene *s, const render_ctx *rc, rsw_err *err) {
  s->pages = rc_pages(rc);
  for (size_t i = 0; i < s->n_objects; i++) {
    object *o = s->objects[i];
    if (o->plugin && o->plugin->prepare) {
      rsw_status st = o->plugin->prepare(o, rc, err);
      if (st) return st;
    }
  }
  return RSW_OK;
}

bool scene_wavelength_dependent(const scene *s) {
  for (size_t i = 0; i < s->n_objects; i++) {
    const object *o = s->objects[i];
    if (o->plugin && o->plugin->spectral && o->plugin->spectral(o)) return true;
  }
  return false;
}

size_t emitter_failures(const scene *s, int channel, char *msg, size_t len) {
  size_t total = 0;
  if (msg && len) msg[0] = 0;
  for (size_t i = 0; s && i < s->n_emitters; i++) {
    const emitter *e = s->emitters[i];
    if (!e->ops->failures) continue;
    total += e->ops->failures(e, channel, msg && len && !msg[0] ? msg : NULL, len);
  }
  return total;
}

const object *scene_page_blocker(const scene *s, const char **why) {
  if (s->integrator && !s->integrator->pages) {
    *why = "carries at most three wavelengths per path (`path`, `direct`, `volpath` and "
           "`piecewise_volpath` carry more)";
    return &s->integrator->base;
  }
  for (size_t i = 0; i < s->n_objects; i++) {
    const object *o = s->objects[i];
    const plugin *pl = o->plugin;
    if (!pl) continue;
    if (pl->prepare && !(pl->pages && pl->pages(o))) {
      *why = "prepares its values at one set of three wavelengths";
      return o;
    }
    /* A delta lobe carries pages where its BSDF says its value at each
     * page and the probability of drawing it (bsdf_ops.delta_value:
     * `plastic`, `dielectric`, `conductor`, `twosided` over them;
     * bsdf_sample_pages weights each page by its value over the pages'
     * mean probability), or where every page draws it alike
     * (bsdf_sample_pages samples every page again with the same numbers
     * and keeps its weight where it drew the same lobe and direction): a
     * BSDF without delta_value whose only lobe is one delta reflection
     * (the mirror direction, drawn with probability 1 at every page), or
     * index-matched (weight 1 at every wavelength). Compositions (blendbsdf,
     * selectbsdf, mask, twosided) say their parts' values and
     * probabilities towards the sampled direction (two delta
     * transmissions that refract apart count each towards its own); their
     * `pages` hook refuses a part whose delta lobe does not say its. */
    if (pl->cls == CLS_BSDF && pl->pages && !pl->pages(o)) { /* a composition (blendbsdf, mask, ...) */
      *why = "has a part whose delta lobe does not say its value per page";
      return o;
    }
    if (pl->cls == CLS_BSDF) {
      const bsdf *b = (const bsdf *)o;
      const unsigned lobes = BSDF_SMOOTH | BSDF_DELTA;
      bool one_mirror = (b->flags & lobes) == BSDF_DELTA_REFLECTION;
      if ((b->flags & BSDF_DELTA) && !(b->flags & BSDF_INDEX_MATCHED) && !one_mirror &&
          !b->ops->delta_value) {
        *why = "has a delta lobe: its sampling differs between a bundle's pages";
        return o;
      }
    }
  }
  return NULL;
}

sensor *scene_find_sensor(const scene *s, const char *id, size_t *index_out) {
  for (size_t i = 0; i < s->n_sensors; i++)
    if (strcmp(s->sensors[i]->base.id, id) == 0) {
      if (index_out) *index_out = i;
      return s->sensors[i];
    }
  char *end;
  errno = 0;
  unsigned long k = strtoul(id, &end, 10);
  if (id[0] >= '0' && id[0] <= '9' && !*end && !errno && k < s->n_sensors) {
    if (index_out) *index_out = k;
    return s->sensors[k];
  }
  return NULL;
}

void scene_free(scene *s) {
  if (!s) return;
  accel_free(s->accel);
  params_free(s->params);
  for (size_t i = s->n_objects; i-- > 0;) {
    object *o = s->objects[i];
    if (o == &s->base) continue;
    if (o->plugin && o->plugin->destroy) o->plugin->destroy(o);
  }
  free(s->objects);
  free(s->shapes);
  free(s->emitters);
  free(s->emitter_cdf);
  free(s->sensors);
  free(s->periodic_z);
  node_free(s->doc);
  free(s);
}

/* A plain shape's primitives: its triangles, or 1 (analytic). */
static size_t shape_primitives(const shape *sh) {
  return shape_is_mesh(sh) ? sh->mesh.n_faces : 1;
}

size_t scene_primitive_count(const scene *s) {
  size_t n = 0;
  for (size_t i = 0; i < s->n_shapes; i++) {
    const shape *sh = s->shapes[i];
    if (shape_is_group(sh)) {
      const shape_group *g = (const shape_group *)sh;
      for (size_t k = 0; k < g->n_members; k++) n += shape_primitives(g->members[k]);
    } else if (shape_is_instancing(sh)) {
      n += ((const instance_shape *)sh)->n;
    } else {
      n += shape_primitives(sh);
    }
  }
  return n;
}
