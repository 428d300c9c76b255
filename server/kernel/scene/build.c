/* The scene assembly: document tree -> object graph. Looks each node's
 * plugin up in the registry, builds it (its create() reads its properties
 * through scene/loader.c, and nested objects come back here through the
 * loader's hooks), rejects unused properties, and is the scene plugin
 * itself: it gathers the scene's children, builds the acceleration
 * structure and the parameter table, and loads scene files. It sits above
 * every plugin (tools/check-layers.py). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../accel.h"
#include "../core/strdist.h"
#include "../extplugin/env_plugin.h"
#include "../media/media.h"
#include "../shapes/instance.h"
#include "../textures/texture.h"
#include "loader.h"
#include "params.h"
#include "periodic.h"
#include "plugin_def.h"
#include "plugin_names.h"
#include "rsw_file.h"
#include "scene.h"

/* ---- plugin lookup and building ------------------------------------------------- */

static rsw_status unknown_plugin(loader *ld, node *n) {
  return registry_unknown_type(ld->err, n->loc, n->type, n->tag);
}

static const char *article(const char *word) {
  return word && strchr("aeiou", word[0]) ? "an" : "a";
}

/* Plugin of a node, checking the XML tag agrees with its class. */
static rsw_status node_plugin(loader *ld, node *n, const plugin **out) {
  const plugin *pl = registry_find(n->type);
  /* `periodic` is the one scene-level object that is not the scene. */
  if (!pl || (pl->cls == CLS_SCENE && pl != &plugin_periodic)) return unknown_plugin(ld, n);
  if (n->tag && strcmp(n->tag, obj_class_name(pl->cls)) != 0)
    return rsw_fail(ld->err, RSW_ERR_TYPE, n->loc, "<%s type=\"%s\">: '%s' is %s %s plugin, not %s %s",
                    n->tag, n->type, n->type, article(obj_class_name(pl->cls)), obj_class_name(pl->cls),
                    article(n->tag), n->tag);
  *out = pl;
  return RSW_OK;
}

/* Build (or return the already built) object of node n, of class cls
 * (CLS__COUNT for any class). */
static rsw_status ld_build(loader *ld, node *n, obj_class cls, object **out) {
  const plugin *pl = NULL;
  rsw_status st = node_plugin(ld, n, &pl);
  if (st) return st;
  if (cls != CLS__COUNT && pl->cls != cls)
    return rsw_fail(ld->err, RSW_ERR_TYPE, n->loc, "expected %s %s here, got the %s plugin '%s'",
                    article(obj_class_name(cls)), obj_class_name(cls), obj_class_name(pl->cls), n->type);
  if (n->build_state == 2) {
    *out = n->built;
    return RSW_OK;
  }
  if (n->build_state == 1)
    return rsw_fail(ld->err, RSW_ERR_CYCLE, n->loc, "'%s' references itself (reference cycle)", n->id);
  n->build_state = 1;
  object *o = NULL;
  st = pl->create(ld, n, &o);
  if (st) {
    if (ld->err && ld->err->code == RSW_OK)
      rsw_fail(ld->err, st, n->loc, "%s '%s': %s", n->type, n->id ? n->id : "", rsw_strerror(st));
    return st;
  }
  if (!o->plugin) o->plugin = pl;
  if (!o->id) o->id = n->id;
  st = ld_adopt(ld, o);
  if (st) return st;
  for (size_t i = 0; i < n->n_props; i++) {
    prop *p = &n->props[i];
    if (!p->used) {
      if (p->kind == PROP_NODE || p->kind == PROP_REF) {
        node *t = p->kind == PROP_NODE ? p->child : ld_resolve_ref(ld, p->ref);
        const plugin *tp = t ? registry_find(t->type) : NULL;
        const char *cname = tp ? obj_class_name(tp->cls) : "object";
        return rsw_fail(ld->err, RSW_ERR_UNUSED_PROPERTY, p->loc,
                        "%s '%s' takes no %s%s%s: %s%s%s is the %s plugin '%s' (unused)", n->type,
                        n->id ? n->id : "", cname, p->name[0] ? " as '" : "", p->name, p->name[0] ? "'" : "",
                        p->kind == PROP_REF ? "the reference resolves to " : "",
                        p->kind == PROP_REF ? p->ref : "it", cname, t ? t->type : "?");
      }
      return rsw_fail(ld->err, RSW_ERR_UNUSED_PROPERTY, p->loc,
                      "%s '%s' has no property '%s' (unused property)", n->type, n->id ? n->id : "", p->name);
    }
  }
  n->build_state = 2;
  n->built = o;
  *out = o;
  return RSW_OK;
}

static texture *uniform_texture(const spectrum *s, const char *id, const char *where) {
  texture *t = uniform_texture_new(s, id);
  if (t && where && !uniform_texture_set_where(t, where)) {
    t->base.plugin->destroy(&t->base);
    t = NULL;
  }
  return t;
}

/* Plugins added at run time (registry_add). */
enum {
  ADDED_MAX = 16
};
static const plugin *added[ADDED_MAX];
static size_t n_added;

