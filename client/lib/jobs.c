/* Jobs: the context builder (a JobRequest document under construction),
 * submit, status, wait (server-sent events, with a polling fallback),
 * cancel, delete, results and fetch. */
#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "bundle_plan.h"
#include "internal.h"

/* ---- the context builder ------------------------------------------------------------ */

/* Most contexts one job may have (the daemon's limit as well). */
#define MAX_CONTEXTS 100000

struct rsw_contexts {
  cJSON *root;   /* the JobRequest: {contexts, defaults?, params?, seed?} */
  cJSON *list;   /* root.contexts */
  cJSON **items; /* items[i] is contexts[i]: O(1) access by index */
  size_t n, cap;
};

rsw_status rsw_contexts_new(rsw_contexts **out) {
  if (!out) return RSW_ERR_INVALID;
  rsw_contexts *x = calloc(1, sizeof *x);
  if (!x) return RSW_ERR_NOMEM;
  x->root = cJSON_CreateObject();
  x->list = x->root ? cJSON_AddArrayToObject(x->root, "contexts") : NULL;
  if (!x->list) {
    rsw_contexts_free(x);
    return RSW_ERR_NOMEM;
  }
  *out = x;
  return RSW_OK;
}

void rsw_contexts_free(rsw_contexts *x) {
  if (!x) return;
  cJSON_Delete(x->root);
  free(x->items);
  free(x);
}

size_t rsw_contexts_count(const rsw_contexts *x) {
  return x ? x->n : 0;
}

static bool valid_context_id(const char *id) {
  size_t n = 0;
  for (const char *p = id; *p; p++, n++) {
    bool ok = (*p >= 'A' && *p <= 'Z') || (*p >= 'a' && *p <= 'z') || (*p >= '0' && *p <= '9') || *p == '.' ||
              *p == '_' || *p == '-';
    if (!ok) return false;
  }
  return n >= 1 && n <= 64;
}

rsw_status rsw_contexts_add(rsw_contexts *x, const char *id, double wavelength, size_t *index) {
  if (!x || !id || !valid_context_id(id)) return RSW_ERR_INVALID;
  if (x->n >= MAX_CONTEXTS) return RSW_ERR_LIMIT;
  if (x->n == x->cap) {
    size_t cap = x->cap ? 2 * x->cap : 64;
    cJSON **v = realloc(x->items, cap * sizeof *v);
    if (!v) return RSW_ERR_NOMEM;
    x->items = v;
    x->cap = cap;
  }
  cJSON *o = cJSON_CreateObject();
  if (!o || !cJSON_AddStringToObject(o, "id", id) ||
      (wavelength > 0 && !cJSON_AddNumberToObject(o, "wavelength", wavelength))) {
    cJSON_Delete(o);
    return RSW_ERR_NOMEM;
  }
  if (!cJSON_AddItemToArray(x->list, o)) {
    cJSON_Delete(o);
    return RSW_ERR_NOMEM;
  }
  x->items[x->n] = o;
  if (index) *index = x->n;
  x->n++;
  return RSW_OK;
}

/* obj[name] as an object or array, created when absent. */
static cJSON *child(cJSON *obj, const char *name, bool array) {
  cJSON *v = cJSON_GetObjectItemCaseSensitive(obj, name);
  if (v) return v;
  return array ? cJSON_AddArrayToObject(obj, name) : cJSON_AddObjectToObject(obj, name);
}

/* Set map[key] = parsed value_json (replacing an earlier value). */
static rsw_status set_in_map(cJSON *map, const char *key, const char *value_json) {
  if (!map) return RSW_ERR_NOMEM;
  if (!key || !*key || !value_json) return RSW_ERR_INVALID;
  cJSON *v = cJSON_Parse(value_json);
  if (!v) return RSW_ERR_PARSE;
  cJSON_DeleteItemFromObjectCaseSensitive(map, key);
  if (!cJSON_AddItemToObject(map, key, v)) {
    cJSON_Delete(v);
    return RSW_ERR_NOMEM;
  }
  return RSW_OK;
}

static rsw_status add_string(cJSON *arr, const char *s) {
  if (!arr) return RSW_ERR_NOMEM;
  if (!s || !*s) return RSW_ERR_INVALID;
  cJSON *v = cJSON_CreateString(s);
  if (!v || !cJSON_AddItemToArray(arr, v)) {
    cJSON_Delete(v);
    return RSW_ERR_NOMEM;
  }
  return RSW_OK;
}

/* obj[name] = value, or removed when value < 0. */
static rsw_status set_int(cJSON *obj, const char *name, long long value) {
  if (!obj) return RSW_ERR_NOMEM;
  cJSON_DeleteItemFromObjectCaseSensitive(obj, name);
  if (value < 0) return RSW_OK;
  /* JSON numbers are doubles here: integers up to 2^53 are exact. */
  if (value > (1LL << 53)) return RSW_ERR_RANGE;
  return cJSON_AddNumberToObject(obj, name, (double)value) ? RSW_OK : RSW_ERR_NOMEM;
}

rsw_status rsw_contexts_set_param(rsw_contexts *x, size_t index, const char *key, const char *value_json) {
  if (!x || index >= x->n) return RSW_ERR_INVALID;
  return set_in_map(child(x->items[index], "params", false), key, value_json);
}

rsw_status rsw_contexts_set_coord(rsw_contexts *x, size_t index, const char *name, const char *value_json) {
  if (!x || index >= x->n || !name || !value_json) return RSW_ERR_INVALID;
  cJSON *v = cJSON_Parse(value_json);
  bool ok = cJSON_IsNumber(v) || cJSON_IsString(v);
  cJSON_Delete(v);
  if (!ok) return v ? RSW_ERR_TYPE : RSW_ERR_PARSE;
  return set_in_map(child(x->items[index], "coords", false), name, value_json);
}

rsw_status rsw_contexts_add_sensor(rsw_contexts *x, size_t index, const char *sensor) {
  if (!x || index >= x->n) return RSW_ERR_INVALID;
  return add_string(child(x->items[index], "sensors", true), sensor);
}

