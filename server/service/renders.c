/* Synchronous renders (POST :render) and the one render path jobs use
 * too (svc_render_locked), plus per-pixel viewing directions. */
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../kernel/core/strdist.h"
#include "../kernel/kapi.h"
#include "buf.h"
#include "rsw_sha256.h"
#include "service_internal.h"
#include "templates.h"

bool svc_find_sensor(const scene *sc, const char *name, size_t *index) {
  return kapi_find_sensor(sc, name, index);
}

/* A sensor that names nothing: the closest id (a misspelling) and the
 * scene's sensors, so the answer says what to write instead. */
rsw_status svc_no_sensor(svc_error *e, const scene *sc, const char *where, const char *name) {
  char list[512] = "";
  size_t len = 0, best_d = (size_t)-1;
  const char *best = NULL;
  for (size_t i = 0; i < sc->n_sensors; i++) {
    const char *id = kapi_sensor_id(sc, i);
    if (!id) continue;
    if (len < sizeof list)
      len += (size_t)snprintf(list + len, sizeof list - len, "%s%s", len ? ", " : "", id);
    size_t d = name ? rsw_edit_distance(name, id) : (size_t)-1;
    if (d < best_d) best_d = d, best = id;
  }
  if (len >= sizeof list) memcpy(list + sizeof list - 5, ", ...", 5); /* (its NUL kept) */
  /* A misspelling: a third of the name's letters, at least 2, differ. */
  size_t near = name ? strlen(name) / 3 : 0;
  bool close = best && best_d <= (near > 2 ? near : 2);
  rsw_status st = svc_fail(e, RSW_ERR_UNKNOWN_NAME, where, "no sensor '%s' in the scene%s%s%s (%s%s%s)",
                           name ? name : "?", close ? "; did you mean '" : "", close ? best : "",
                           close ? "'?" : "", sc->n_sensors ? "its sensors: " : "it has no sensor", list,
                           sc->n_sensors ? "; an index counts from 0" : "");
  if (close) snprintf(e->candidates[0], sizeof e->candidates[0], "%s", best);
  return st;
}

rsw_status svc_check_film(const service *svc, const scene *sc, size_t si, unsigned quantities, bool variance,
                          const char *where, svc_error *e) {
  const sensor *se = sc->sensors[si];
  int channels;
  uint64_t need = sensor_film_bytes(se, sc->variant, &channels);
  uint64_t extra = render_planes_bytes(se, sc->variant, quantities, variance);
  need = need > UINT64_MAX - extra ? UINT64_MAX : need + extra;
  if (need <= svc->opts.max_film_bytes) return RSW_OK;
  return svc_fail(
      e, RSW_ERR_LIMIT, where,
      "sensor '%s': rendering its %dx%d film (%d channel%s) takes %.3g MB, more than this server's "
      "limit of %.3g MB (--max-film-bytes)",
      se->base.id, se->film->width, se->film->height, channels, channels > 1 ? "s" : "", (double)need / 1e6,
      (double)svc->opts.max_film_bytes / 1e6);
}

void svc_film_free(svc_film *f) {
  if (f) film_image_free(&f->img);
}

/* ---- render views -------------------------------------------------------------
 *
 * Copy-on-write parameter state per render. A render with overrides, or
 * one that finds the base borrowed by another render, renders on a view: a
 * private scene loaded from the resident's text with every PATCH since
 * replayed (so bitwise the base revision: an update equals a reload,
 * params.h), then the render's overrides applied to the view alone. The
 * base is never written by a render, so a render cannot leave the base
 * changed under its revision, and renders of one scene with different
 * overrides run at the same time.
 *
 * Why whole-scene views and not per-object clones sharing geometry and
 * Embree: a render writes wavelength-dependent state into the objects
 * themselves (scene_prepare: uniform textures, conductors, envmaps,
 * bitmaps, films), objects point at each other (shape -> bsdf -> texture,
 * emitter <-> shape, sensor -> film) and no plugin has a clone operation;
 * a geometric override (a shape's to_world, vertex positions) needs its
 * own acceleration data in any design. A view costs one load of the scene
 * (memory and time of a POST /v1/scenes, with the same files); it is
 * built once and reused: after a render the keys it overrode are set back
 * to the view's own earlier values (a view whose reset fails is dropped;
 * the base never sees it). Views per scene are capped (view_cap); renders
 * beyond the cap wait for one. A render without overrides takes a view
 * only for a small scene (VIEW_FREE_BYTES of geometry, kapi_scene_bytes):
 * on a big one it waits for the base rather than load the scene again. */