/* The built-in plugins (scene/registry.c), those added at run time, then
 * the environment plugins loaded with --plugin-dir. */
const plugin *registry_find(const char *name) {
  for (size_t i = 0; rsw_plugins[i]; i++)
    if (strcmp(rsw_plugins[i]->name, name) == 0) return rsw_plugins[i];
  for (size_t i = 0; i < n_added; i++)
    if (strcmp(added[i]->name, name) == 0) return added[i];
  return plugins_find(name);
}

bool registry_add(const plugin *p) {
  if (!p || !p->name || n_added == ADDED_MAX || registry_find(p->name)) return false;
  added[n_added++] = p;
  return true;
}

const loader_hooks scene_build_hooks = {
    .node_plugin = node_plugin, .build = ld_build, .find = registry_find, .uniform_texture = uniform_texture};

/* Shapes first, then everything that depends on the scene's bounds
 * (instance_bbox: plain shapes, groups and instances). */

/* Bounds and everything derived from them: the scene's bounding sphere,
 * emitters' and sensors' set_scene. Run at load and after every geometric
 * update, so that an update equals a reload (Mitsuba does not refresh
 * sensors after an update; we do, deliberately). */
rsw_status scene_refresh_bounds(scene *s, rsw_err *err) {
  vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
  for (size_t i = 0; i < s->n_shapes; i++) instance_bbox(s->shapes[i], &lo, &hi);
  if (!(lo.x <= hi.x)) lo = hi = v3(0, 0, 0); /* no rendered geometry */
  if (s->periodic.on) {
    /* The geometry's vertical extent bounds the wrapping; the column's
     * lateral extent gives the bounding sphere. That sphere does not bound
     * the (infinite) scene, so nothing may use it as a bound on ray
     * lengths or to put an origin outside the scene: shadow rays towards
     * infinitely distant emitters are unbounded and distant sensors
     * place their origins outside the slab (scene/periodic.h). */
    s->periodic.zmin = lo.z;
    s->periodic.zmax = hi.z;
    rsw_status zst = periodic_refresh_shapes(s, err);
    if (zst) return zst;
    lo.x = s->periodic.min[0], lo.y = s->periodic.min[1];
    hi.x = s->periodic.max[0], hi.y = s->periodic.max[1];
  }
  s->bbox_min = lo;
  s->bbox_max = hi;
  media_refresh_null_boxes(s);
  s->bsphere_center = v3_scale(v3_add(lo, hi), 0.5);
  double r = v3_len(v3_sub(hi, s->bsphere_center));
  /* Mitsuba's sensors and emitters inflate the bounding sphere:
   * R = max(RayEpsilon, R (1 + RayEpsilon)). */
  s->bsphere_radius = fmax(RSW_RAY_EPSILON, r * (1.0 + RSW_RAY_EPSILON));
  for (size_t i = 0; i < s->n_emitters; i++) {
    emitter *e = s->emitters[i];
    if (e->ops->set_scene) e->ops->set_scene(e, s);
  }
  for (size_t i = 0; i < s->n_sensors; i++) {
    sensor *se = s->sensors[i];
    if (se->ops->set_scene) {
      rsw_status st = se->ops->set_scene(se, s, err);
      if (st) return st;
    }
  }
  return RSW_OK;
}

static rsw_status scene_finalize(loader *ld, scene *s) {
  rsw_status st;
  if (!s->integrator) {
    /* Deliberate difference from Mitsuba 3.7.1 (which refuses to render
     * without one): a scene without an integrator gets `path` with its
     * defaults, like upstream Mitsuba's Scene constructor. */
    object *o;
    st = ld_create_default(ld, "path", CLS_INTEGRATOR, "path", &o);
    if (st) return st;
    s->integrator = (integrator *)o;
  }
  for (size_t i = 0; i < s->n_shapes; i++) s->shapes[i]->index = (unsigned)i;
  st = accel_build(s, ld->err);
  if (st) return st;
  s->emitter_weight_sum = 0;
  if (s->n_emitters) {
    s->emitter_cdf = malloc(s->n_emitters * sizeof(double));
    if (!s->emitter_cdf) return rsw_fail(ld->err, RSW_ERR_NOMEM, "", "out of memory");
    for (size_t i = 0; i < s->n_emitters; i++) {
      s->emitter_weight_sum += s->emitters[i]->sampling_weight;
      s->emitter_cdf[i] = s->emitter_weight_sum;
    }
  }
  st = scene_refresh_bounds(s, ld->err);
  if (st) return st;
  st = scene_check_media(s, ld->root, ld->err);
  if (st) return st;
  return params_build(s, ld->err);
}

