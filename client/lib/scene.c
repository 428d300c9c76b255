/* Scene push, list, info and delete.
 *
 * A pushed scene must not depend on the client's disk: every file it
 * references is hashed (SHA-256), the daemon is asked which digests it
 * lacks (POST /v1/blobs:missing), only those are uploaded (PUT
 * /v1/blobs/{hex}), and the references are rewritten to "sha256:<hex>"
 * before POST /v1/scenes. References are `filename` string properties:
 * in JSON any member called "filename" with a string value; in Mitsuba XML
 * `<string name="filename" value="..."/>`. The XML is sent byte for byte
 * as given except for those attribute values, so the daemon's file:line
 * error locations still match the user's file. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <expat.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"
#include "rsw_sha256.h"

#define SHA_PREFIX "sha256:"
/* Most distinct files one scene may reference. */
#define MAX_REFS   65536

/* One referenced file. */
typedef struct file_ref {
  char *path; /* resolved local path (owned) */
  char hex[65];
} file_ref;

typedef struct ref_list {
  file_ref *v;
  size_t n, cap;
} ref_list;

static void refs_free(ref_list *l) {
  for (size_t i = 0; i < l->n; i++) free(l->v[i].path);
  free(l->v);
  memset(l, 0, sizeof *l);
}

/* ---- hashing ------------------------------------------------------------------- */

/* SHA-256 of a file, streamed, as lowercase hex. */
static rsw_status hash_file(rsw_client *c, const char *path, char hex[65]) {
  unsigned char digest[32];
  errno = 0;
  if (!rsw_sha256_file(path, digest)) {
    if (errno)
      return client_fail(c, RSW_ERR_IO, "%s: cannot read referenced file: %s", path, strerror(errno));
    return client_fail(c, RSW_ERR_IO, "%s: SHA-256 failed", path);
  }
  rsw_hex(digest, 32, hex);
  return RSW_OK;
}

/* Read a whole file (owned, NUL-terminated). */
static rsw_status read_all(rsw_client *c, const char *path, const char *what, char **out, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return client_fail(c, RSW_ERR_IO, "%s: cannot open %s: %s", path, what, strerror(errno));
  char *p = NULL;
  size_t n = 0, cap = 0;
  for (;;) {
    if (n + 65536 + 1 > cap) {
      size_t ncap = cap ? cap * 2 : 65536 * 2;
      if (ncap > CLIENT_MAX_BODY) {
        free(p);
        fclose(f);
        return client_fail(c, RSW_ERR_LIMIT, "%s: %s larger than %zu bytes", path, what,
                           (size_t)CLIENT_MAX_BODY);
      }
      char *q = realloc(p, ncap);
      if (!q) {
        free(p);
        fclose(f);
        return client_fail(c, RSW_ERR_NOMEM, "%s: no memory to read %s", path, what);
      }
      p = q;
      cap = ncap;
    }
    size_t k = fread(p + n, 1, cap - n - 1, f);
    n += k;
    if (k == 0) break;
  }
  bool err = ferror(f);
  fclose(f);
  if (err) {
    free(p);
    return client_fail(c, RSW_ERR_IO, "%s: read error in %s", path, what);
  }
  p[n] = '\0';
  *out = p;
  *len = n;
  return RSW_OK;
}

/* Resolve name against base_dir, hash the file, and add it to the list
 * (once per path). hex_out gets its digest. */