#define VIEW_FREE_BYTES ((size_t)16 << 20)

static int view_cap(void) {
  static atomic_int cap;
  int c = atomic_load(&cap);
  if (!c) {
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    c = n < 2 ? 2 : n > 8 ? 8 : (int)n;
    atomic_store(&cap, c);
  }
  return c;
}

void svc_views_free(resident *r) {
  while (r->views) {
    svc_view *v = r->views;
    r->views = v->next;
    scene_free(v->sc);
    free(v);
    r->n_views--;
  }
}

bool svc_keep_patch(resident *r, const cJSON *body) {
  if (!r->patches) return false;
  cJSON *m = svc_patch_merged(r->patches, body, r->sc);
  if (!m) return false;
  cJSON_Delete(r->patches);
  r->patches = m;
  return true;
}

/* The canonical path of key in sc (key itself when it does not resolve:
 * the update that follows refuses it). */
static const char *canonical_key(const scene *sc, const char *key, size_t *idx) {
  rsw_err err = {0};
  param_info info;
  if (params_lookup(sc, key, idx, &err) != RSW_OK || !params_info(sc, *idx, &info)) {
    *idx = SIZE_MAX;
    return key;
  }
  return info.key;
}

cJSON *svc_patch_merged(const cJSON *old, const cJSON *body, const scene *sc) {
  unsigned jm = svc_json_mark();
  cJSON *m = old ? cJSON_Duplicate(old, true) : cJSON_CreateObject();
  for (const cJSON *k = body->child; m && k; k = k->next) {
    size_t idx;
    const char *key = canonical_key(sc, k->string, &idx);
    /* Drop the entry's earlier value under any of its names. */
    for (cJSON *o = m->child, *next; o; o = next) {
      next = o->next;
      size_t oi = SIZE_MAX;
      if (idx != SIZE_MAX) (void)canonical_key(sc, o->string, &oi);
      if (strcmp(o->string, k->string) == 0 || (idx != SIZE_MAX && oi == idx))
        cJSON_Delete(cJSON_DetachItemViaPointer(m, o));
    }
    cJSON *d = cJSON_Duplicate(k, true);
    if (!d || !cJSON_AddItemToObject(m, key, d)) { /* the key's copy: out of memory */
      cJSON_Delete(d);
      cJSON_Delete(m);
      m = NULL;
    }
  }
  if (m && !svc_json_ok(jm)) {
    cJSON_Delete(m);
    m = NULL;
  }
  return m;
}

/* Build a view of r at the revision whose PATCHes `patches` holds. */
static rsw_status view_build(service *svc, resident *r, const cJSON *patches, uint64_t revision,
                             svc_view **out, svc_error *e) {
  scene *sc = NULL;
  rsw_status st = svc_scene_build_at(svc, r, patches, &sc, e);
  if (st) {
    svc_error why = *e;
    return svc_fail(e, RSW_ERR_RENDER, why.err.where, "cannot build a render view of the scene: %s",
                    why.err.msg);
  }
  svc_view *v = calloc(1, sizeof *v);
  if (!v) {
    scene_free(sc);
    return svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
  }
  v->sc = sc;
  v->revision = revision;
  *out = v;
  return RSW_OK;
}

static bool stop_waiting(const render_spec *rs) {
  return (rs->cancel && atomic_load(rs->cancel)) || (rs->deadline > 0 && svc_now() > rs->deadline);
}

/* The scene to render on: the base (*v NULL; only when base_ok) or a view
 * at the current revision. */