rsw_status scene_build(node *root, const char *doc_variant, const scene_load_opts *opts, scene **out,
                       rsw_err *err) {
  const char *vname = opts && opts->variant ? opts->variant : doc_variant;
  rsw_variant var = VARIANT_RGB;
  bool polarized = false;
  if (vname && !variant_parse(vname, &var, &polarized)) {
    rsw_status st = rsw_fail(
        err, RSW_ERR_INVALID, opts && opts->variant ? "--variant" : root->loc,
        "unknown variant '%s' (expected \"mono\", \"rgb\", \"mono_polarized\" or \"rgb_polarized\")", vname);
    node_free(root);
    return st;
  }
  scene *s = calloc(1, sizeof *s);
  if (!s) {
    node_free(root);
    return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  }
  s->base.plugin = &plugin_scene;
  s->variant = var;
  s->polarized = polarized;
  s->doc = root;
  loader ld = {.variant = var,
               .polarized = polarized,
               .err = err,
               .base_dir = opts && opts->base_dir ? opts->base_dir : ".",
               .root = root,
               .scene = s,
               .resolve = opts ? opts->resolve : NULL,
               .resolve_user = opts ? opts->resolve_user : NULL,
               .hooks = &scene_build_hooks};
  rsw_status st = ld_index(&ld);
  if (!st) {
    root->build_state = 1;
    object *o;
    st = scene_create(&ld, root, &o);
  }
  if (!st) {
    for (size_t i = 0; i < root->n_props; i++) {
      prop *p = &root->props[i];
      if (!p->used) {
        st = rsw_fail(err, RSW_ERR_UNUSED_PROPERTY, p->loc,
                      "the scene has no property '%s' (its children must be objects)", p->name);
        break;
      }
    }
  }
  if (!st) st = scene_finalize(&ld, s);
  free(ld.ids);
  free(ld.ref_slots);
  if (st) {
    scene_free(s);
    return st;
  }
  *out = s;
  return RSW_OK;
}

static char *read_all(const char *path, size_t *len, rsw_err *err) {
  FILE *f = rsw_fopen_regular(path, "rb");
  if (!f) {
    rsw_fail(err, RSW_ERR_FILE, path, "cannot open scene file: %s", rsw_open_strerror(errno));
    return NULL;
  }
  const size_t cap_max = (size_t)1 << 30;
  size_t cap = 1 << 16, n = 0;
  char *buf = malloc(cap + 1);
  while (buf) {
    size_t r = fread(buf + n, 1, cap - n, f);
    n += r;
    if (n < cap) break;
    if (cap >= cap_max) {
      free(buf);
      buf = NULL;
      rsw_fail(err, RSW_ERR_LIMIT, path, "scene file larger than 1 GiB");
      break;
    }
    char *nb = realloc(buf, 2 * cap + 1);
    if (!nb) {
      free(buf);
      buf = NULL;
      break;
    }
    buf = nb;
    cap *= 2;
  }
  if (buf && ferror(f)) {
    free(buf);
    buf = NULL;
    rsw_fail(err, RSW_ERR_IO, path, "read error");
  }
  fclose(f);
  if (!buf) {
    rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory reading the scene");
    return NULL;
  }
  buf[n] = '\0';
  *len = n;
  return buf;
}

rsw_status scene_load_memory(const char *text, size_t len, const char *name, bool is_xml,
                             const scene_load_opts *opts, scene **out, rsw_err *err) {
  node *root = NULL;
  char *doc_variant = NULL;
  rsw_status st;
  if (is_xml) {
    st = scene_read_xml(text, len, name, opts ? opts->defines : NULL, opts ? opts->n_defines : 0, &root,
                        &doc_variant, err);
  } else {
    if (opts && opts->n_defines)
      return rsw_fail(err, RSW_ERR_USAGE, "-D", "-D parameters apply to XML scenes only (%s is JSON)", name);
    st = scene_read_json(text, len, name, &root, &doc_variant, err);
  }
  if (st) return st;
  st = scene_build(root, doc_variant, opts, out, err);
  free(doc_variant);
  return st;
}

rsw_status scene_load_file(const char *path, const scene_load_opts *opts, scene **out, rsw_err *err) {
  size_t len;
  char *text = read_all(path, &len, err);
  if (!text) return err ? err->code : RSW_ERR_IO;
  const char *dot = strrchr(path, '.');
  bool is_xml;
  if (dot && strcmp(dot, ".xml") == 0) {
    is_xml = true;
  } else if (dot && strcmp(dot, ".json") == 0) {
    is_xml = false;
  } else {
    const char *c = text;
    while (*c == ' ' || *c == '\t' || *c == '\n' || *c == '\r') c++;
    is_xml = *c == '<';
  }
  scene_load_opts o = {.size = sizeof o};
  if (opts) o = *opts;
  char dir[4096];
  if (!o.base_dir) {
    const char *slash = strrchr(path, '/');
    if (slash) {
      size_t l = (size_t)(slash - path);
      if (l >= sizeof dir) l = sizeof dir - 1;
      memcpy(dir, path, l);
      dir[l] = '\0';
      if (l == 0) strcpy(dir, "/");
      o.base_dir = dir;
    }
  }
  rsw_status st = scene_load_memory(text, len, path, is_xml, &o, out, err);
  free(text);
  return st;
}