static rsw_status add_ref(rsw_client *c, ref_list *l, const char *base_dir, const char *name,
                          char hex_out[65]) {
  if (!*name) return client_fail(c, RSW_ERR_IO, "a scene references an empty file name");
  size_t need = strlen(base_dir) + strlen(name) + 2;
  char *path = malloc(need);
  if (!path) return client_fail(c, RSW_ERR_NOMEM, "out of memory");
  if (name[0] == '/')
    snprintf(path, need, "%s", name);
  else
    snprintf(path, need, "%s/%s", base_dir, name);
  for (size_t i = 0; i < l->n; i++)
    if (strcmp(l->v[i].path, path) == 0) {
      memcpy(hex_out, l->v[i].hex, 65);
      free(path);
      return RSW_OK;
    }
  if (l->n >= MAX_REFS) {
    free(path);
    return client_fail(c, RSW_ERR_LIMIT, "a scene references more than %d files", MAX_REFS);
  }
  if (l->n == l->cap) {
    size_t cap = l->cap ? 2 * l->cap : 8;
    file_ref *v = realloc(l->v, cap * sizeof *v);
    if (!v) {
      free(path);
      return client_fail(c, RSW_ERR_NOMEM, "out of memory");
    }
    l->v = v;
    l->cap = cap;
  }
  rsw_status s = hash_file(c, path, hex_out);
  if (s) {
    free(path);
    return s;
  }
  l->v[l->n].path = path;
  memcpy(l->v[l->n].hex, hex_out, 65);
  l->n++;
  return RSW_OK;
}

static bool is_digest_ref(const char *v) {
  return strncmp(v, SHA_PREFIX, strlen(SHA_PREFIX)) == 0;
}

/* ---- JSON scenes ---------------------------------------------------------------- */

static rsw_status json_walk(rsw_client *c, cJSON *node, ref_list *l, const char *base_dir, bool *changed) {
  cJSON *it;
  cJSON_ArrayForEach(it, node) {
    if (cJSON_IsObject(node) && it->string && strcmp(it->string, "filename") == 0 && cJSON_IsString(it) &&
        !is_digest_ref(it->valuestring)) {
      char hex[65], ref[80];
      rsw_status s = add_ref(c, l, base_dir, it->valuestring, hex);
      if (s) return s;
      snprintf(ref, sizeof ref, SHA_PREFIX "%s", hex);
      char *v = malloc(strlen(ref) + 1);
      if (!v) return client_fail(c, RSW_ERR_NOMEM, "out of memory");
      strcpy(v, ref);
      free(it->valuestring);
      it->valuestring = v;
      *changed = true;
    } else if (cJSON_IsObject(it) || cJSON_IsArray(it)) {
      rsw_status s = json_walk(c, it, l, base_dir, changed);
      if (s) return s;
    }
  }
  return RSW_OK;
}

/* The document to post: text itself when it references nothing (*out
 * NULL), else the rewritten document (owned). A document that does not
 * parse is posted unchanged: the daemon's answer says where it is wrong. */
static rsw_status json_rewrite(rsw_client *c, const char *text, size_t len, const char *base_dir, ref_list *l,
                               char **out, size_t *out_len) {
  *out = NULL;
  cJSON *doc = cJSON_ParseWithLength(text, len);
  if (!doc) return RSW_OK;
  bool changed = false;
  rsw_status s = json_walk(c, doc, l, base_dir, &changed);
  if (!s && changed) {
    *out = cJSON_PrintUnformatted(doc);
    if (!*out)
      s = client_fail(c, RSW_ERR_NOMEM, "cannot print the rewritten scene");
    else
      *out_len = strlen(*out);
  }
  cJSON_Delete(doc);
  return s;
}

/* ---- XML scenes ---------------------------------------------------------------- */

/* One <string name="filename" value="..."/> start tag: where its value
 * attribute's raw text lies in the document, and the digest to put there. */
typedef struct xml_edit {
  size_t from, to; /* [from, to) of the attribute value between its quotes */
  char hex[65];
} xml_edit;

typedef struct xml_state {
  rsw_client *c;
  XML_Parser parser;
  const char *text;
  size_t len;
  const char *base_dir;
  ref_list *refs;
  xml_edit *edits;
  size_t n_edits, cap_edits;
  rsw_status status;
} xml_state;

/* Find the raw value of attribute `name` inside the start tag text
 * tag[0..n) ("<string name=... value=.../>"): [*from, *to) relative to tag. */