rsw_status rsw_contexts_set_spp(rsw_contexts *x, size_t index, long long spp) {
  if (!x || index >= x->n || spp == 0) return RSW_ERR_INVALID;
  return set_int(x->items[index], "spp", spp);
}

rsw_status rsw_contexts_set_seed(rsw_contexts *x, size_t index, long long seed) {
  if (!x || index >= x->n) return RSW_ERR_INVALID;
  return set_int(x->items[index], "seed", seed);
}

rsw_status rsw_contexts_set_job_param(rsw_contexts *x, const char *key, const char *value_json) {
  if (!x) return RSW_ERR_INVALID;
  return set_in_map(child(x->root, "params", false), key, value_json);
}

rsw_status rsw_contexts_add_default_sensor(rsw_contexts *x, const char *sensor) {
  if (!x) return RSW_ERR_INVALID;
  cJSON *d = child(x->root, "defaults", false);
  return add_string(d ? child(d, "sensors", true) : NULL, sensor);
}

rsw_status rsw_contexts_set_default_spp(rsw_contexts *x, long long spp) {
  if (!x || spp == 0) return RSW_ERR_INVALID;
  return set_int(child(x->root, "defaults", false), "spp", spp);
}

rsw_status rsw_contexts_set_job_seed(rsw_contexts *x, long long seed) {
  if (!x) return RSW_ERR_INVALID;
  return set_int(x->root, "seed", seed);
}

rsw_status rsw_contexts_set_quantities(rsw_contexts *x, const char *const *names, size_t n) {
  if (!x || (n && !names)) return RSW_ERR_INVALID;
  cJSON *a = cJSON_CreateArray();
  for (size_t i = 0; a && i < n; i++) {
    cJSON *q = names[i] ? cJSON_CreateString(names[i]) : NULL;
    if (!q || !cJSON_AddItemToArray(a, q)) {
      cJSON_Delete(q);
      cJSON_Delete(a);
      return names[i] ? RSW_ERR_NOMEM : RSW_ERR_INVALID;
    }
  }
  if (!a) return RSW_ERR_NOMEM;
  cJSON_DeleteItemFromObjectCaseSensitive(x->root, "quantities");
  if (!n) {
    cJSON_Delete(a);
    return RSW_OK;
  }
  if (!cJSON_AddItemToObject(x->root, "quantities", a)) {
    cJSON_Delete(a);
    return RSW_ERR_NOMEM;
  }
  return RSW_OK;
}

rsw_status rsw_contexts_set_variance(rsw_contexts *x, int on) {
  if (!x) return RSW_ERR_INVALID;
  cJSON_DeleteItemFromObjectCaseSensitive(x->root, "variance");
  if (on && !cJSON_AddBoolToObject(x->root, "variance", 1)) return RSW_ERR_NOMEM;
  return RSW_OK;
}

rsw_status rsw_contexts_set_bundle(rsw_contexts *x, int k) {
  if (!x || (k < 1 && k != RSW_BUNDLE_AUTO)) return RSW_ERR_INVALID;
  cJSON_DeleteItemFromObjectCaseSensitive(x->root, "bundle");
  if (k == RSW_BUNDLE_AUTO)
    return cJSON_AddStringToObject(x->root, "bundle", "auto") ? RSW_OK : RSW_ERR_NOMEM;
  return cJSON_AddNumberToObject(x->root, "bundle", k) ? RSW_OK : RSW_ERR_NOMEM;
}

rsw_status rsw_contexts_set_bundle_group(rsw_contexts *x, size_t index, long long group) {
  if (!x || index >= x->n) return RSW_ERR_INVALID;
  return set_int(x->items[index], "bundle_group", group);
}

rsw_status rsw_contexts_set_templates(rsw_contexts *x, const char *templates_json) {
  if (!x) return RSW_ERR_INVALID;
  cJSON_DeleteItemFromObjectCaseSensitive(x->root, "templates");
  if (!templates_json || !*templates_json) return RSW_OK;
  cJSON *t = cJSON_Parse(templates_json);
  if (!t) return RSW_ERR_PARSE;
  if (!cJSON_IsObject(t)) {
    cJSON_Delete(t);
    return RSW_ERR_TYPE;
  }
  if (!cJSON_AddItemToObject(x->root, "templates", t)) {
    cJSON_Delete(t);
    return RSW_ERR_NOMEM;
  }
  return RSW_OK;
}

/* ---- submit and status ---------------------------------------------------------------- */

/* "/v1/jobs/<escaped id><suffix>" into path; false when too long. */
static bool job_path(const char *job_id, const char *suffix, char *path, size_t cap) {
  char esc[256];
  if (!job_id || !client_escape(job_id, esc, sizeof esc)) return false;
  int n = snprintf(path, cap, "/v1/jobs/%s%s", esc, suffix);
  return n > 0 && (size_t)n < cap;
}

/* POST body (a JobRequest) to scene_id's jobs; the answer's id. */
static rsw_status submit_body(rsw_client *c, const char *path, const char *body, const char *idempotency_key,
                              char job_id_out[40]) {
  http_resp r;
  rsw_status s = http_request(c,
                              &(http_req){.method = "POST",
                                          .path = path,
                                          .content_type = "application/json",
                                          .body = body,
                                          .body_len = strlen(body),
                                          .idempotency_key = idempotency_key,
                                          .computed = true},
                              &r);
  if (s) return s;
  cJSON *a = cJSON_ParseWithLength(r.body, r.len);
  const cJSON *id = cJSON_GetObjectItemCaseSensitive(a, "id");
  if (!cJSON_IsString(id) || !*id->valuestring || strlen(id->valuestring) >= 40)
    s = client_fail(c, RSW_ERR_PARSE, "POST %s: the answer has no job \"id\" (under 40 characters)", path);
  else
    snprintf(job_id_out, 40, "%s", id->valuestring);
  cJSON_Delete(a);
  http_resp_free(&r);
  return s;
}

/* A submission's start: the client's last error cleared, job_id_out
 * given, and "/v1/scenes/<escaped id>/jobs" into path (300 bytes). */