static rsw_status take_scene(service *svc, resident *r, bool base_ok, const render_spec *rs, svc_view **v,
                             uint64_t *revision, svc_error *e) {
  bool build_failed = false;
  pthread_mutex_lock(&r->lock);
  for (;;) {
    if (base_ok && !r->base_busy) {
      r->base_busy = true;
      *v = NULL;
      *revision = r->revision;
      pthread_mutex_unlock(&r->lock);
      return RSW_OK;
    }
    if (r->views) {
      *v = r->views;
      r->views = (*v)->next;
      *revision = r->revision;
      pthread_mutex_unlock(&r->lock);
      return RSW_OK;
    }
    if (!base_ok && !r->patches) {
      /* Out of memory while recording a PATCH: views can no longer
       * reproduce the base. */
      pthread_mutex_unlock(&r->lock);
      return svc_fail(e, RSW_ERR_NOMEM, "params", "out of memory: this scene can no longer take overrides");
    }
    bool may_build = !build_failed && (!base_ok || kapi_scene_bytes(r->sc) <= VIEW_FREE_BYTES);
    if (may_build && r->n_views < view_cap() && r->patches) {
      r->n_views++;
      uint64_t rev = r->revision;
      cJSON *p = cJSON_Duplicate(r->patches, true);
      pthread_mutex_unlock(&r->lock);
      rsw_status st = p ? view_build(svc, r, p, rev, v, e) : svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
      cJSON_Delete(p);
      pthread_mutex_lock(&r->lock);
      if (!st && r->revision == rev) {
        *revision = rev;
        pthread_mutex_unlock(&r->lock);
        return RSW_OK;
      }
      r->n_views--;
      pthread_cond_broadcast(&r->cond);
      if (st && base_ok) { /* wait for the base instead */
        build_failed = true;
        memset(e, 0, sizeof *e);
        continue;
      }
      if (st) {
        pthread_mutex_unlock(&r->lock);
        return st;
      }
      /* A PATCH landed while it was built: build again. */
      pthread_mutex_unlock(&r->lock);
      scene_free((*v)->sc);
      free(*v);
      pthread_mutex_lock(&r->lock);
      continue;
    }
    if (stop_waiting(rs)) {
      pthread_mutex_unlock(&r->lock);
      if (rs->cancel && atomic_load(rs->cancel))
        return svc_fail(e, RSW_ERR_CANCELLED, "render", "render cancelled");
      return svc_fail(e, RSW_ERR_TIMEOUT, "timeout_s",
                      "the render's deadline passed while it waited for the scene");
    }
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    ts.tv_nsec += 20 * 1000000L;
    if (ts.tv_nsec >= 1000000000L) ts.tv_sec++, ts.tv_nsec -= 1000000000L;
    pthread_cond_timedwait(&r->cond, &r->lock, &ts);
  }
}

/* Give the base or a view back; a view that is stale (a PATCH since) or
 * whose reset failed is freed. */
static void give_back(resident *r, svc_view *v, bool keep) {
  pthread_mutex_lock(&r->lock);
  if (!v) {
    r->base_busy = false;
  } else if (keep && v->revision == r->revision) {
    v->next = r->views;
    r->views = v;
    v = NULL;
  } else {
    r->n_views--;
  }
  pthread_cond_broadcast(&r->cond);
  pthread_mutex_unlock(&r->lock);
  if (v) {
    scene_free(v->sc);
    free(v);
  }
}

/* The view's current values of the overridden keys, to set it back after
 * the render (values round-trip exactly through their JSON text). */
rsw_status svc_param_snapshot(const scene *sc, const param_update *u, size_t n, param_update **out,
                              rsw_err *err) {
  param_update *s = calloc(n ? n : 1, sizeof *s);
  if (!s) return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  for (size_t i = 0; i < n; i++) {
    size_t idx;
    rsw_status st = params_lookup(sc, u[i].key, &idx, err);
    char *txt = st ? NULL : params_value_json(sc, idx, 0);
    if (!st && !txt) st = rsw_fail(err, RSW_ERR_NOMEM, u[i].key, "out of memory");
    if (!st) {
      s[i].key = u[i].key;
      st = param_value_parse(txt, u[i].key, &s[i].value, err);
    }
    free(txt);
    if (st) {
      for (size_t q = 0; q < i; q++) param_value_free(&s[q].value);
      free(s);
      return st;
    }
  }
  *out = s;
  return RSW_OK;
}

rsw_status svc_parse_quantities(const cJSON *v, const char *ptr, unsigned *out, svc_error *e) {
  unsigned q = 0;
  if (!cJSON_IsArray(v))
    return svc_fail(e, RSW_ERR_TYPE, ptr, "quantities must be a list of %s", RENDER_QUANTITY_NAMES);
  int i = 0;
  for (const cJSON *x = v->child; x; x = x->next, i++) {
    unsigned bit;
    if (!cJSON_IsString(x) || !render_quantity_bit(x->valuestring, &bit)) {
      char w[320];
      snprintf(w, sizeof w, "%s/%d", ptr, i);
      return svc_fail(e, RSW_ERR_INVALID, w, "unknown quantity '%s' (one of %s)",
                      cJSON_IsString(x) ? x->valuestring : "?", RENDER_QUANTITY_NAMES);
    }
    q |= bit;
  }
  *out = q;
  return RSW_OK;
}