static bool find_attr(const char *tag, size_t n, const char *name, size_t *from, size_t *to) {
  size_t i = 1;
  while (i < n && !strchr(" \t\r\n/>", tag[i])) i++; /* the element name */
  size_t k = strlen(name);
  while (i < n) {
    while (i < n && strchr(" \t\r\n", tag[i])) i++;
    if (i >= n || tag[i] == '/' || tag[i] == '>') return false;
    size_t a = i;
    while (i < n && !strchr(" \t\r\n=", tag[i])) i++;
    size_t an = i - a;
    while (i < n && strchr(" \t\r\n", tag[i])) i++;
    if (i >= n || tag[i] != '=') return false;
    i++;
    while (i < n && strchr(" \t\r\n", tag[i])) i++;
    if (i >= n || (tag[i] != '"' && tag[i] != '\'')) return false;
    char q = tag[i++];
    size_t v = i;
    while (i < n && tag[i] != q) i++;
    if (i >= n) return false;
    if (an == k && strncmp(tag + a, name, k) == 0) {
      *from = v;
      *to = i;
      return true;
    }
    i++;
  }
  return false;
}

static void XMLCALL xml_start(void *user, const XML_Char *el, const XML_Char **attrs) {
  xml_state *x = user;
  if (x->status || strcmp(el, "string") != 0) return;
  const char *name = NULL, *value = NULL;
  for (int i = 0; attrs[i]; i += 2) {
    if (strcmp(attrs[i], "name") == 0)
      name = attrs[i + 1];
    else if (strcmp(attrs[i], "value") == 0)
      value = attrs[i + 1];
  }
  if (!name || strcmp(name, "filename") != 0 || !value || is_digest_ref(value)) return;
  XML_Index at = XML_GetCurrentByteIndex(x->parser);
  int count = XML_GetCurrentByteCount(x->parser);
  size_t from, to;
  if (at < 0 || count <= 0 || (size_t)at + (size_t)count > x->len ||
      !find_attr(x->text + at, (size_t)count, "value", &from, &to)) {
    x->status =
        client_fail(x->c, RSW_ERR_PARSE, "line %lu: cannot locate the value of <string name=\"filename\">",
                    (unsigned long)XML_GetCurrentLineNumber(x->parser));
    XML_StopParser(x->parser, XML_FALSE);
    return;
  }
  if (x->n_edits == x->cap_edits) {
    size_t cap = x->cap_edits ? 2 * x->cap_edits : 8;
    xml_edit *e = realloc(x->edits, cap * sizeof *e);
    if (!e) {
      x->status = client_fail(x->c, RSW_ERR_NOMEM, "out of memory");
      XML_StopParser(x->parser, XML_FALSE);
      return;
    }
    x->edits = e;
    x->cap_edits = cap;
  }
  xml_edit *e = &x->edits[x->n_edits];
  e->from = (size_t)at + from;
  e->to = (size_t)at + to;
  x->status = add_ref(x->c, x->refs, x->base_dir, value, e->hex);
  if (x->status) {
    XML_StopParser(x->parser, XML_FALSE);
    return;
  }
  x->n_edits++;
}

static rsw_status xml_rewrite(rsw_client *c, const char *text, size_t len, const char *base_dir, ref_list *l,
                              char **out, size_t *out_len) {
  *out = NULL;
  if (len > (size_t)0x7fffffff) return client_fail(c, RSW_ERR_LIMIT, "XML scene larger than 2 GiB");
  XML_Parser p = XML_ParserCreate(NULL);
  if (!p) return client_fail(c, RSW_ERR_NOMEM, "cannot create an XML parser");
  xml_state x = {.c = c, .parser = p, .text = text, .len = len, .base_dir = base_dir, .refs = l};
  XML_SetUserData(p, &x);
  XML_SetStartElementHandler(p, xml_start);
  enum XML_Status ok = XML_Parse(p, text, (int)len, XML_TRUE);
  XML_ParserFree(p);
  if (x.status) {
    free(x.edits);
    return x.status;
  }
  /* A malformed document goes to the daemon unchanged: it reports the
   * line. */
  if (ok != XML_STATUS_OK || !x.n_edits) {
    free(x.edits);
    return RSW_OK;
  }
  size_t n = len;
  for (size_t i = 0; i < x.n_edits; i++) n = n - (x.edits[i].to - x.edits[i].from) + strlen(SHA_PREFIX) + 64;
  char *o = malloc(n + 1);
  if (!o) {
    free(x.edits);
    return client_fail(c, RSW_ERR_NOMEM, "out of memory");
  }
  size_t w = 0, r = 0;
  for (size_t i = 0; i < x.n_edits; i++) { /* edits come in document order */
    memcpy(o + w, text + r, x.edits[i].from - r);
    w += x.edits[i].from - r;
    w += (size_t)sprintf(o + w, SHA_PREFIX "%s", x.edits[i].hex);
    r = x.edits[i].to;
  }
  memcpy(o + w, text + r, len - r);
  w += len - r;
  o[w] = '\0';
  free(x.edits);
  *out = o;
  *out_len = w;
  return RSW_OK;
}