static rsw_status submit_start(rsw_client *c, const char *scene_id, const char *job_id_out, char path[300]) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char esc[256];
  if (!scene_id || !client_escape(scene_id, esc, sizeof esc))
    return client_fail(c, RSW_ERR_INVALID, "scene id missing or too long");
  if (!job_id_out) return client_fail(c, RSW_ERR_INVALID, "job submit: no job_id_out");
  snprintf(path, 300, "/v1/scenes/%s/jobs", esc);
  return RSW_OK;
}

rsw_status rsw_job_submit(rsw_client *c, const char *scene_id, const rsw_contexts *x,
                          const char *idempotency_key, char job_id_out[40]) {
  char path[300];
  rsw_status s = submit_start(c, scene_id, job_id_out, path);
  if (s) return s;
  if (!x || !x->n) return client_fail(c, RSW_ERR_INVALID, "job submit: no contexts");
  char *body = cJSON_PrintUnformatted(x->root);
  if (!body) return client_fail(c, RSW_ERR_NOMEM, "cannot print the job request");
  s = submit_body(c, path, body, idempotency_key, job_id_out);
  free(body);
  return s;
}

rsw_status rsw_job_submit_json(rsw_client *c, const char *scene_id, const char *request_json,
                               const char *idempotency_key, char job_id_out[40]) {
  char path[300];
  rsw_status s = submit_start(c, scene_id, job_id_out, path);
  if (s) return s;
  if (!request_json) return client_fail(c, RSW_ERR_INVALID, "job submit: no request");
  cJSON *j = cJSON_Parse(request_json);
  bool object = cJSON_IsObject(j);
  cJSON_Delete(j);
  if (!object) return client_fail(c, RSW_ERR_PARSE, "job submit: the request is not a JSON object");
  return submit_body(c, path, request_json, idempotency_key, job_id_out);
}

static const struct {
  const char *name;
  rsw_job_state state;
} job_states[] = {
    {"queued", RSW_JOB_QUEUED}, {"running", RSW_JOB_RUNNING},     {"succeeded", RSW_JOB_SUCCEEDED},
    {"failed", RSW_JOB_FAILED}, {"cancelled", RSW_JOB_CANCELLED},
};

static bool state_from_name(const char *name, rsw_job_state *out) {
  for (size_t i = 0; i < sizeof job_states / sizeof job_states[0]; i++)
    if (strcmp(job_states[i].name, name) == 0) {
      *out = job_states[i].state;
      return true;
    }
  return false;
}

static bool is_final(rsw_job_state s) {
  return s == RSW_JOB_SUCCEEDED || s == RSW_JOB_FAILED || s == RSW_JOB_CANCELLED;
}

static size_t count_of(const cJSON *o, const char *name) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, name);
  return cJSON_IsNumber(v) && v->valuedouble > 0 ? (size_t)v->valuedouble : 0;
}

/* Decode a Job document. */
static rsw_status job_decode(rsw_client *c, const char *text, size_t len, const char *what,
                             rsw_job_status *out) {
  cJSON *a = cJSON_ParseWithLength(text, len);
  const cJSON *st = cJSON_GetObjectItemCaseSensitive(a, "state");
  rsw_job_status j = {0};
  if (!cJSON_IsString(st) || !state_from_name(st->valuestring, &j.state)) {
    cJSON_Delete(a);
    return client_fail(c, RSW_ERR_PARSE, "%s: the answer has no job \"state\"", what);
  }
  j.contexts_total = count_of(a, "contexts_total");
  j.contexts_done = count_of(a, "contexts_done");
  j.renders_total = count_of(a, "renders_total");
  j.renders_done = count_of(a, "renders_done");
  j.renders_failed = count_of(a, "renders_failed");
  const cJSON *secs = cJSON_GetObjectItemCaseSensitive(a, "seconds");
  j.seconds = cJSON_IsNumber(secs) ? secs->valuedouble : 0.0;
  const cJSON *err = cJSON_GetObjectItemCaseSensitive(a, "error");
  if (cJSON_IsString(err)) snprintf(j.error, sizeof j.error, "%s", err->valuestring);
  cJSON_Delete(a);
  *out = j;
  return RSW_OK;
}

rsw_status rsw_job_get(rsw_client *c, const char *job_id, rsw_job_status *out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char path[320];
  if (!job_path(job_id, "", path, sizeof path))
    return client_fail(c, RSW_ERR_INVALID, "job id missing or too long");
  if (!out) return client_fail(c, RSW_ERR_INVALID, "job get: out is NULL");
  http_resp r;
  rsw_status s = http_request(c, &(http_req){.method = "GET", .path = path}, &r);
  if (s) return s;
  char what[340];
  snprintf(what, sizeof what, "GET %s", path);
  s = job_decode(c, r.body, r.len, what, out);
  http_resp_free(&r);
  return s;
}

/* A Job's (or JobDryRun's) warnings as rsw_job_warnings' text into *text_out
 * (NULL when none). */
static rsw_status warnings_text(rsw_client *c, const cJSON *a, char **text_out) {
  *text_out = NULL;
  const cJSON *w = cJSON_GetObjectItemCaseSensitive(a, "warnings");
  size_t n = 0;
  for (int pass = 0; pass < 2 && cJSON_IsArray(w) && w->child; pass++) {
    size_t at = 0;
    for (const cJSON *x = w->child; x; x = x->next) {
      const cJSON *code = cJSON_GetObjectItemCaseSensitive(x, "code");
      const cJSON *coord = cJSON_GetObjectItemCaseSensitive(x, "coordinate");
      const cJSON *detail = cJSON_GetObjectItemCaseSensitive(x, "detail");
      int k = snprintf(pass ? *text_out + at : NULL, pass ? n + 1 - at : 0, "%s%s (%s): %s", at ? "\n" : "",
                       cJSON_IsString(code) ? code->valuestring : "?",
                       cJSON_IsString(coord) ? coord->valuestring : "?",
                       cJSON_IsString(detail) ? detail->valuestring : "");
      at += k > 0 ? (size_t)k : 0;
    }
    if (!pass && !(*text_out = malloc((n = at) + 1))) return client_fail(c, RSW_ERR_NOMEM, "out of memory");
  }
  return RSW_OK;
}