rsw_status svc_parse_variance(const cJSON *v, const char *ptr, bool *out, svc_error *e) {
  if (!cJSON_IsBool(v)) return svc_fail(e, RSW_ERR_TYPE, ptr, "variance must be true or false");
  *out = cJSON_IsTrue(v);
  return RSW_OK;
}

rsw_status svc_check_planes(const scene *sc, size_t si, uint32_t spp, unsigned quantities, bool variance,
                            const char *ptr_q, const char *ptr_v, svc_error *e) {
  rsw_err err = {0};
  rsw_status st = render_check_planes(sc, si, spp, quantities, variance, &err);
  if (!st) return RSW_OK;
  return svc_fail(e, st, strcmp(err.where, "variance") == 0 ? ptr_v : ptr_q, "%s", err.msg);
}

rsw_status svc_render_locked(service *svc, resident *r, const render_spec *rs, svc_film *out, svc_error *e) {
  bool overrides = rs->overrides && rs->overrides->child;
  svc_view *v = NULL;
  uint64_t revision = 0;
  rsw_status st = take_scene(svc, r, !overrides, rs, &v, &revision, e);
  if (st) return st;
  scene *sc = v ? v->sc : r->sc;
  param_update *u = NULL, *restore = NULL;
  size_t n = 0;
  rsw_err err = {0};
  if (overrides) st = svc_map_to_updates(rs->overrides, sc, "params", &u, &n, e);
  if (!st && n) {
    st = svc_param_snapshot(sc, u, n, &restore, &err);
    if (st) st = svc_update_error(e, sc, u, n, &err);
  }
  bool keep = true;
  if (!st && n) {
    update_report rep;
    st = scene_update(sc, u, n, &rep, &err);
    if (st)
      st = svc_update_error(e, sc, u, n, &err);
    else
      svc_count_update(svc, &rep);
  }
  if (!st) {
    render_opts ro = {.size = sizeof ro,
                      .sensor = rs->sensor_index,
                      .spp = rs->spp,
                      .seed = rs->seed,
                      .wavelength = rs->wavelength,
                      .threads = svc->opts.render_threads,
                      .cancel = rs->cancel,
                      .deadline = rs->deadline,
                      .quantities = rs->quantities,
                      .variance = rs->variance,
                      .samples = rs->samples,
                      .bundle = rs->bundle};
    memcpy(ro.bundle_wl, rs->bundle_wl, sizeof ro.bundle_wl);
    int nb = rs->bundle > 1 ? rs->bundle : 1;
    film_image img[RENDER_MAX_BUNDLE];
    render_result_stats stats;
    rsw_err rerr = {0};
    st = render_sensor_bundle(sc, &ro, img, &stats, &rerr);
    if (st) {
      e->err = rerr;
      e->err.code = st = svc_request_code(st);
    } else {
      pthread_mutex_lock(&svc->lock);
      svc->render_seconds += stats.wall_s;
      svc->unresolved_rays += stats.rays.unresolved;
      for (int b = 0; b < nb; b++)
        if (img[b].nonfinite) svc->films_nonfinite++;
      pthread_mutex_unlock(&svc->lock);
      for (int b = 0; b < nb; b++) {
        out[b].img = img[b];
        memcpy(out[b].scene, r->id, 65);
        out[b].revision = revision;
        snprintf(out[b].sensor, sizeof out[b].sensor, "%s", kapi_sensor_id(sc, rs->sensor_index));
      }
    }
  }
  if (restore) {
    /* The view back to its revision (the same values, so bitwise); on
     * failure it is dropped, never used again. */
    rsw_err rerr = {0};
    keep = scene_update(sc, restore, n, NULL, &rerr) == RSW_OK;
    for (size_t i = 0; i < n; i++) param_value_free(&restore[i].value);
    free(restore);
  } else if (n) {
    keep = false; /* overrides were (maybe partly) applied without a snapshot */
  }
  give_back(r, v, keep);
  svc_free_updates(u, n);
  return st;
}

