/* A scene's parameter table: GET (from a base-state cache that never
 * waits for a render) and PATCH, and the {key: value} maps that
 * renders and job contexts carry as overrides. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "buf.h"
#include "rsw_sha256.h"
#include "service_internal.h"

static cJSON *param_entry_json(const scene *sc, size_t i) {
  param_info pi;
  if (!params_info(sc, i, &pi)) return NULL;
  cJSON *o = cJSON_CreateObject();
  cJSON_AddStringToObject(o, "key", pi.key);
  cJSON_AddStringToObject(o, "type", param_type_name(pi.type));
  cJSON_AddStringToObject(o, "class", update_class_name(pi.cls));
  cJSON *sh = cJSON_AddArrayToObject(o, "shape");
  svc_json_push(sh, cJSON_CreateNumber((double)pi.shape[0]));
  if (pi.shape[1]) svc_json_push(sh, cJSON_CreateNumber((double)pi.shape[1]));
  cJSON_AddStringToObject(o, "object_type", pi.object_type);
  cJSON_AddStringToObject(o, "object_class", pi.object_class);
  cJSON_AddStringToObject(o, "object_id", pi.object_id);
  /* The value's text is NULL, or does not parse, only when out of
   * memory: then the entry is not made (no "value": null in its place). */
  char *v = params_value_json(sc, i, 16);
  cJSON *val = v ? cJSON_Parse(v) : NULL;
  free(v);
  if (!val) {
    cJSON_Delete(o);
    return NULL;
  }
  svc_json_put(o, "value", val);
  cJSON *al = cJSON_AddArrayToObject(o, "aliases");
  for (size_t a = 0; a < pi.n_aliases; a++) svc_json_push(al, cJSON_CreateString(pi.aliases[a]));
  return o;
}

/* Rebuild the base-state cache; r->lock held (no overrides applied). A
 * rebuild that ran out of memory (an entry or a field missing) is
 * dropped: the old cache stays, marked stale. */
bool svc_refresh_param_cache(resident *r) {
  unsigned jm = svc_json_mark();
  cJSON *a = cJSON_CreateArray();
  size_t n = params_count(r->sc);
  bool ok = a != NULL;
  for (size_t i = 0; ok && i < n; i++) {
    cJSON *p = param_entry_json(r->sc, i);
    ok = p && cJSON_AddItemToArray(a, p);
    if (!ok) cJSON_Delete(p);
  }
  ok = ok && svc_json_ok(jm);
  if (!ok) cJSON_Delete(a);
  pthread_mutex_lock(&r->cache_lock);
  if (ok) {
    cJSON_Delete(r->base_params);
    r->base_params = a;
    r->cache_revision = r->revision;
  }
  r->cache_stale = !ok;
  pthread_mutex_unlock(&r->cache_lock);
  return ok;
}

/* An unknown-key error with the closest keys, for problem+json. */
rsw_status svc_key_error(svc_error *e, const scene *sc, const char *key, const rsw_err *err) {
  e->err = *err;
  e->err.code = svc_request_code(err->code);
  snprintf(e->key, sizeof e->key, "%s", key);
  if (err->code == RSW_ERR_NOT_FOUND) {
    const char *c[3];
    size_t n = params_closest(sc, key, c);
    for (size_t i = 0; i < n; i++) snprintf(e->candidates[i], sizeof e->candidates[i], "%s", c[i]);
  }
  return e->err.code;
}

/* A cached entry whose value is a buffer's {"length": n} stand-in gets
 * its values, read from the scene (r->lock held, base state). False when
 * out of memory. */
static bool params_entry_full(const resident *r, size_t i, cJSON *p) {
  cJSON *v = cJSON_GetObjectItemCaseSensitive(p, "value");
  if (!cJSON_IsObject(v) || !cJSON_GetObjectItemCaseSensitive(v, "length")) return true;
  char *txt = params_value_json(r->sc, i, 0);
  cJSON *full = txt ? cJSON_Parse(txt) : NULL;
  free(txt);
  if (full && cJSON_ReplaceItemInObjectCaseSensitive(p, "value", full)) return true;
  cJSON_Delete(full);
  return false;
}