/* ---- blobs ---------------------------------------------------------------------------- */

/* Upload the referenced files the daemon does not have yet. */
static rsw_status upload_missing(rsw_client *c, const ref_list *l) {
  if (!l->n) return RSW_OK;
  cJSON *q = cJSON_CreateObject();
  cJSON *arr = cJSON_AddArrayToObject(q, "digests");
  for (size_t i = 0; i < l->n && arr; i++) {
    bool dup = false;
    for (size_t j = 0; j < i && !dup; j++) dup = strcmp(l->v[i].hex, l->v[j].hex) == 0;
    if (!dup) cJSON_AddItemToArray(arr, cJSON_CreateString(l->v[i].hex));
  }
  char *body = arr ? cJSON_PrintUnformatted(q) : NULL;
  cJSON_Delete(q);
  if (!body) return client_fail(c, RSW_ERR_NOMEM, "out of memory");
  http_resp r;
  rsw_status s = http_request(c,
                              &(http_req){.method = "POST",
                                          .path = "/v1/blobs:missing",
                                          .content_type = "application/json",
                                          .body = body,
                                          .body_len = strlen(body)},
                              &r);
  free(body);
  if (s) return s;
  cJSON *a = cJSON_ParseWithLength(r.body, r.len);
  http_resp_free(&r);
  const cJSON *missing = cJSON_GetObjectItemCaseSensitive(a, "missing");
  if (!cJSON_IsArray(missing)) {
    cJSON_Delete(a);
    return client_fail(c, RSW_ERR_PARSE, "POST /v1/blobs:missing: the answer has no \"missing\" array");
  }
  const cJSON *it;
  cJSON_ArrayForEach(it, missing) {
    const file_ref *f = NULL;
    for (size_t i = 0; i < l->n && !f; i++)
      if (cJSON_IsString(it) && strcmp(l->v[i].hex, it->valuestring) == 0) f = &l->v[i];
    if (!f) continue; /* not one we asked about */
    char *data = NULL;
    size_t len = 0;
    s = read_all(c, f->path, "referenced file", &data, &len);
    if (s) break;
    char path[128];
    snprintf(path, sizeof path, "/v1/blobs/%s", f->hex);
    s = http_request(c,
                     &(http_req){.method = "PUT",
                                 .path = path,
                                 .content_type = "application/octet-stream",
                                 .body = data,
                                 .body_len = len},
                     &r);
    free(data);
    if (s) break;
    http_resp_free(&r);
  }
  cJSON_Delete(a);
  return s;
}

/* ---- push ------------------------------------------------------------------------------ */

static bool looks_xml(const char *text, size_t len) {
  size_t i = 0;
  if (len >= 3 && (unsigned char)text[0] == 0xEF && (unsigned char)text[1] == 0xBB &&
      (unsigned char)text[2] == 0xBF)
    i = 3; /* UTF-8 byte order mark */
  while (i < len && strchr(" \t\r\n", text[i])) i++;
  return i < len && text[i] == '<';
}

/* is_xml: 1 XML, 0 JSON, -1 from the content. name (may be NULL): the
 * file's name, which the daemon's messages about the text use (?name=). */