rsw_status rsw_job_warnings(rsw_client *c, const char *job_id, char **text_out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char path[320];
  if (!job_path(job_id, "", path, sizeof path))
    return client_fail(c, RSW_ERR_INVALID, "job id missing or too long");
  if (!text_out) return client_fail(c, RSW_ERR_INVALID, "job warnings: text_out is NULL");
  *text_out = NULL;
  http_resp r;
  rsw_status s = http_request(c, &(http_req){.method = "GET", .path = path}, &r);
  if (s) return s;
  cJSON *a = cJSON_ParseWithLength(r.body, r.len);
  http_resp_free(&r);
  if (!a) return client_fail(c, RSW_ERR_PARSE, "GET %s: the answer is not JSON", path);
  s = warnings_text(c, a, text_out);
  cJSON_Delete(a);
  return s;
}

rsw_status rsw_job_check(rsw_client *c, const char *scene_id, const rsw_contexts *x, size_t *renders_out,
                         char **warnings_out) {
  char path[300], unused[40];
  rsw_status s = submit_start(c, scene_id, unused, path);
  if (s) return s;
  if (!x || !x->n) return client_fail(c, RSW_ERR_INVALID, "job check: no contexts");
  if (warnings_out) *warnings_out = NULL;
  char *body = cJSON_PrintUnformatted(x->root);
  if (!body) return client_fail(c, RSW_ERR_NOMEM, "cannot print the job request");
  strcat(path, "?dry_run=1");
  http_resp r;
  s = http_request(c,
                   &(http_req){.method = "POST",
                               .path = path,
                               .content_type = "application/json",
                               .body = body,
                               .body_len = strlen(body),
                               .computed = true},
                   &r);
  free(body);
  if (s) return s;
  cJSON *a = cJSON_ParseWithLength(r.body, r.len);
  http_resp_free(&r);
  if (!cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(a, "dry_run"))) {
    /* A daemon from before ?dry_run queued it: take the job back. */
    const cJSON *id = cJSON_GetObjectItemCaseSensitive(a, "id");
    if (cJSON_IsString(id)) rsw_job_delete(c, id->valuestring);
    cJSON_Delete(a);
    return client_fail(c, RSW_ERR_UNSUPPORTED,
                       "POST %s: the daemon has no dry runs (a job was queued, and deleted)", path);
  }
  const cJSON *n = cJSON_GetObjectItemCaseSensitive(a, "renders_total");
  if (renders_out) *renders_out = cJSON_IsNumber(n) && n->valuedouble >= 0 ? (size_t)n->valuedouble : 0;
  s = warnings_out ? warnings_text(c, a, warnings_out) : RSW_OK;
  cJSON_Delete(a);
  return s;
}

rsw_status rsw_job_cancel(rsw_client *c, const char *job_id) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char path[320];
  if (!job_path(job_id, ":cancel", path, sizeof path))
    return client_fail(c, RSW_ERR_INVALID, "job id missing or too long");
  http_resp r;
  rsw_status s = http_request(c, &(http_req){.method = "POST", .path = path}, &r);
  if (!s) http_resp_free(&r);
  return s;
}

rsw_status rsw_job_delete(rsw_client *c, const char *job_id) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char path[320];
  if (!job_path(job_id, "", path, sizeof path))
    return client_fail(c, RSW_ERR_INVALID, "job id missing or too long");
  http_resp r;
  rsw_status s = http_request(c, &(http_req){.method = "DELETE", .path = path}, &r);
  if (!s) http_resp_free(&r);
  return s;
}

rsw_status rsw_job_list(rsw_client *c, char **json_out) {
  if (!c) return RSW_ERR_INVALID;
  return client_get_text(c, "/v1/jobs", json_out);
}

rsw_status rsw_job_results(rsw_client *c, const char *job_id, char **json_out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char path[320];
  if (!job_path(job_id, "/results", path, sizeof path))
    return client_fail(c, RSW_ERR_INVALID, "job id missing or too long");
  return client_get_text(c, path, json_out);
}

/* GET /v1/jobs/{id}/results/{context}/{sensor} as accept: path[900]
 * names it for messages. */
static rsw_status fetch_result(rsw_client *c, const char *job_id, const char *context, const char *sensor,
                               const char *accept, char path[900], http_resp *r) {
  char ctx[256], sen[256], suffix[540];
  memset(r, 0, sizeof *r);
  if (!context || !sensor || !client_escape(context, ctx, sizeof ctx) ||
      !client_escape(sensor, sen, sizeof sen))
    return client_fail(c, RSW_ERR_INVALID, "fetch: context and sensor must be given (under 85 characters)");
  snprintf(suffix, sizeof suffix, "/results/%s/%s", ctx, sen);
  if (!job_path(job_id, suffix, path, 900))
    return client_fail(c, RSW_ERR_INVALID, "job id missing or too long");
  return http_request(c, &(http_req){.method = "GET", .path = path, .accept = accept}, r);
}

rsw_status rsw_job_fetch(rsw_client *c, const char *job_id, const char *context, const char *sensor,
                         rsw_film **film_out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  if (!film_out) return client_fail(c, RSW_ERR_INVALID, "fetch: film_out is NULL");
  char path[900];
  http_resp r;
  rsw_status s = fetch_result(c, job_id, context, sensor, "application/json", path, &r);
  if (s) return s;
  char what[920];
  snprintf(what, sizeof what, "GET %s", path);
  s = film_from_json(c, r.body, r.len, what, film_out);
  http_resp_free(&r);
  return s;
}

/* The media types rsw_job_fetch_encoded takes, and how each file starts:
 * OpenEXR's magic number 20000630 little-endian, NumPy's "\x93NUMPY",
 * PNG's signature, a JSON object. */
static const struct {
  const char *type;
  const char *magic;
  size_t magic_len;
} film_encodings[] = {
    {"image/x-exr", "\x76\x2f\x31\x01", 4},
    {"application/x-npy", "\x93NUMPY", 6},
    {"image/png", "\x89PNG\r\n\x1a\n", 8},
    {"application/json", "{", 1},
};

#define N_FILM_ENCODINGS (sizeof film_encodings / sizeof film_encodings[0])