/* A render's coords and templates: the scene's templates and the
 * request's (req_tmpl) compiled, every coordinate read by one of them
 * (else a 422 at /coords/NAME: a misspelt coordinate would render the
 * document's values), coords.wavelength checked against the request's
 * wavelength (wl_field) and taken as the wavelength when there is none,
 * and the templates rendered into *rendered (a copy of the request's
 * params, which win), which rs->overrides then points at. */
static rsw_status render_templates(const resident *r, const cJSON *coords, const cJSON *req_tmpl,
                                   const cJSON *wl_field, render_spec *rs, tmpl_set **ts, cJSON **rendered,
                                   svc_error *e) {
  const scene *sc = r->sc;
  rsw_status st = tmpl_compile(sc, r->templates, "/scene/templates", req_tmpl, rs->overrides, ts, e);
  if (st) return st;
  const cJSON *cw = coords ? cJSON_GetObjectItemCaseSensitive(coords, "wavelength") : NULL;
  if (cw && (st = tmpl_check_coord_wavelength(sc, wl_field, cw, "", e))) return st;
  if (cw && !wl_field) rs->wavelength = cw->valuedouble;
  for (const cJSON *c = coords ? coords->child : NULL; c; c = c->next) {
    if (strcmp(c->string, "wavelength") == 0) continue;
    if (!*ts || !tmpl_uses_coord(*ts, c->string)) {
      char ptr[300];
      snprintf(ptr, sizeof ptr, "/coords/%.280s", c->string);
      const char *why = !r->templates && !req_tmpl ? "the scene has no templates, and the request gives none"
                        : rs->overrides && rs->overrides->child
                            ? "nor does one whose parameter the request's params set: explicit values win"
                            : "the templates read other coordinates";
      return svc_fail(e, RSW_ERR_UNUSED_PROPERTY, ptr,
                      "no template reads the coordinate '%s' (%s): the render would not depend on it",
                      c->string, why);
    }
  }
  if (!*ts) return RSW_OK;
  *rendered = rs->overrides ? cJSON_Duplicate(rs->overrides, true) : cJSON_CreateObject();
  if (!*rendered) return svc_fail(e, RSW_ERR_NOMEM, "/coords", "out of memory");
  double wl = sc->variant != VARIANT_MONO ? 0 : rs->wavelength > 0 ? rs->wavelength : 550;
  st = tmpl_render(*ts, sc, coords, wl, *rendered, "", e);
  if (!st) rs->overrides = *rendered;
  return st;
}