static rsw_status params_get(service *svc, const char *id, const char *match, const char *cls, bool full,
                             char **json_out, uint64_t *revision_out, svc_error *e) {
  unsigned jm = svc_json_mark();
  resident *r = svc_scene_acquire(svc, id);
  if (!r) return svc_no_scene(e, id);
  unsigned mask = UPDATE_SPECTRAL | UPDATE_GEOMETRIC;
  bool none = true;
  if (cls && *cls) {
    update_class c;
    if (!update_class_parse(cls, &c)) {
      svc_scene_release(svc, r);
      return svc_fail(e, RSW_ERR_BAD_REQUEST, "class", "class must be spectral, geometric or none (got '%s')",
                      cls);
    }
    mask = c == UPDATE_NONE ? 0 : (unsigned)c;
    none = c == UPDATE_NONE;
  }
  /* Matching reads only the table's keys and classes (fixed at load);
   * values come from the base-state cache, so this never waits for a
   * render. */
  /* A stale cache (its rebuild after an update ran out of memory) is
   * rebuilt now, if no render holds the scene; else this answers 503. */
  pthread_mutex_lock(&r->cache_lock);
  bool stale = r->cache_stale;
  pthread_mutex_unlock(&r->cache_lock);
  if (stale && pthread_mutex_trylock(&r->lock) == 0) {
    stale = !svc_refresh_param_cache(r);
    pthread_mutex_unlock(&r->lock);
  }
  if (stale) {
    svc_scene_release(svc, r);
    return svc_fail(e, RSW_ERR_UNAVAILABLE, "",
                    "the parameter table is being rebuilt (the last rebuild ran out of memory); retry");
  }
  /* Full values come from the scene in its base state: wait for a
   * render's overrides to be undone (lock order: r->lock, then
   * cache_lock, as in svc_refresh_param_cache). */
  if (full) pthread_mutex_lock(&r->lock);
  bool oom = false;
  size_t *idx = NULL, n = 0;
  rsw_err err = {0};
  rsw_status st = params_match(r->sc, match && *match ? match : "*", mask, none, &idx, &n, &err);
  cJSON *o = NULL;
  pthread_mutex_lock(&r->cache_lock);
  uint64_t rev = r->cache_revision;
  if (st == RSW_OK) {
    o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "revision", (double)rev);
    cJSON *a = cJSON_AddArrayToObject(o, "params");
    for (size_t k = 0; k < n; k++) {
      cJSON *p = cJSON_GetArrayItem(r->base_params, (int)idx[k]);
      cJSON *d = p ? cJSON_Duplicate(p, 1) : NULL;
      if (d && full && !params_entry_full(r, idx[k], d)) oom = true;
      if (p) svc_json_push(a, d);
    }
  } else if (st == RSW_ERR_NOT_FOUND && !strchr(match, ':')) {
    /* A glob matching nothing is an empty table, not an error, over HTTP. */
    o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "revision", (double)rev);
    cJSON_AddArrayToObject(o, "params");
    st = RSW_OK;
  } else {
    st = svc_key_error(e, r->sc, match, &err);
  }
  pthread_mutex_unlock(&r->cache_lock);
  if (full) pthread_mutex_unlock(&r->lock);
  *revision_out = rev;
  free(idx);
  svc_scene_release(svc, r);
  if (st) return st;
  if (oom) {
    cJSON_Delete(o);
    return svc_fail(e, RSW_ERR_NOMEM, "", "out of memory writing the full parameter values");
  }
  return svc_json_out(json_out, o, jm, e);
}

rsw_status service_params_get(service *svc, const char *id, const char *match, const char *cls,
                              char **json_out, uint64_t *revision_out, svc_error *e) {
  return params_get(svc, id, match, cls, false, json_out, revision_out, e);
}

rsw_status service_params_get_full(service *svc, const char *id, const char *match, const char *cls,
                                   char **json_out, uint64_t *revision_out, svc_error *e) {
  return params_get(svc, id, match, cls, true, json_out, revision_out, e);
}

/* Parse a JSON object {key: value} into updates. Keys borrowed from j. */
rsw_status svc_map_to_updates(const cJSON *j, const scene *sc, const char *where, param_update **out,
                              size_t *n, svc_error *e) {
  *out = NULL;
  *n = 0;
  if (!cJSON_IsObject(j)) return svc_fail(e, RSW_ERR_TYPE, where, "%s must be an object {key: value}", where);
  size_t cnt = 0;
  for (const cJSON *k = j->child; k; k = k->next) cnt++;
  param_update *u = calloc(cnt ? cnt : 1, sizeof *u);
  if (!u) return svc_fail(e, RSW_ERR_NOMEM, where, "out of memory");
  size_t i = 0;
  for (const cJSON *k = j->child; k; k = k->next, i++) {
    u[i].key = k->string;
    rsw_err err = {0};
    rsw_status st = param_value_from_json(k, k->string, &u[i].value, &err);
    if (st) {
      for (size_t q = 0; q < i; q++) param_value_free(&u[q].value);
      free(u);
      svc_key_error(e, sc, k->string, &err);
      if (e->err.code == RSW_ERR_UNKNOWN_NAME) e->candidates[0][0] = '\0';
      return e->err.code;
    }
  }
  *out = u;
  *n = cnt;
  return RSW_OK;
}

void svc_free_updates(param_update *u, size_t n) {
  for (size_t i = 0; i < n; i++) param_value_free(&u[i].value);
  free(u);
}