/* The index of media_type in film_encodings, or N_FILM_ENCODINGS. */
static size_t film_encoding(const char *media_type) {
  size_t e = 0;
  while (e < N_FILM_ENCODINGS && !(media_type && strcmp(media_type, film_encodings[e].type) == 0)) e++;
  return e;
}

bool client_film_media_type_known(const char *media_type) {
  return film_encoding(media_type) < N_FILM_ENCODINGS;
}

rsw_status rsw_job_fetch_encoded(rsw_client *c, const char *job_id, const char *context, const char *sensor,
                                 const char *media_type, void **bytes_out, size_t *len_out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  if (!bytes_out || !len_out) return client_fail(c, RSW_ERR_INVALID, "fetch: bytes_out or len_out is NULL");
  *bytes_out = NULL, *len_out = 0;
  size_t e = film_encoding(media_type);
  if (e == N_FILM_ENCODINGS)
    return client_fail(c, RSW_ERR_INVALID,
                       "fetch: media type '%s' is none of image/x-exr, application/x-npy, image/png, "
                       "application/json",
                       media_type ? media_type : "(null)");
  char path[900];
  http_resp r;
  rsw_status s = fetch_result(c, job_id, context, sensor, media_type, path, &r);
  if (s) return s;
  /* The answer must be what was asked for: a server (or a proxy) that
   * ignored Accept would otherwise leave, say, JSON in a .exr file. */
  size_t tl = strcspn(r.content_type, "; \t");
  if (tl != strlen(media_type) || strncasecmp(r.content_type, media_type, tl) != 0 ||
      r.len < film_encodings[e].magic_len ||
      memcmp(r.body, film_encodings[e].magic, film_encodings[e].magic_len) != 0) {
    s = client_fail(c, RSW_ERR_PARSE, "GET %s: asked for %s, the answer is %s%s", path, media_type,
                    r.content_type[0] ? r.content_type : "of no type",
                    tl == strlen(media_type) && strncasecmp(r.content_type, media_type, tl) == 0
                        ? " but does not start as one"
                        : "");
    http_resp_free(&r);
    return s;
  }
  *bytes_out = r.body, *len_out = r.len;
  return RSW_OK;
}

/* One part of a multipart/mixed answer at *p (end): its headers' Content-Location and
 * Content-Length, its bytes; *p moves past it. false when malformed. */
static bool next_part(const char **p, const char *end, const char *dash_boundary, size_t bl, char loc[600],
                      const char **bytes, size_t *len) {
  const char *q = *p;
  if ((size_t)(end - q) < bl + 2 || memcmp(q, dash_boundary, bl) != 0 || memcmp(q + bl, "\r\n", 2) != 0)
    return false;
  q += bl + 2;
  loc[0] = '\0';
  bool has_len = false;
  for (;;) { /* header lines up to the empty one */
    const char *eol = memmem(q, (size_t)(end - q), "\r\n", 2);
    if (!eol) return false;
    size_t n = (size_t)(eol - q);
    if (n == 0) {
      q = eol + 2;
      break;
    }
    if (n > 16 && strncasecmp(q, "Content-Length: ", 16) == 0) {
      char num[24];
      if (n - 16 >= sizeof num) return false;
      memcpy(num, q + 16, n - 16);
      num[n - 16] = '\0';
      char *e;
      unsigned long long v = strtoull(num, &e, 10);
      if (*e || e == num) return false;
      *len = (size_t)v, has_len = true;
    } else if (n > 18 && strncasecmp(q, "Content-Location: ", 18) == 0 && n - 18 < 600) {
      memcpy(loc, q + 18, n - 18);
      loc[n - 18] = '\0';
    }
    q = eol + 2;
  }
  if (!has_len || (size_t)(end - q) < *len + 2 || memcmp(q + *len, "\r\n", 2) != 0) return false;
  *bytes = q;
  *p = q + *len + 2;
  return true;
}

rsw_status client_job_fetch_encoded_many(rsw_client *c, const char *job_id, size_t n,
                                         const char *const *contexts, const char *const *sensors,
                                         const char *media_type, char **answer_out, const void **bytes_out,
                                         size_t *len_out) {
  size_t e = film_encoding(media_type);
  *answer_out = NULL;
  if (e == N_FILM_ENCODINGS || n == 0 || n > CLIENT_FETCH_MAX)
    return client_fail(c, RSW_ERR_INVALID, "fetch: bad batch");
  for (size_t i = 0; i < n; i++) bytes_out[i] = NULL, len_out[i] = 0;
  char path[900];
  if (!job_path(job_id, "/results:fetch", path, sizeof path))
    return client_fail(c, RSW_ERR_INVALID, "job id missing or too long");
  cJSON *req = cJSON_CreateObject();
  cJSON *a = cJSON_AddArrayToObject(req, "results");
  for (size_t i = 0; i < n; i++) {
    cJSON *x = cJSON_CreateObject();
    cJSON_AddStringToObject(x, "context", contexts[i]);
    cJSON_AddStringToObject(x, "sensor", sensors[i]);
    cJSON_AddItemToArray(a, x);
  }
  char *body = cJSON_PrintUnformatted(req);
  cJSON_Delete(req);
  if (!body) return client_fail(c, RSW_ERR_NOMEM, "out of memory");
  http_resp r;
  memset(&r, 0, sizeof r);
  rsw_status s = http_request(c,
                              &(http_req){.method = "POST",
                                          .path = path,
                                          .content_type = "application/json",
                                          .body = body,
                                          .body_len = strlen(body),
                                          .accept = media_type},
                              &r);
  free(body);
  if (s) return s;
  /* multipart/mixed; boundary=B: the parts in the order asked for, each
   * what GET .../results/{context}/{sensor} answers. */
  const char *bp = strstr(r.content_type, "boundary=");
  char dash[96];
  size_t bl = 0;
  if (strncasecmp(r.content_type, "multipart/mixed", 15) == 0 && bp) {
    bp += 9;
    size_t n_b = strcspn(bp, "; \t");
    if (n_b > 0 && n_b < 70) bl = (size_t)snprintf(dash, sizeof dash, "--%.*s", (int)n_b, bp);
  }
  const char *p = r.body, *end = r.body + r.len;
  for (size_t i = 0; i < n && !s; i++) {
    char loc[600], want[600], ce[256], se[256];
    const char *bytes;
    size_t len = 0;
    if (!bl || !next_part(&p, end, dash, bl, loc, &bytes, &len)) {
      s = client_fail(c, RSW_ERR_PARSE, "POST %s: the answer is not the multipart/mixed asked for", path);
      break;
    }
    snprintf(want, sizeof want, "/results/%s/%s", client_escape(contexts[i], ce, sizeof ce) ? ce : "?",
             client_escape(sensors[i], se, sizeof se) ? se : "?");
    size_t wl = strlen(want), ll = strlen(loc);
    if (ll < wl || strcmp(loc + ll - wl, want) != 0 || len < film_encodings[e].magic_len ||
        memcmp(bytes, film_encodings[e].magic, film_encodings[e].magic_len) != 0) {
      s = client_fail(c, RSW_ERR_PARSE, "POST %s: part %zu is not the %s of %s/%s", path, i, media_type,
                      contexts[i], sensors[i]);
      break;
    }
    bytes_out[i] = bytes, len_out[i] = len;
  }
  if (!s && ((size_t)(end - p) < bl + 2 || memcmp(p, dash, bl) != 0 || memcmp(p + bl, "--", 2) != 0))
    s = client_fail(c, RSW_ERR_PARSE, "POST %s: the multipart answer does not end as it should", path);
  if (s) {
    for (size_t i = 0; i < n; i++) bytes_out[i] = NULL, len_out[i] = 0;
    http_resp_free(&r);
    return s;
  }
  *answer_out = r.body; /* the parts' bytes: taken over */
  return RSW_OK;
}