rsw_status service_render(service *svc, const char *id, const char *body, size_t len,
                          const atomic_int *cancel, svc_film *out, svc_error *e) {
  if (!service_ready(svc)) return svc_fail(e, RSW_ERR_UNAVAILABLE, "", "the server is shutting down");
  resident *r = svc_scene_acquire(svc, id);
  if (!r) return svc_no_scene(e, id);
  memset(out, 0, sizeof *out);
  cJSON *j = NULL, *rendered = NULL;
  const cJSON *coords = NULL, *req_tmpl = NULL, *wl_field = NULL;
  tmpl_set *ts = NULL;
  render_spec rs = {.seed = 0, .cancel = cancel};
  rsw_status st = svc_parse_body(body, len, &j, e);
  if (!st && !cJSON_IsObject(j)) st = svc_fail(e, RSW_ERR_TYPE, "", "the body must be a JSON object");
  for (const cJSON *k = j && !st ? j->child : NULL; k && !st; k = k->next) {
    char ptr[300];
    snprintf(ptr, sizeof ptr, "/%s", k->string);
    if (strcmp(k->string, "sensor") == 0) {
      char buf[32];
      const char *name = cJSON_IsString(k) ? k->valuestring : NULL;
      if (cJSON_IsNumber(k) && k->valuedouble >= 0 && k->valuedouble == floor(k->valuedouble)) {
        snprintf(buf, sizeof buf, "%.0f", k->valuedouble);
        name = buf;
      }
      if (!name || !svc_find_sensor(r->sc, name, &rs.sensor_index)) st = svc_no_sensor(e, r->sc, ptr, name);
    } else if (strcmp(k->string, "spp") == 0) {
      if (!cJSON_IsNumber(k) || k->valuedouble < 1 || k->valuedouble > 4294967295.0 ||
          k->valuedouble != floor(k->valuedouble))
        st = svc_fail(e, RSW_ERR_INVALID, ptr, "spp must be a positive integer");
      else
        rs.spp = (uint32_t)k->valuedouble;
    } else if (strcmp(k->string, "seed") == 0) {
      if (!cJSON_IsNumber(k) || k->valuedouble < 0 || k->valuedouble > 9007199254740991.0 ||
          k->valuedouble != floor(k->valuedouble))
        st = svc_fail(e, RSW_ERR_INVALID, ptr, "seed must be a non-negative integer");
      else
        rs.seed = (uint64_t)k->valuedouble;
    } else if (strcmp(k->string, "wavelength") == 0) {
      if (!cJSON_IsNumber(k) || !(k->valuedouble > 0) || !isfinite(k->valuedouble))
        st = svc_fail(e, RSW_ERR_INVALID, ptr, "wavelength must be a positive number of nm");
      else
        rs.wavelength = k->valuedouble, wl_field = k;
    } else if (strcmp(k->string, "coords") == 0) {
      if (!cJSON_IsObject(k))
        st = svc_fail(e, RSW_ERR_TYPE, ptr,
                      "coords must be an object {name: value} (the templates' coordinates)");
      else
        coords = k;
    } else if (strcmp(k->string, "templates") == 0) {
      if (!cJSON_IsObject(k))
        st = svc_fail(e, RSW_ERR_TYPE, ptr, "templates must be an object {key: template}");
      else
        req_tmpl = k;
    } else if (strcmp(k->string, "params") == 0) {
      if (!cJSON_IsObject(k))
        st = svc_fail(e, RSW_ERR_TYPE, ptr, "params must be an object {key: value}");
      else
        rs.overrides = k;
    } else if (strcmp(k->string, "timeout_s") == 0) {
      if (!cJSON_IsNumber(k) || !(k->valuedouble > 0))
        st = svc_fail(e, RSW_ERR_INVALID, ptr, "timeout_s must be a positive number");
      else
        rs.deadline = svc_now() + k->valuedouble;
    } else if (strcmp(k->string, "quantities") == 0) {
      st = svc_parse_quantities(k, ptr, &rs.quantities, e);
    } else if (strcmp(k->string, "variance") == 0) {
      st = svc_parse_variance(k, ptr, &rs.variance, e);
    } else {
      st = svc_fail(
          e, RSW_ERR_UNUSED_PROPERTY, ptr,
          "unknown field '%s' (expected sensor, spp, seed, wavelength, params, coords, templates, timeout_s, "
          "quantities, variance)",
          k->string);
    }
  }
  /* coords (and the request's templates): the render is a context whose
   * templates, the scene's and the request's, render into its overrides
   * as a job's do (docs/experiments.md#templates); explicit params win. */
  if (!st && (coords || req_tmpl))
    st = render_templates(r, coords, req_tmpl, wl_field, &rs, &ts, &rendered, e);
  if (!st && r->sc->n_sensors && (rs.quantities || rs.variance))
    st = svc_check_planes(r->sc, rs.sensor_index, rs.spp, rs.quantities, rs.variance, "/quantities",
                          "/variance", e);
  if (!st && rs.wavelength > 0 && r->sc->variant != VARIANT_MONO)
    st = svc_fail(e, RSW_ERR_INVALID, "/wavelength", "wavelength applies to mono scenes; this scene is rgb");
  if (!st && r->sc->n_sensors == 0) st = svc_fail(e, RSW_ERR_INVALID, "/sensor", "the scene has no sensor");
  /* Limits before anything is allocated: the film's memory, then its
   * samples. */
  if (!st) st = svc_check_film(svc, r->sc, rs.sensor_index, rs.quantities, rs.variance, "/sensor", e);
  if (!st) {
    const sensor *se = r->sc->sensors[rs.sensor_index];
    uint64_t spp = rs.spp ? rs.spp : se->sampler->sample_count;
    uint64_t ps = (uint64_t)se->film->width * (uint64_t)se->film->height * spp;
    if (ps > svc->opts.max_pixel_samples)
      st = svc_fail(e, RSW_ERR_LIMIT, "/spp", "%llu pixel samples exceed this server's limit of %llu",
                    (unsigned long long)ps, (unsigned long long)svc->opts.max_pixel_samples);
  }
  if (!st) {
    pthread_mutex_lock(&svc->lock);
    svc->sync_renders++;
    pthread_mutex_unlock(&svc->lock);
    st = svc_render_locked(svc, r, &rs, out, e);
    pthread_mutex_lock(&svc->lock);
    svc->sync_renders--;
    if (!st) svc->contexts_rendered++;
    pthread_mutex_unlock(&svc->lock);
    if (!st) snprintf(out->context, sizeof out->context, "render");
    /* A value a template rendered that the parameter refuses: the
     * template is named, as for a job. */
    if (st && e->key[0] &&
        !cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(j, "params"), e->key))
      tmpl_blame(ts, "/coords", e);
  }
  tmpl_free(ts);
  cJSON_Delete(rendered);
  cJSON_Delete(j);
  svc_scene_release(svc, r);
  return st;
}