rsw_status svc_update_error(svc_error *e, const scene *sc, const param_update *u, size_t n,
                            const rsw_err *err) {
  /* Name the key the kernel complained about (err->where is the key). */
  const char *key = err->where;
  for (size_t i = 0; i < n; i++)
    if (strcmp(u[i].key, err->where) == 0) key = u[i].key;
  return svc_key_error(e, sc, key, err);
}

rsw_status service_params_patch(service *svc, const char *id, const char *body, size_t len, int64_t if_match,
                                char **json_out, uint64_t *revision_out, svc_error *e) {
  unsigned jm = svc_json_mark();
  resident *r = svc_scene_acquire(svc, id);
  if (!r) return svc_no_scene(e, id);
  cJSON *j;
  rsw_status pst = svc_parse_body(body, len, &j, e);
  if (pst) {
    svc_scene_release(svc, r);
    return pst;
  }
  pthread_mutex_lock(&r->lock);
  /* Wait out a render that borrows the base (renders.c); views keep
   * rendering the revision they were built at. */
  while (r->base_busy) pthread_cond_wait(&r->cond, &r->lock);
  rsw_status st = RSW_OK;
  param_update *u = NULL;
  size_t n = 0;
  update_report rep = {0};
  if (r->broken)
    st = svc_fail(e, RSW_ERR_UNAVAILABLE, r->id,
                  "the scene's base state was lost (restoring it after a render ran out of memory): delete "
                  "the scene and post it again");
  else if (if_match >= 0 && (uint64_t)if_match != r->revision)
    st =
        svc_fail(e, RSW_ERR_PRECONDITION, "If-Match", "revision %lld is stale: the scene is at revision %llu",
                 (long long)if_match, (unsigned long long)r->revision);
  if (!st) st = svc_map_to_updates(j, r->sc, "body", &u, &n, e);
  /* What the update is recorded as (for a reload; for views, which
   * replay it), built first: a PATCH that could not record itself fails
   * before it changes anything. */
  cJSON *patches = NULL;
  if (!st && r->patches) {
    patches = svc_patch_merged(r->patches, j, r->sc);
    if (!patches) st = svc_fail(e, RSW_ERR_NOMEM, "body", "out of memory");
  }
  /* With a state directory the PATCH is acknowledged only once stored:
   * the keys' values before it, to undo it if it cannot be. */
  param_update *before = NULL;
  if (!st && svc_state_on(svc) && r->patches) {
    rsw_err err = {0};
    st = svc_param_snapshot(r->sc, u, n, &before, &err);
    if (st) st = svc_update_error(e, r->sc, u, n, &err);
  }
  if (!st) {
    rsw_err err = {0};
    st = scene_update(r->sc, u, n, &rep, &err);
    if (st) st = svc_update_error(e, r->sc, u, n, &err);
  }
  if (!st && rep.changed) {
    uint64_t old_revision = r->revision;
    cJSON *old_patches = NULL;
    r->revision++;
    if (patches) {
      old_patches = r->patches;
      r->patches = patches; /* views replay it, --state-dir stores it */
      patches = NULL;
    }
    st = svc_scene_patched(svc, r, e);
    if (st) {
      /* Not stored: the scene back to its revision (the same values, so
       * bitwise), and the record to the previous state in case the
       * failure came after the rename (best effort). */
      rsw_err uerr = {0};
      svc_error ignored = {0};
      r->revision = old_revision;
      patches = r->patches;
      r->patches = old_patches;
      old_patches = NULL;
      if (!before || scene_update(r->sc, before, n, NULL, &uerr) != RSW_OK) r->broken = true;
      (void)svc_state_scene_patched(svc, r, &ignored);
    }
    cJSON_Delete(old_patches);
    (void)svc_refresh_param_cache(r); /* out of memory: stale, rebuilt by the next GET */
    svc_views_free(r);                /* idle views of the old revision */
  }
  for (size_t i = 0; before && i < n; i++) param_value_free(&before[i].value);
  free(before);
  cJSON_Delete(patches);
  *revision_out = r->revision;
  cJSON *o = NULL;
  if (!st) {
    o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "revision", (double)r->revision);
    cJSON_AddNumberToObject(o, "changed", (double)rep.changed);
    cJSON *c = cJSON_AddArrayToObject(o, "classes");
    if (rep.classes & UPDATE_SPECTRAL) svc_json_push(c, cJSON_CreateString("spectral"));
    if (rep.classes & UPDATE_GEOMETRIC) svc_json_push(c, cJSON_CreateString("geometric"));
    cJSON_AddNumberToObject(o, "seconds", rep.seconds);
  }
  pthread_mutex_unlock(&r->lock);
  if (!st) svc_count_update(svc, &rep);
  svc_free_updates(u, n);
  cJSON_Delete(j);
  svc_scene_release(svc, r);
  if (st) return st;
  return svc_json_out(json_out, o, jm, e);
}