/* ---- wait ---------------------------------------------------------------------------- */

/* One server-sent event being assembled (text/event-stream, WHATWG HTML
 * "server-sent events": lines "field: value", a blank line dispatches,
 * lines starting with ':' are comments such as the daemon's ": ping"). */
typedef struct sse_state {
  rsw_client *c;
  char event[32];
  char *data; /* data lines joined with '\n' */
  size_t data_len, data_cap;
  char pending_id[32]; /* the id: of the event being assembled */
  char last_id[32];    /* of the last dispatched event: Last-Event-ID */
  bool ended;          /* `event: end` seen */
  bool user_stop;      /* the progress callback asked to stop */
  bool gone;           /* `event: error` (the job went away) */
  char gone_detail[512];
  size_t events; /* context events dispatched (progress made) */
  rsw_progress_fn progress;
  void *user;
} sse_state;

static bool data_append(sse_state *s, const char *p, size_t n) {
  if (s->data_len + n + 2 > CLIENT_MAX_SSE_EVENT) return false;
  if (s->data_len + n + 2 > s->data_cap) {
    size_t cap = s->data_cap ? s->data_cap : 256;
    while (cap < s->data_len + n + 2) cap *= 2;
    char *q = realloc(s->data, cap);
    if (!q) return false;
    s->data = q;
    s->data_cap = cap;
  }
  if (s->data_len) s->data[s->data_len++] = '\n';
  memcpy(s->data + s->data_len, p, n);
  s->data_len += n;
  s->data[s->data_len] = '\0';
  return true;
}

static const char *jstr(const cJSON *o, const char *name) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, name);
  return cJSON_IsString(v) ? v->valuestring : NULL;
}

/* A blank line: act on the event assembled so far. Returns non-zero to
 * stop the stream. */
static int sse_dispatch(sse_state *s) {
  int stop = 0;
  if (s->pending_id[0]) memcpy(s->last_id, s->pending_id, sizeof s->last_id);
  cJSON *d = s->data_len ? cJSON_ParseWithLength(s->data, s->data_len) : NULL;
  if (strcmp(s->event, "context") == 0 && d) {
    const char *ctx = jstr(d, "context"), *sensor = jstr(d, "sensor"), *state = jstr(d, "state");
    s->events++;
    if (s->progress && s->progress(s->user, ctx ? ctx : "", sensor ? sensor : "", count_of(d, "done"),
                                   count_of(d, "total"), state && strcmp(state, "failed") == 0)) {
      s->user_stop = true;
      stop = 1;
    }
  } else if (strcmp(s->event, "end") == 0) {
    s->ended = true;
    stop = 1;
  } else if (strcmp(s->event, "error") == 0) {
    const char *detail = jstr(d, "detail");
    snprintf(s->gone_detail, sizeof s->gone_detail, "%s", detail ? detail : "the job's event stream failed");
    s->gone = true;
    stop = 1;
  }
  cJSON_Delete(d);
  s->event[0] = '\0';
  s->pending_id[0] = '\0';
  s->data_len = 0;
  return stop;
}

static int sse_line(void *user, const char *line, size_t len) {
  sse_state *s = user;
  if (len == 0) return sse_dispatch(s);
  if (line[0] == ':') return 0; /* a comment: ": ping" keeps the connection alive */
  const char *colon = memchr(line, ':', len);
  size_t fn = colon ? (size_t)(colon - line) : len;
  const char *v = colon ? colon + 1 : line + len;
  if (v < line + len && *v == ' ') v++;
  size_t vn = (size_t)(line + len - v);
  if (fn == 5 && strncmp(line, "event", 5) == 0) {
    snprintf(s->event, sizeof s->event, "%.*s", (int)vn, v);
  } else if (fn == 4 && strncmp(line, "data", 4) == 0) {
    if (!data_append(s, v, vn)) return 1;
  } else if (fn == 2 && strncmp(line, "id", 2) == 0) {
    snprintf(s->pending_id, sizeof s->pending_id, "%.*s", (int)vn, v);
  }
  return 0; /* "retry" and unknown fields are ignored */
}

/* Polling fallback: GET the job (and its results, to report each newly
 * finished (context, sensor)) with a growing interval until it ends. */