/* Each pixel's viewing direction as the sensor maps it (its
 * pixel_directions and pixel_angles ops), printed straight into a capped
 * buffer: some 150 bytes of JSON per pixel and 40 of scratch, where a
 * cJSON tree took a kilobyte. Films beyond SVC_MAX_DIRECTION_PIXELS are
 * refused before anything is allocated. */
rsw_status service_directions(service *svc, const char *id, const char *sensor_name, char **json_out,
                              svc_error *e) {
  resident *r = svc_scene_acquire(svc, id);
  if (!r) return svc_no_scene(e, id);
  size_t si;
  if (!svc_find_sensor(r->sc, sensor_name, &si)) {
    svc_scene_release(svc, r);
    return svc_fail(e, RSW_ERR_NOT_FOUND, sensor_name, "no sensor '%s' in scene %s", sensor_name, id);
  }
  const sensor *se = r->sc->sensors[si];
  int W = se->film->width, H = se->film->height;
  size_t n = (size_t)W * (size_t)H;
  rsw_status st = RSW_OK;
  if (!se->ops->pixel_directions || !se->ops->pixel_angles)
    st = svc_fail(
        e, RSW_ERR_UNSUPPORTED, sensor_name,
        "sensor '%s' is a %s; per-pixel directions exist for distant-family sensors (hdistant, distant)",
        sensor_name, se->base.plugin->name);
  else if (n > SVC_MAX_DIRECTION_PIXELS)
    st = svc_fail(e, RSW_ERR_LIMIT, sensor_name,
                  "sensor '%s': its film has %dx%d = %zu pixels; directions are served for at most %d pixels",
                  sensor_name, W, H, n, SVC_MAX_DIRECTION_PIXELS);
  double *xyz = NULL, *za = NULL;
  if (!st) {
    xyz = malloc(3 * n * sizeof *xyz);
    za = malloc(2 * n * sizeof *za);
    if (!xyz || !za) st = svc_fail(e, RSW_ERR_NOMEM, sensor_name, "out of memory");
  }
  if (!st) {
    /* The sensor's transform is parameter state: read under the scene's
     * lock (a render may be applying an override). */
    pthread_mutex_lock(&r->lock);
    se->ops->pixel_directions(se, W, H, xyz);
    se->ops->pixel_angles(se, W, H, za);
    pthread_mutex_unlock(&r->lock);
    svc_buf b = svc_buf_make(160 * n + 4096);
    svc_buf_printf(&b, "{\"sensor\":");
    char *esc = NULL;
    cJSON *name = cJSON_CreateString(se->base.id);
    if (name) esc = cJSON_PrintUnformatted(name);
    cJSON_Delete(name);
    svc_buf_printf(&b, "%s,\"width\":%d,\"height\":%d,\"convention\":\"east_right\",\"pixels\":[",
                   esc ? esc : "\"\"", W, H);
    free(esc);
    for (size_t i = 0; i < n && !b.failed; i++) {
      const double *w = &xyz[3 * i], *a = &za[2 * i];
      svc_buf_printf(&b,
                     "%s{\"ix\":%zu,\"iy\":%zu,\"x\":%.17g,\"y\":%.17g,\"z\":%.17g,\"zenith_deg\":%.17g,"
                     "\"azimuth_deg\":%.17g}",
                     i ? "," : "", i % (size_t)W, i / (size_t)W, w[0], w[1], w[2], a[0], a[1]);
    }
    svc_buf_printf(&b, "]}");
    *json_out = svc_buf_take(&b);
    if (!*json_out) st = svc_fail(e, RSW_ERR_NOMEM, sensor_name, "out of memory");
  }
  free(xyz);
  free(za);
  svc_scene_release(svc, r);
  return st;
}
