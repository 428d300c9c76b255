/* Synchronous renders (POST :render) and the one render path jobs use
 * too (svc_render_locked), plus per-pixel viewing directions. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../kernel/core/warp.h"
#include "buf.h"
#include "rsw_sha256.h"
#include "service_internal.h"

bool svc_find_sensor(const scene *sc, const char *name, size_t *index) {
  return scene_find_sensor(sc, name, index) != NULL;
}

void svc_film_free(svc_film *f) {
  if (f) film_image_free(&f->img);
}

/* The current values of the overridden keys, to restore the base state
 * after a render (values round-trip exactly through their JSON text). */
static rsw_status snapshot(const scene *sc, const param_update *u, size_t n, param_update **out,
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

rsw_status svc_render_locked(service *svc, resident *r, const render_spec *rs, svc_film *out, svc_error *e) {
  scene *sc = r->sc;
  param_update *u = NULL, *restore = NULL;
  size_t n = 0;
  rsw_status st = RSW_OK;
  rsw_err err = {0};
  pthread_mutex_lock(&r->lock);
  if (rs->overrides) st = svc_map_to_updates(rs->overrides, sc, "params", &u, &n, e);
  if (!st && n) {
    st = snapshot(sc, u, n, &restore, &err);
    if (st) st = svc_update_error(e, sc, u, n, &err);
  }
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
                      .deadline = rs->deadline};
    render_result_stats stats;
    rsw_err rerr = {0};
    st = render_sensor(sc, &ro, &out->img, &stats, &rerr);
    if (st) {
      e->err = rerr;
      e->err.code = st = svc_request_code(st);
    } else {
      pthread_mutex_lock(&svc->lock);
      svc->render_seconds += stats.wall_s;
      svc->unresolved_rays += stats.rays.unresolved;
      pthread_mutex_unlock(&svc->lock);
      memcpy(out->scene, r->id, 65);
      out->revision = r->revision;
      snprintf(out->sensor, sizeof out->sensor, "%s", sc->sensors[rs->sensor_index]->base.id);
    }
  }
  if (restore) {
    /* Back to the base state: the same values, so bitwise the base. */
    rsw_err rerr = {0};
    if (scene_update(sc, restore, n, NULL, &rerr) != RSW_OK && !st)
      st = svc_fail(e, RSW_ERR_RENDER, rerr.where, "restoring the base state failed: %s", rerr.msg);
    for (size_t i = 0; i < n; i++) param_value_free(&restore[i].value);
    free(restore);
  }
  pthread_mutex_unlock(&r->lock);
  svc_free_updates(u, n);
  return st;
}

rsw_status service_render(service *svc, const char *id, const char *body, size_t len,
                          const atomic_int *cancel, svc_film *out, svc_error *e) {
  if (!service_ready(svc)) return svc_fail(e, RSW_ERR_UNAVAILABLE, "", "the server is shutting down");
  resident *r = svc_scene_acquire(svc, id);
  if (!r) return svc_no_scene(e, id);
  memset(out, 0, sizeof *out);
  cJSON *j = NULL;
  render_spec rs = {.seed = 0, .cancel = cancel};
  rsw_status st = svc_parse_body(body, len, &j, e);
  if (!st && !cJSON_IsObject(j))
    st = svc_fail(e, RSW_ERR_TYPE, "", "the body must be a JSON object");
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
      if (!name || !svc_find_sensor(r->sc, name, &rs.sensor_index))
        st = svc_fail(e, RSW_ERR_UNKNOWN_NAME, ptr, "no sensor '%s' in the scene", name ? name : "?");
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
        rs.wavelength = k->valuedouble;
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
    } else {
      st = svc_fail(e, RSW_ERR_UNUSED_PROPERTY, ptr,
                    "unknown field '%s' (expected sensor, spp, seed, wavelength, params, timeout_s)",
                    k->string);
    }
  }
  if (!st && rs.wavelength > 0 && r->sc->variant != VARIANT_MONO)
    st = svc_fail(e, RSW_ERR_INVALID, "/wavelength", "wavelength applies to mono scenes; this scene is rgb");
  if (!st && r->sc->n_sensors == 0) st = svc_fail(e, RSW_ERR_INVALID, "/sensor", "the scene has no sensor");
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
  }
  cJSON_Delete(j);
  svc_scene_release(svc, r);
  return st;
}

rsw_status service_directions(service *svc, const char *id, const char *sensor_name, char **json_out,
                              svc_error *e) {
  resident *r = svc_scene_acquire(svc, id);
  if (!r) return svc_no_scene(e, id);
  size_t si;
  rsw_status st = RSW_OK;
  if (!svc_find_sensor(r->sc, sensor_name, &si)) {
    svc_scene_release(svc, r);
    return svc_fail(e, RSW_ERR_NOT_FOUND, sensor_name, "no sensor '%s' in scene %s", sensor_name, id);
  }
  pthread_mutex_lock(&r->lock);
  const sensor *se = r->sc->sensors[si];
  const char *type = se->base.plugin->name;
  cJSON *o = NULL;
  if (strcmp(type, "hdistant") != 0 && strcmp(type, "distant") != 0) {
    st = svc_fail(
        e, RSW_ERR_UNSUPPORTED, sensor_name,
        "sensor '%s' is a %s; per-pixel directions exist for distant-family sensors (hdistant, distant)",
        sensor_name, type);
  } else {
    int W = se->film->width, H = se->film->height;
    o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "sensor", se->base.id);
    cJSON_AddNumberToObject(o, "width", W);
    cJSON_AddNumberToObject(o, "height", H);
    cJSON_AddStringToObject(o, "convention", "east_right");
    cJSON *px = cJSON_AddArrayToObject(o, "pixels");
    for (int iy = 0; iy < H; iy++)
      for (int ix = 0; ix < W; ix++) {
        /* hdistant: omega = to_world H(u) at the pixel centre
         * (kernel-behavior.md §1.2); angles from the local vector, as
         * Eradiate's post-processing (theta = acos z, phi = atan2(y, x),
         * east-right). distant: omega = -(to_world z). */
        vec3 local, w;
        if (strcmp(type, "hdistant") == 0) {
          local = warp_square_to_uniform_hemisphere(v2((ix + 0.5) / W, (iy + 0.5) / H));
          w = v3_norm(xf_vector(&se->to_world, local));
        } else {
          local = v3(0, 0, 1);
          w = v3_neg(v3_norm(xf_vector(&se->to_world, v3(0, 0, 1))));
          local = w;
        }
        double zen = acos(fmax(-1.0, fmin(1.0, local.z))) * 180.0 / RSW_PI;
        double az = atan2(local.y, local.x) * 180.0 / RSW_PI;
        if (az < 0) az += 360.0;
        cJSON *p = cJSON_CreateObject();
        cJSON_AddNumberToObject(p, "ix", ix);
        cJSON_AddNumberToObject(p, "iy", iy);
        cJSON_AddNumberToObject(p, "x", w.x);
        cJSON_AddNumberToObject(p, "y", w.y);
        cJSON_AddNumberToObject(p, "z", w.z);
        cJSON_AddNumberToObject(p, "zenith_deg", zen);
        cJSON_AddNumberToObject(p, "azimuth_deg", az);
        cJSON_AddItemToArray(px, p);
      }
  }
  pthread_mutex_unlock(&r->lock);
  svc_scene_release(svc, r);
  if (st) return st;
  *json_out = svc_print_json(o);
  return RSW_OK;
}