static rsw_status wait_polling(rsw_client *c, const char *job_id, rsw_progress_fn progress, void *user,
                               double deadline, size_t skip, rsw_job_status *st) {
  char path[320];
  if (!job_path(job_id, "/results", path, sizeof path))
    return client_fail(c, RSW_ERR_INVALID, "job id too long");
  unsigned char *reported = NULL; /* reported[i]: results[i] already passed to progress */
  size_t n_reported = 0, n_done = skip;
  double interval = 0.05;
  rsw_status s;
  for (;;) {
    s = rsw_job_get(c, job_id, st);
    if (s) break;
    if (progress) {
      char *text = NULL;
      s = client_get_text(c, path, &text);
      if (s) break;
      cJSON *a = cJSON_Parse(text);
      rsw_free(text);
      const cJSON *list = cJSON_GetObjectItemCaseSensitive(a, "results");
      size_t n = (size_t)cJSON_GetArraySize(list);
      if (n > n_reported) {
        unsigned char *r = realloc(reported, n);
        if (!r) {
          cJSON_Delete(a);
          s = client_fail(c, RSW_ERR_NOMEM, "out of memory");
          break;
        }
        memset(r + n_reported, 0, n - n_reported);
        reported = r;
        n_reported = n;
      }
      size_t i = 0;
      bool stop = false;
      const cJSON *it;
      cJSON_ArrayForEach(it, list) {
        const char *state = jstr(it, "state"), *ctx = jstr(it, "context"), *sensor = jstr(it, "sensor");
        bool finished = state && (strcmp(state, "succeeded") == 0 || strcmp(state, "failed") == 0);
        if (finished && !reported[i] && !stop) {
          reported[i] = 1;
          /* The daemon renders a job's items in order, so the first
           * `skip` finished ones are those the event stream reported. */
          if (skip) {
            skip--;
          } else {
            n_done++;
            stop = progress(user, ctx ? ctx : "", sensor ? sensor : "", n_done, n,
                            strcmp(state, "failed") == 0) != 0;
          }
        }
        i++;
      }
      cJSON_Delete(a);
      if (stop) {
        s = client_fail(c, RSW_ERR_CANCELLED, "waiting for job %s stopped by the progress callback", job_id);
        break;
      }
    }
    if (is_final(st->state)) break;
    double now = client_now_s();
    if (deadline > 0 && now >= deadline) {
      s = client_fail(c, RSW_ERR_TIMEOUT, "job %s still %s at the wait limit", job_id,
                      st->state == RSW_JOB_QUEUED ? "queued" : "running");
      break;
    }
    double nap = interval;
    if (deadline > 0 && now + nap > deadline) nap = deadline - now;
    client_sleep_s(c, nap);
    if (client_interrupted(c)) {
      s = client_fail_interrupted(c, path);
      break;
    }
    if (interval < 1.0) interval *= 1.5;
  }
  free(reported);
  return s;
}

rsw_status rsw_job_wait(rsw_client *c, const char *job_id, rsw_progress_fn progress, void *user,
                        double timeout_s, rsw_job_status *final_out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char path[320];
  if (!job_path(job_id, "/events", path, sizeof path))
    return client_fail(c, RSW_ERR_INVALID, "job id missing or too long");
  double deadline = timeout_s > 0 ? client_now_s() + timeout_s : 0;
  sse_state ss = {.c = c, .progress = progress, .user = user};
  rsw_status s = RSW_OK;
  bool poll = false;
  int drops = 0; /* consecutive reconnections without progress */
  double backoff = c->retry_backoff_s;
  while (!ss.ended) {
    double left = 0;
    if (deadline > 0) {
      left = deadline - client_now_s();
      if (left <= 0) {
        s = client_fail(c, RSW_ERR_TIMEOUT, "job %s did not end within %.3g s", job_id, timeout_s);
        break;
      }
    }
    size_t before = ss.events;
    bool stopped = false, not_a_stream = false;
    http_req q = {.method = "GET",
                  .path = path,
                  .accept = "text/event-stream",
                  .last_event_id = ss.last_id[0] ? ss.last_id : NULL};
    s = http_stream(c, &q, left, sse_line, &ss, &stopped, &not_a_stream);
    ss.event[0] = ss.pending_id[0] = '\0'; /* a partial event is sent again after reconnecting */
    ss.data_len = 0;
    if (s == RSW_ERR_CANCELLED && client_interrupted(c)) break; /* the job keeps running */
    if (ss.user_stop) {
      s = client_fail(c, RSW_ERR_CANCELLED, "waiting for job %s stopped by the progress callback", job_id);
      break;
    }
    if (ss.gone) {
      s = client_fail(c, RSW_ERR_NOT_FOUND, "job %s: %s", job_id, ss.gone_detail);
      break;
    }
    if (ss.ended) {
      s = RSW_OK;
      break;
    }
    if (s == RSW_ERR_UNAUTHORIZED || s == RSW_ERR_NOT_FOUND) break;
    if (stopped) { /* a line over the event cap or no memory */
      s = client_fail(c, RSW_ERR_LIMIT, "GET %s: an event over %zu bytes", path,
                      (size_t)CLIENT_MAX_SSE_EVENT);
      break;
    }
    if (s == RSW_ERR_TIMEOUT && deadline > 0 && client_now_s() >= deadline) {
      s = client_fail(c, RSW_ERR_TIMEOUT, "job %s did not end within %.3g s", job_id, timeout_s);
      break;
    }
    /* Events unavailable (an HTTP error, or not an event stream: a proxy
     * in between, an older daemon): fall back to polling. */
    if (not_a_stream || (s != RSW_OK && s != RSW_ERR_UNAVAILABLE && s != RSW_ERR_TIMEOUT)) {
      poll = true;
      break;
    }
    /* The stream dropped before `event: end`: reconnect with Last-Event-ID,
     * backing off while no progress is made. */
    drops = ss.events > before ? 0 : drops + 1;
    if (drops > (c->max_retries > 3 ? c->max_retries : 3)) {
      poll = true; /* polling reports the daemon's own error if it is gone */
      break;
    }
    if (drops > 1) {
      client_sleep_s(c, backoff);
      backoff *= 2.0;
    } else {
      backoff = c->retry_backoff_s;
    }
  }
  free(ss.data);
  rsw_job_status st = {0};
  if (poll) {
    s = wait_polling(c, job_id, progress, user, deadline, ss.events, &st);
    if (s) return s;
  } else {
    if (s) return s;
    s = rsw_job_get(c, job_id, &st);
    if (s) return s;
  }
  if (progress) progress(user, NULL, NULL, st.renders_done, st.renders_total, st.state != RSW_JOB_SUCCEEDED);
  client_clear_error(c);
  if (final_out) *final_out = st;
  return RSW_OK;
}