static rsw_status push(rsw_client *c, const char *text, size_t len, const char *base_dir, const char *variant,
                       const char *name, int is_xml, char id_out[65], char doc_out[65], int *created_out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  if (!text || !id_out)
    return client_fail(c, RSW_ERR_INVALID, "scene push: text and id_out must not be NULL");
  if (is_xml < 0) is_xml = looks_xml(text, len);
  if (!base_dir || !*base_dir) base_dir = ".";
  ref_list refs = {0};
  char *doc = NULL;
  size_t doc_len = 0;
  rsw_status s = is_xml ? xml_rewrite(c, text, len, base_dir, &refs, &doc, &doc_len)
                        : json_rewrite(c, text, len, base_dir, &refs, &doc, &doc_len);
  if (!s) s = upload_missing(c, &refs);
  refs_free(&refs);
  char path[1200] = "/v1/scenes";
  if (!s && variant && *variant) {
    char esc[128];
    if (!client_escape(variant, esc, sizeof esc))
      s = client_fail(c, RSW_ERR_INVALID, "variant name too long");
    else
      snprintf(path, sizeof path, "/v1/scenes?variant=%s", esc);
  }
  /* The file's name, the daemon's name for the document in its messages
   * and the scene's label (a name it cannot take, too long or with control
   * characters, is not sent). */
  char nesc[800];
  bool name_ok = name && *name && strlen(name) <= 255;
  for (const char *p = name; name_ok && *p; p++)
    if ((unsigned char)*p < 0x20 || *p == 0x7f) name_ok = false;
  if (!s && name_ok && client_escape(name, nesc, sizeof nesc)) {
    size_t at = strlen(path);
    snprintf(path + at, sizeof path - at, "%sname=%s", strchr(path, '?') ? "&" : "?", nesc);
  }
  http_resp r = {0};
  if (!s)
    s = http_request(c,
                     &(http_req){.method = "POST",
                                 .path = path,
                                 .content_type = is_xml ? "application/xml" : "application/json",
                                 .body = doc ? doc : text,
                                 .body_len = doc ? doc_len : len,
                                 .computed = true},
                     &r);
  free(doc);
  if (s) return s;
  cJSON *a = cJSON_ParseWithLength(r.body, r.len);
  const cJSON *id = cJSON_GetObjectItemCaseSensitive(a, "id");
  if (!cJSON_IsString(id) || strlen(id->valuestring) != 64) {
    s = client_fail(c, RSW_ERR_PARSE, "POST /v1/scenes: the answer has no 64-character \"id\": %.200s",
                    r.body);
  } else {
    memcpy(id_out, id->valuestring, 65);
    if (created_out) *created_out = r.status == 201;
    /* The document's id: the scene's own for its twin, another for a
     * scene loaded while the twin had changed (a daemon before "document"
     * has no such scene). */
    const cJSON *d = cJSON_GetObjectItemCaseSensitive(a, "document");
    if (doc_out)
      memcpy(doc_out, cJSON_IsString(d) && strlen(d->valuestring) == 64 ? d->valuestring : id_out, 65);
  }
  cJSON_Delete(a);
  http_resp_free(&r);
  return s;
}

rsw_status rsw_scene_push_buffer(rsw_client *c, const char *text, size_t len, const char *base_dir,
                                 const char *variant, char id_out[65], int *created_out) {
  return push(c, text, len, base_dir, variant, NULL, -1, id_out, NULL, created_out);
}

rsw_status rsw_scene_push_file(rsw_client *c, const char *path, const char *variant, char id_out[65],
                               int *created_out) {
  return client_scene_push_file(c, path, variant, id_out, NULL, created_out);
}