/* ---- for spread.c ------------------------------------------------------------------------ */

const char *client_contexts_id(const rsw_contexts *x, size_t i) {
  return x && i < x->n ? cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(x->items[i], "id")) : NULL;
}

cJSON *client_contexts_item(const rsw_contexts *x, size_t i) {
  return x && i < x->n ? x->items[i] : NULL;
}

char *client_contexts_print(const rsw_contexts *x) {
  return x ? cJSON_PrintUnformatted(x->root) : NULL;
}

rsw_status client_contexts_subset(const rsw_contexts *x, const size_t *idx, size_t n, rsw_contexts **out) {
  if (!x || !out) return RSW_ERR_INVALID;
  rsw_contexts *y = calloc(1, sizeof *y);
  if (!y) return RSW_ERR_NOMEM;
  /* Everything of the JobRequest but the contexts, then the chosen ones. */
  y->root = cJSON_CreateObject();
  const cJSON *f;
  bool ok = y->root != NULL;
  cJSON_ArrayForEach(f, x->root) {
    if (!ok) break;
    if (strcmp(f->string, "contexts") == 0) continue;
    cJSON *d = cJSON_Duplicate(f, 1);
    ok = d && cJSON_AddItemToObject(y->root, f->string, d);
    if (!ok) cJSON_Delete(d);
  }
  y->list = ok ? cJSON_AddArrayToObject(y->root, "contexts") : NULL;
  y->items = malloc((n ? n : 1) * sizeof *y->items);
  ok = ok && y->list && y->items;
  for (size_t i = 0; i < n && ok; i++) {
    cJSON *d = idx[i] < x->n ? cJSON_Duplicate(x->items[idx[i]], 1) : NULL;
    ok = d && cJSON_AddItemToArray(y->list, d);
    if (!ok) {
      cJSON_Delete(d);
      break;
    }
    y->items[y->n++] = d;
  }
  y->cap = n;
  if (!ok) {
    rsw_contexts_free(y);
    return RSW_ERR_NOMEM;
  }
  *out = y;
  return RSW_OK;
}

typedef struct text_key {
  const char *text;
  size_t index;
} text_key;

static int cmp_text_key(const void *a, const void *b) {
  return strcmp(((const text_key *)a)->text, ((const text_key *)b)->text);
}

int client_contexts_bundle(const rsw_contexts *x) {
  const cJSON *b = x ? cJSON_GetObjectItemCaseSensitive(x->root, "bundle") : NULL;
  /* "auto", or none (the daemon's default, auto): the most any daemon takes */
  if (!b || cJSON_IsString(b)) return RSW_BUNDLE_MAX;
  return cJSON_IsNumber(b) && b->valuedouble > 1 ? (int)b->valuedouble : 1;
}

rsw_status client_contexts_bundle_leads(const rsw_contexts *x, size_t *lead) {
  size_t n = x->n;
  for (size_t i = 0; i < n; i++) lead[i] = i;
  int k = client_contexts_bundle(x);
  if (k <= 1) return RSW_OK;
  /* Contexts with a "bundle_group": the first of theirs leads. */
  text_key *g = malloc((n ? n : 1) * sizeof *g);
  char **text = calloc(n ? n : 1, sizeof *text);
  uint64_t *key = malloc((n ? n : 1) * sizeof *key);
  double *wl = malloc((n ? n : 1) * sizeof *wl);
  size_t *run = malloc((n ? n : 1) * sizeof *run);
  size_t ng = 0;
  bool ok = g && text && key && wl && run;
  for (size_t i = 0; i < n && ok; i++) {
    const cJSON *bg = cJSON_GetObjectItemCaseSensitive(x->items[i], "bundle_group");
    const cJSON *w = cJSON_GetObjectItemCaseSensitive(x->items[i], "wavelength");
    wl[i] = cJSON_IsNumber(w) ? w->valuedouble : 0;
    key[i] = RSW_BUNDLE_ALONE;
    if (bg) {
      char *t = cJSON_PrintUnformatted(bg);
      text[i] = t ? strdup(t) : NULL;
      cJSON_free(t);
      ok = text[i] != NULL;
      g[ng++] = (text_key){text[i], i};
    } else {
      text[i] = rsw_bundle_context_text(x->items[i]);
    }
  }
  if (ok) { /* groups: in order of index within equal texts (a stable sort by hand) */
    qsort(g, ng, sizeof *g, cmp_text_key);
    for (size_t a = 0, b; a < ng; a = b) {
      size_t first = g[a].index;
      for (b = a; b < ng && strcmp(g[b].text, g[a].text) == 0; b++)
        if (g[b].index < first) first = g[b].index;
      for (size_t c = a; c < b; c++) lead[g[c].index] = first;
    }
    /* The others: their texts numbered, cut into runs (common/bundle_plan.h). */
    size_t m = 0;
    for (size_t i = 0; i < n; i++)
      if (text[i] && !cJSON_GetObjectItemCaseSensitive(x->items[i], "bundle_group"))
        g[m++] = (text_key){text[i], i};
    qsort(g, m, sizeof *g, cmp_text_key);
    for (size_t a = 0, id = 0; a < m; a++) {
      if (a && strcmp(g[a].text, g[a - 1].text) != 0) id++;
      key[g[a].index] = id;
    }
    ok = rsw_bundle_runs(n, key, wl, k, run) == 0;
    for (size_t i = 0; i < n && ok; i++)
      if (!cJSON_GetObjectItemCaseSensitive(x->items[i], "bundle_group")) lead[i] = run[i];
  }
  for (size_t i = 0; text && i < n; i++) free(text[i]);
  free(text);
  free(g);
  free(key);
  free(wl);
  free(run);
  return ok ? RSW_OK : RSW_ERR_NOMEM;
}