rsw_status client_scene_push_file(rsw_client *c, const char *path, const char *variant, char id_out[65],
                                  char doc_out[65], int *created_out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  if (!path) return client_fail(c, RSW_ERR_INVALID, "scene push: path is NULL");
  char *text = NULL;
  size_t len = 0;
  rsw_status s = read_all(c, path, "scene file", &text, &len);
  if (s) return s;
  /* The scene's directory resolves its relative file names. */
  char *dir = malloc(strlen(path) + 2);
  if (!dir) {
    free(text);
    return client_fail(c, RSW_ERR_NOMEM, "out of memory");
  }
  strcpy(dir, path);
  char *slash = strrchr(dir, '/');
  if (!slash)
    strcpy(dir, ".");
  else if (slash == dir)
    dir[1] = '\0';
  else
    *slash = '\0';
  size_t n = strlen(path);
  int is_xml = n >= 4 && strcmp(path + n - 4, ".xml") == 0    ? 1
               : n >= 5 && strcmp(path + n - 5, ".json") == 0 ? 0
                                                              : -1;
  const char *base = strrchr(path, '/');
  s = push(c, text, len, dir, variant, base ? base + 1 : path, is_xml, id_out, doc_out, created_out);
  free(dir);
  free(text);
  return s;
}

/* ---- list / info / delete -------------------------------------------------------------- */

rsw_status rsw_scene_list(rsw_client *c, char **json_out) {
  if (!c) return RSW_ERR_INVALID;
  return client_get_text(c, "/v1/scenes", json_out);
}

rsw_status rsw_scene_info(rsw_client *c, const char *id, char **json_out) {
  if (!c) return RSW_ERR_INVALID;
  char esc[256], path[300];
  if (!id || !client_escape(id, esc, sizeof esc))
    return client_fail(c, RSW_ERR_INVALID, "scene id missing or too long");
  snprintf(path, sizeof path, "/v1/scenes/%s", esc);
  return client_get_text(c, path, json_out);
}

rsw_status rsw_scene_delete(rsw_client *c, const char *id, int force) {
  if (!c) return RSW_ERR_INVALID;
  char esc[256], path[320];
  if (!id || !client_escape(id, esc, sizeof esc))
    return client_fail(c, RSW_ERR_INVALID, "scene id missing or too long");
  snprintf(path, sizeof path, "/v1/scenes/%s%s", esc, force ? "?force=true" : "");
  http_resp r;
  rsw_status s = http_request(c, &(http_req){.method = "DELETE", .path = path}, &r);
  if (!s) http_resp_free(&r);
  return s;
}

/* POST /v1/scenes/{id}:OP with no body; the answer's text (owned) and
 * its HTTP status. */
static rsw_status scene_op(rsw_client *c, const char *id, const char *op, char **json_out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char esc[256], path[320];
  if (!id || !client_escape(id, esc, sizeof esc))
    return client_fail(c, RSW_ERR_INVALID, "scene id missing or too long");
  snprintf(path, sizeof path, "/v1/scenes/%s:%s", esc, op);
  http_resp r;
  rsw_status s = http_request(c, &(http_req){.method = "POST", .path = path}, &r);
  if (s) return s;
  *json_out = r.body;
  r.body = NULL;
  http_resp_free(&r);
  return *json_out ? RSW_OK : client_fail(c, RSW_ERR_PARSE, "POST %s: empty answer", path);
}

rsw_status rsw_scene_reset(rsw_client *c, const char *id, char **json_out) {
  char *j = NULL;
  rsw_status s = scene_op(c, id, "reset", &j);
  if (!s && json_out)
    *json_out = j;
  else
    free(j);
  return s;
}

rsw_status rsw_scene_copy(rsw_client *c, const char *id, char id_out[65], char **json_out) {
  if (c && !id_out) return client_fail(c, RSW_ERR_INVALID, "scene copy: id_out is NULL");
  char *j = NULL;
  rsw_status s = scene_op(c, id, "copy", &j);
  if (s) return s;
  cJSON *a = cJSON_Parse(j);
  const cJSON *nid = cJSON_GetObjectItemCaseSensitive(a, "id");
  if (!cJSON_IsString(nid) || strlen(nid->valuestring) != 64)
    s = client_fail(c, RSW_ERR_PARSE, "POST :copy: the answer has no 64-character \"id\": %.200s", j);
  else
    memcpy(id_out, nid->valuestring, 65);
  cJSON_Delete(a);
  if (!s && json_out)
    *json_out = j;
  else
    free(j);
  return s;
}

/* ---- parameters ------------------------------------------------------------------------- */

static rsw_status params_get(rsw_client *c, const char *id, const char *match, const char *class_name,
                             bool full, char **json_out, uint64_t *revision_out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char esc[256], m[512], k[128], path[1024];
  if (!id || !client_escape(id, esc, sizeof esc))
    return client_fail(c, RSW_ERR_INVALID, "scene id missing or too long");
  if (!json_out) return client_fail(c, RSW_ERR_INVALID, "params: json_out is NULL");
  if (match && !client_escape(match, m, sizeof m))
    return client_fail(c, RSW_ERR_INVALID, "match pattern too long");
  if (class_name && !client_escape(class_name, k, sizeof k))
    return client_fail(c, RSW_ERR_INVALID, "class name too long");
  snprintf(path, sizeof path, "/v1/scenes/%s/params%s%s%s%s%s", esc, match || class_name ? "?" : "",
           match ? "match=" : "", match ? m : "", match && class_name ? "&" : "", class_name ? "class=" : "");
  if (class_name) strncat(path, k, sizeof path - strlen(path) - 1);
  if (full) strncat(path, match || class_name ? "&full=1" : "?full=1", sizeof path - strlen(path) - 1);
  http_resp r;
  rsw_status s = http_request(c, &(http_req){.method = "GET", .path = path}, &r);
  if (s) return s;
  cJSON *a = cJSON_ParseWithLength(r.body, r.len);
  const cJSON *rev = cJSON_GetObjectItemCaseSensitive(a, "revision");
  if (!cJSON_IsNumber(rev) || rev->valuedouble < 0) {
    cJSON_Delete(a);
    http_resp_free(&r);
    return client_fail(c, RSW_ERR_PARSE, "GET %s: the answer has no \"revision\"", path);
  }
  if (revision_out) *revision_out = (uint64_t)rev->valuedouble;
  cJSON_Delete(a);
  *json_out = r.body;
  return RSW_OK;
}

rsw_status rsw_params_get(rsw_client *c, const char *id, const char *match, const char *class_name,
                          char **json_out, uint64_t *revision_out) {
  return params_get(c, id, match, class_name, false, json_out, revision_out);
}

rsw_status rsw_params_get_full(rsw_client *c, const char *id, const char *match, const char *class_name,
                               char **json_out, uint64_t *revision_out) {
  return params_get(c, id, match, class_name, true, json_out, revision_out);
}

rsw_status rsw_params_update(rsw_client *c, const char *id, const char *map_json, int64_t if_match,
                             uint64_t *revision_out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char esc[256], path[300], etag[40];
  if (!id || !client_escape(id, esc, sizeof esc))
    return client_fail(c, RSW_ERR_INVALID, "scene id missing or too long");
  if (!map_json) return client_fail(c, RSW_ERR_INVALID, "params update: map_json is NULL");
  snprintf(path, sizeof path, "/v1/scenes/%s/params", esc);
  snprintf(etag, sizeof etag, "\"%lld\"", (long long)if_match);
  http_resp r;
  rsw_status s = http_request(c,
                              &(http_req){.method = "PATCH",
                                          .path = path,
                                          .content_type = "application/json",
                                          .body = map_json,
                                          .body_len = strlen(map_json),
                                          .if_match = if_match >= 0 ? etag : NULL,
                                          .computed = true},
                              &r);
  if (s) return s;
  cJSON *a = cJSON_ParseWithLength(r.body, r.len);
  const cJSON *rev = cJSON_GetObjectItemCaseSensitive(a, "revision");
  if (!cJSON_IsNumber(rev) || rev->valuedouble < 0)
    s = client_fail(c, RSW_ERR_PARSE, "PATCH %s: the answer has no \"revision\"", path);
  else if (revision_out)
    *revision_out = (uint64_t)rev->valuedouble;
  cJSON_Delete(a);
  http_resp_free(&r);
  return s;
}
