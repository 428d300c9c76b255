/* OBJ and PLY mesh loaders (see mesh_io.h for what each accepts).
 *
 * Formats: Wavefront OBJ as written by common exporters (the subset that
 * Mitsuba 3's src/shapes/obj.cpp reads: v, vt, vn, f), and PLY 1.0 (Greg
 * Turk's format; Mitsuba 3's src/shapes/ply.cpp reads the same vertex and
 * face properties). Both files are read whole into memory; the OBJ buffer
 * is split into NUL-terminated lines in place so that strtod() can never
 * run past a line. */
#include "mesh_io.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "rsw_file.h"

/* ---- shared helpers ------------------------------------------------------ */

/* Largest mesh file we read into memory: 16 GiB. */
#define MESH_MAX_FILE_BYTES ((uint64_t)1 << 34)

typedef struct file_buf {
  char *data; /* size bytes plus a terminating NUL (owned) */
  size_t size;
} file_buf;

static rsw_status read_whole_file(const char *path, file_buf *fb, rsw_err *err) {
  FILE *f = rsw_fopen_regular(path, "rb");
  if (!f) return rsw_fail(err, RSW_ERR_FILE, path, "cannot open mesh file: %s", rsw_open_strerror(errno));
  struct stat sb;
  if (fstat(fileno(f), &sb) != 0 || !S_ISREG(sb.st_mode)) {
    fclose(f);
    return rsw_fail(err, RSW_ERR_FILE, path, "not a regular file");
  }
  if ((uint64_t)sb.st_size > MESH_MAX_FILE_BYTES) {
    fclose(f);
    return rsw_fail(err, RSW_ERR_LIMIT, path, "mesh file of %lld bytes exceeds the %llu byte limit",
                    (long long)sb.st_size, (unsigned long long)MESH_MAX_FILE_BYTES);
  }
  size_t n = (size_t)sb.st_size;
  char *d = malloc(n + 1);
  if (!d) {
    fclose(f);
    return rsw_fail(err, RSW_ERR_NOMEM, path, "no memory for %zu bytes", n);
  }
  size_t got = fread(d, 1, n, f);
  int bad = ferror(f);
  fclose(f);
  if (bad || got != n) {
    free(d);
    return rsw_fail(err, RSW_ERR_FILE, path, "read error");
  }
  d[n] = '\0';
  fb->data = d;
  fb->size = n;
  return RSW_OK;
}

/* Make room for `need` elements of `elem` bytes (capacity doubles). */
static bool reserve(void **p, size_t *cap, size_t need, size_t elem) {
  if (need <= *cap) return true;
  size_t nc = *cap ? *cap : 64;
  while (nc < need) {
    if (nc > SIZE_MAX / 2) return false;
    nc *= 2;
  }
  if (nc > SIZE_MAX / elem) return false;
  void *q = realloc(*p, nc * elem);
  if (!q) return false;
  *p = q;
  *cap = nc;
  return true;
}

void mesh_free(mesh *m) {
  if (!m) return;
  free(m->pos);
  free(m->nrm);
  free(m->uv);
  free(m->faces);
  memset(m, 0, sizeof *m);
}

static bool is_blank(char c) {
  return c == ' ' || c == '\t' || c == '\r';
}

/* ---- OBJ ----------------------------------------------------------------- */

#define OBJ_NONE UINT32_MAX

typedef struct obj_parser {
  const char *path;
  size_t line;
  rsw_err *err;
  float *v, *vt, *vn; /* 3, 2, 3 floats each */
  size_t nv, nvt, nvn, cap_v, cap_vt, cap_vn;
  uint32_t *keys; /* (v, vt, vn) per output vertex, OBJ_NONE if absent */
  size_t nkeys, cap_keys;
  uint32_t *table; /* hash of keys: output vertex + 1, 0 = empty */
  size_t table_size;
  uint32_t *faces; /* 3 per triangle */
  size_t nf, cap_f;
  uint32_t *corners; /* the current face's output vertices */
  size_t cap_corners;
  bool any_vt, all_vn;
} obj_parser;

static rsw_status obj_fail(obj_parser *o, rsw_status code, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static rsw_status obj_fail(obj_parser *o, rsw_status code, const char *fmt, ...) {
  char where[300], msg[512];
  snprintf(where, sizeof where, "%s:%zu", o->path, o->line);
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  return rsw_fail(o->err, code, where, "%s", msg);
}

/* Parse one number at *s (blanks first); the token must end at a blank or
 * the end of the line. */
static rsw_status obj_number(obj_parser *o, char **s, const char *what, double *out) {
  char *p = *s;
  while (is_blank(*p)) p++;
  if (!*p) return obj_fail(o, RSW_ERR_FILE, "missing %s", what);
  char *e;
  double x = strtod(p, &e);
  if (e == p || (*e && !is_blank(*e))) {
    char *t = p;
    while (*t && !is_blank(*t)) t++;
    return obj_fail(o, RSW_ERR_FILE, "bad number \"%.*s\" for %s", (int)(t - p > 40 ? 40 : t - p), p, what);
  }
  if (!isfinite(x) || !isfinite((float)x))
    return obj_fail(o, RSW_ERR_FILE, "non-finite %s \"%.*s\"", what, (int)(e - p > 40 ? 40 : e - p), p);
  *out = x;
  *s = e;
  return RSW_OK;
}

static bool obj_more(const char *s) {
  while (is_blank(*s)) s++;
  return *s != '\0';
}

/* Read n numbers (n_required of them mandatory, the rest default to 0)
 * and append them as floats to *arr. */
static rsw_status obj_append(obj_parser *o, char *s, int n, int n_required, const char *what, float **arr,
                             size_t *count, size_t *cap) {
  if (*count >= MESH_MAX_ELEMENTS)
    return obj_fail(o, RSW_ERR_LIMIT, "more than %u %s entries", (unsigned)MESH_MAX_ELEMENTS, what);
  if (!reserve((void **)arr, cap, (*count + 1) * (size_t)n, sizeof(float)))
    return obj_fail(o, RSW_ERR_NOMEM, "no memory for %s", what);
  float *dst = *arr + *count * (size_t)n;
  for (int i = 0; i < n; i++) {
    double x = 0;
    if (i < n_required || obj_more(s)) {
      rsw_status st = obj_number(o, &s, what, &x);
      if (st != RSW_OK) return st;
    }
    dst[i] = (float)x;
  }
  (*count)++;
  return RSW_OK;
}

static rsw_status obj_stmt_v(obj_parser *o, char *s) {
  return obj_append(o, s, 3, 3, "vertex coordinate", &o->v, &o->nv, &o->cap_v);
}
static rsw_status obj_stmt_vt(obj_parser *o, char *s) {
  return obj_append(o, s, 2, 1, "texture coordinate", &o->vt, &o->nvt, &o->cap_vt);
}
static rsw_status obj_stmt_vn(obj_parser *o, char *s) {
  return obj_append(o, s, 3, 3, "normal", &o->vn, &o->nvn, &o->cap_vn);
}

/* Resolve an OBJ index (1-based, or negative from the end) against count.
 * Parses at *s; *present is false when no index is written there. */
static rsw_status obj_index(obj_parser *o, char **s, size_t count, const char *what, bool *present,
                            uint32_t *out) {
  char *p = *s;
  *present = false;
  if (*p != '-' && *p != '+' && (*p < '0' || *p > '9')) return RSW_OK;
  char *e;
  errno = 0;
  long long i = strtoll(p, &e, 10);
  if (e == p) return obj_fail(o, RSW_ERR_FILE, "bad %s index \"%.10s\"", what, p);
  *s = e;
  long long r;
  if (i > 0)
    r = i - 1;
  else if (i < 0)
    r = (long long)count + i; /* -1 is the last one defined so far */
  else
    return obj_fail(o, RSW_ERR_FILE, "%s index 0 (OBJ indices start at 1)", what);
  if (errno == ERANGE || r < 0 || (unsigned long long)r >= count)
    return obj_fail(o, RSW_ERR_FILE, "%s index %lld out of range (%zu defined so far)", what, i, count);
  *present = true;
  *out = (uint32_t)r;
  return RSW_OK;
}

static uint64_t key_hash(const uint32_t *k) {
  uint64_t h = k[0] * 0x9e3779b97f4a7c15ull;
  h ^= (k[1] + 0x632be59bd9b4e019ull) * 0xbf58476d1ce4e5b9ull;
  h ^= (k[2] + 0x2545f4914f6cdd1dull) * 0x94d049bb133111ebull;
  return h ^ (h >> 31);
}

/* Double the hash table and reinsert every key. */
static bool obj_rehash(obj_parser *o) {
  size_t ns = o->table_size ? o->table_size * 2 : 1024;
  uint32_t *t = calloc(ns, sizeof *t);
  if (!t) return false;
  for (size_t id = 0; id < o->nkeys; id++) {
    size_t j = (size_t)key_hash(o->keys + 3 * id) & (ns - 1);
    while (t[j]) j = (j + 1) & (ns - 1);
    t[j] = (uint32_t)id + 1;
  }
  free(o->table);
  o->table = t;
  o->table_size = ns;
  return true;
}

/* Output vertex for a (v, vt, vn) corner, created on first use. */
static rsw_status obj_vertex(obj_parser *o, const uint32_t key[3], uint32_t *out) {
  if ((o->nkeys + 1) * 2 > o->table_size && !obj_rehash(o))
    return obj_fail(o, RSW_ERR_NOMEM, "no memory for vertices");
  size_t mask = o->table_size - 1;
  size_t j = (size_t)key_hash(key) & mask;
  while (o->table[j]) {
    const uint32_t *k = o->keys + 3 * (size_t)(o->table[j] - 1);
    if (k[0] == key[0] && k[1] == key[1] && k[2] == key[2]) {
      *out = o->table[j] - 1;
      return RSW_OK;
    }
    j = (j + 1) & mask;
  }
  if (o->nkeys >= MESH_MAX_ELEMENTS)
    return obj_fail(o, RSW_ERR_LIMIT, "more than %u distinct vertices", (unsigned)MESH_MAX_ELEMENTS);
  if (!reserve((void **)&o->keys, &o->cap_keys, (o->nkeys + 1) * 3, sizeof *o->keys))
    return obj_fail(o, RSW_ERR_NOMEM, "no memory for vertices");
  memcpy(o->keys + 3 * o->nkeys, key, 3 * sizeof *key);
  o->table[j] = (uint32_t)o->nkeys + 1;
  *out = (uint32_t)o->nkeys++;
  return RSW_OK;
}

/* f c1 c2 c3 ...: corners v, v/vt, v//vn or v/vt/vn; fan-triangulated. */
static rsw_status obj_stmt_f(obj_parser *o, char *s) {
  size_t n = 0;
  rsw_status st;
  for (;;) {
    while (is_blank(*s)) s++;
    if (!*s) break;
    char *tok = s;
    uint32_t key[3] = {OBJ_NONE, OBJ_NONE, OBJ_NONE};
    bool has_v, has_vt = false, has_vn = false;
    if ((st = obj_index(o, &s, o->nv, "vertex", &has_v, &key[0])) != RSW_OK) return st;
    if (!has_v) goto bad_corner;
    if (*s == '/') {
      s++;
      if ((st = obj_index(o, &s, o->nvt, "texture coordinate", &has_vt, &key[1])) != RSW_OK) return st;
      if (*s == '/') {
        s++;
        if ((st = obj_index(o, &s, o->nvn, "normal", &has_vn, &key[2])) != RSW_OK) return st;
        if (!has_vn) goto bad_corner;
      } else if (!has_vt) {
        goto bad_corner; /* "v/" */
      }
    }
    if (*s && !is_blank(*s)) goto bad_corner;
    o->any_vt |= has_vt;
    o->all_vn &= has_vn;
    if (!reserve((void **)&o->corners, &o->cap_corners, n + 1, sizeof *o->corners))
      return obj_fail(o, RSW_ERR_NOMEM, "no memory for a face");
    if ((st = obj_vertex(o, key, &o->corners[n])) != RSW_OK) return st;
    n++;
    continue;
  bad_corner : {
    char *t = tok;
    while (*t && !is_blank(*t)) t++;
    return obj_fail(o, RSW_ERR_FILE, "bad face corner \"%.*s\"", (int)(t - tok > 40 ? 40 : t - tok), tok);
  }
  }
  if (n < 3) return obj_fail(o, RSW_ERR_FILE, "face with %zu corners (need 3 or more)", n);
  if (o->nf + (n - 2) > MESH_MAX_ELEMENTS)
    return obj_fail(o, RSW_ERR_LIMIT, "more than %u triangles", (unsigned)MESH_MAX_ELEMENTS);
  if (!reserve((void **)&o->faces, &o->cap_f, (o->nf + n - 2) * 3, sizeof *o->faces))
    return obj_fail(o, RSW_ERR_NOMEM, "no memory for faces");
  for (size_t i = 1; i + 1 < n; i++) {
    uint32_t *t = o->faces + 3 * o->nf++;
    t[0] = o->corners[0];
    t[1] = o->corners[i];
    t[2] = o->corners[i + 1];
  }
  return RSW_OK;
}

/* The statements we read; every other keyword (o, g, s, usemtl, mtllib,
 * l, p, vp, ...) is ignored, as Mitsuba does. */
static const struct obj_statement {
  const char *keyword;
  rsw_status (*parse)(obj_parser *o, char *args);
} obj_statements[] = {
    {"v", obj_stmt_v},
    {"vt", obj_stmt_vt},
    {"vn", obj_stmt_vn},
    {"f", obj_stmt_f},
};

static void obj_parser_free(obj_parser *o) {
  free(o->v);
  free(o->vt);
  free(o->vn);
  free(o->keys);
  free(o->table);
  free(o->faces);
  free(o->corners);
}

/* Build the output mesh from the deduplicated corners. */
static rsw_status obj_build(obj_parser *o, bool flip_tex_coords, mesh *out) {
  size_t nv = o->nkeys;
  mesh m = {0};
  m.n_verts = (uint32_t)nv;
  m.n_faces = (uint32_t)o->nf;
  m.pos = malloc(nv * 3 * sizeof *m.pos);
  m.faces = malloc(o->nf * 3 * sizeof *m.faces);
  if (o->any_vt) m.uv = malloc(nv * 2 * sizeof *m.uv);
  if (o->all_vn) m.nrm = malloc(nv * 3 * sizeof *m.nrm);
  if (!m.pos || !m.faces || (o->any_vt && !m.uv) || (o->all_vn && !m.nrm)) {
    mesh_free(&m);
    return rsw_fail(o->err, RSW_ERR_NOMEM, o->path, "no memory for %zu vertices", nv);
  }
  for (size_t i = 0; i < nv; i++) {
    const uint32_t *k = o->keys + 3 * i;
    memcpy(m.pos + 3 * i, o->v + 3 * (size_t)k[0], 3 * sizeof(float));
    if (m.uv) {
      float u = 0, v = 0;
      if (k[1] != OBJ_NONE) {
        u = o->vt[2 * (size_t)k[1]];
        v = o->vt[2 * (size_t)k[1] + 1];
        if (flip_tex_coords) v = 1.0f - v;
      }
      m.uv[2 * i] = u;
      m.uv[2 * i + 1] = v;
    }
    if (m.nrm) memcpy(m.nrm + 3 * i, o->vn + 3 * (size_t)k[2], 3 * sizeof(float));
  }
  memcpy(m.faces, o->faces, o->nf * 3 * sizeof *m.faces);
  *out = m;
  return RSW_OK;
}

rsw_status mesh_load_obj(const char *path, bool flip_tex_coords, mesh *out, rsw_err *err) {
  file_buf fb;
  rsw_status st = read_whole_file(path, &fb, err);
  if (st != RSW_OK) return st;
  obj_parser o = {.path = path, .err = err, .all_vn = true};
  char *p = fb.data, *end = fb.data + fb.size;
  while (st == RSW_OK && p < end) {
    o.line++;
    char *nl = memchr(p, '\n', (size_t)(end - p));
    char *next = nl ? nl + 1 : end;
    if (nl) *nl = '\0';
    if (memchr(p, '\0', (size_t)((nl ? nl : end) - p))) {
      st = obj_fail(&o, RSW_ERR_FILE, "NUL byte in a text file");
      break;
    }
    char *hash = strchr(p, '#');
    if (hash) *hash = '\0';
    while (is_blank(*p)) p++;
    char *kw = p;
    while (*p && !is_blank(*p)) p++;
    size_t kwlen = (size_t)(p - kw);
    for (size_t i = 0; kwlen && i < sizeof obj_statements / sizeof *obj_statements; i++)
      if (strlen(obj_statements[i].keyword) == kwlen && memcmp(obj_statements[i].keyword, kw, kwlen) == 0) {
        st = obj_statements[i].parse(&o, p);
        break;
      }
    p = next;
  }
  if (st == RSW_OK && o.nf == 0) st = rsw_fail(err, RSW_ERR_FILE, path, "OBJ file has no faces");
  if (st == RSW_OK) st = obj_build(&o, flip_tex_coords, out);
  obj_parser_free(&o);
  free(fb.data);
  return st;
}

/* ---- PLY ----------------------------------------------------------------- */

typedef enum ply_type {
  PLY_INVALID,
  PLY_I8,
  PLY_U8,
  PLY_I16,
  PLY_U16,
  PLY_I32,
  PLY_U32,
  PLY_F32,
  PLY_F64
} ply_type;

static const struct {
  const char *name;
  ply_type type;
} ply_type_names[] = {
    {"char", PLY_I8},   {"int8", PLY_I8},     {"uchar", PLY_U8},   {"uint8", PLY_U8},
    {"short", PLY_I16}, {"int16", PLY_I16},   {"ushort", PLY_U16}, {"uint16", PLY_U16},
    {"int", PLY_I32},   {"int32", PLY_I32},   {"uint", PLY_U32},   {"uint32", PLY_U32},
    {"float", PLY_F32}, {"float32", PLY_F32}, {"double", PLY_F64}, {"float64", PLY_F64},
};
static const unsigned ply_type_size[] = {0, 1, 1, 2, 2, 4, 4, 4, 8};

static bool ply_is_integer(ply_type t) {
  return t >= PLY_I8 && t <= PLY_U32;
}

#define PLY_MAX_ELEMENTS 64
#define PLY_MAX_PROPS    64
#define PLY_NAME_LEN     64

typedef struct ply_prop {
  char name[PLY_NAME_LEN];
  ply_type type;       /* scalar type, or a list's item type */
  ply_type count_type; /* PLY_INVALID for scalars */
} ply_prop;

typedef struct ply_elem {
  char name[PLY_NAME_LEN];
  uint64_t count;
  ply_prop props[PLY_MAX_PROPS];
  int n_props;
} ply_elem;

/* Roles of vertex properties we keep. */
enum {
  R_X,
  R_Y,
  R_Z,
  R_NX,
  R_NY,
  R_NZ,
  R_U,
  R_V,
  R__COUNT
};

typedef struct ply_file {
  const char *path;
  rsw_err *err;
  bool ascii;
  ply_elem elems[PLY_MAX_ELEMENTS];
  int n_elems;
  int vertex_elem, face_elem; /* -1 if absent */
  int role_prop[R__COUNT];    /* property index in the vertex element, -1 */
  int face_prop;              /* index list in the face element */
  /* data cursor */
  const unsigned char *base, *p, *end;
  size_t line;          /* ascii: line of *p */
  const char *cur_elem; /* for messages */
  uint64_t cur_index;
} ply_file;

/* Error at the data cursor: "file:line" (ascii) or "byte N" (binary),
 * plus the element being read. */
static rsw_status ply_fail(ply_file *f, rsw_status code, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static rsw_status ply_fail(ply_file *f, rsw_status code, const char *fmt, ...) {
  char msg[512], where[300];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  if (f->ascii) {
    snprintf(where, sizeof where, "%s:%zu", f->path, f->line);
    return rsw_fail(f->err, code, where, "%s %llu: %s", f->cur_elem, (unsigned long long)f->cur_index, msg);
  }
  return rsw_fail(f->err, code, f->path, "byte %llu (%s %llu): %s", (unsigned long long)(f->p - f->base),
                  f->cur_elem, (unsigned long long)f->cur_index, msg);
}

static rsw_status header_fail(ply_file *f, size_t line, rsw_status code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static rsw_status header_fail(ply_file *f, size_t line, rsw_status code, const char *fmt, ...) {
  char msg[512], where[300];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  snprintf(where, sizeof where, "%s:%zu", f->path, line);
  return rsw_fail(f->err, code, where, "bad PLY header: %s", msg);
}

static ply_type ply_type_by_name(const char *s) {
  for (size_t i = 0; i < sizeof ply_type_names / sizeof *ply_type_names; i++)
    if (strcmp(ply_type_names[i].name, s) == 0) return ply_type_names[i].type;
  return PLY_INVALID;
}

/* Split a header line into at most max blank-separated words. */
static int split_words(char *s, char **w, int max) {
  int n = 0;
  for (;;) {
    while (is_blank(*s)) s++;
    if (!*s) return n;
    if (n == max) return max + 1;
    w[n++] = s;
    while (*s && !is_blank(*s)) s++;
    if (*s) *s++ = '\0';
  }
}

static rsw_status ply_header_line(ply_file *f, char *line, size_t ln, bool *done) {
  char *w[8];
  int n = split_words(line, w, 6);
  if (n == 0) return RSW_OK;
  if (strcmp(w[0], "comment") == 0 || strcmp(w[0], "obj_info") == 0) return RSW_OK;
  if (strcmp(w[0], "end_header") == 0) {
    *done = true;
    return RSW_OK;
  }
  if (strcmp(w[0], "format") == 0) {
    if (n != 3 || strcmp(w[2], "1.0") != 0)
      return header_fail(f, ln, RSW_ERR_FILE, "expected \"format <kind> 1.0\"");
    if (strcmp(w[1], "ascii") == 0)
      f->ascii = true;
    else if (strcmp(w[1], "binary_little_endian") == 0)
      f->ascii = false;
    else if (strcmp(w[1], "binary_big_endian") == 0)
      return rsw_fail(f->err, RSW_ERR_UNSUPPORTED, f->path,
                      "binary_big_endian PLY files are unsupported (convert "
                      "to binary_little_endian)");
    else
      return header_fail(f, ln, RSW_ERR_FILE, "unknown format \"%.40s\"", w[1]);
    return RSW_OK;
  }
  if (strcmp(w[0], "element") == 0) {
    if (n != 3) return header_fail(f, ln, RSW_ERR_FILE, "expected \"element <name> <count>\"");
    if (f->n_elems == PLY_MAX_ELEMENTS)
      return header_fail(f, ln, RSW_ERR_LIMIT, "more than %d elements", PLY_MAX_ELEMENTS);
    if (strlen(w[1]) >= PLY_NAME_LEN) return header_fail(f, ln, RSW_ERR_FILE, "element name too long");
    char *e;
    errno = 0;
    unsigned long long c = strtoull(w[2], &e, 10);
    if (*e || e == w[2] || w[2][0] == '-' || errno == ERANGE)
      return header_fail(f, ln, RSW_ERR_FILE, "bad element count \"%.40s\"", w[2]);
    if (c > MESH_MAX_ELEMENTS)
      return header_fail(f, ln, RSW_ERR_LIMIT, "element %s count %llu exceeds %u", w[1], c,
                         (unsigned)MESH_MAX_ELEMENTS);
    ply_elem *el = &f->elems[f->n_elems++];
    memset(el, 0, sizeof *el);
    snprintf(el->name, sizeof el->name, "%s", w[1]);
    el->count = c;
    return RSW_OK;
  }
  if (strcmp(w[0], "property") == 0) {
    if (f->n_elems == 0) return header_fail(f, ln, RSW_ERR_FILE, "property before any element");
    ply_elem *el = &f->elems[f->n_elems - 1];
    if (el->n_props == PLY_MAX_PROPS)
      return header_fail(f, ln, RSW_ERR_LIMIT, "more than %d properties", PLY_MAX_PROPS);
    ply_prop pr = {0};
    const char *name;
    if (n == 5 && strcmp(w[1], "list") == 0) {
      pr.count_type = ply_type_by_name(w[2]);
      pr.type = ply_type_by_name(w[3]);
      name = w[4];
      if (!ply_is_integer(pr.count_type))
        return header_fail(f, ln, RSW_ERR_FILE, "list count type \"%.20s\" is not an integer type", w[2]);
      if (pr.type == PLY_INVALID) return header_fail(f, ln, RSW_ERR_FILE, "unknown type \"%.20s\"", w[3]);
    } else if (n == 3) {
      pr.type = ply_type_by_name(w[1]);
      name = w[2];
      if (pr.type == PLY_INVALID) return header_fail(f, ln, RSW_ERR_FILE, "unknown type \"%.20s\"", w[1]);
    } else {
      return header_fail(f, ln, RSW_ERR_FILE, "malformed property line");
    }
    if (strlen(name) >= PLY_NAME_LEN) return header_fail(f, ln, RSW_ERR_FILE, "property name too long");
    snprintf(pr.name, sizeof pr.name, "%s", name);
    el->props[el->n_props++] = pr;
    return RSW_OK;
  }
  return header_fail(f, ln, RSW_ERR_FILE, "unknown keyword \"%.40s\" (is end_header missing?)", w[0]);
}

/* Vertex property names for each role; the first pair of u/v names that
 * is complete wins. */
static const struct {
  const char *name;
  int role;
} ply_roles[] = {
    {"x", R_X},         {"y", R_Y},         {"z", R_Z},         {"nx", R_NX},       {"ny", R_NY},
    {"nz", R_NZ},       {"u", R_U},         {"v", R_V},         {"s", R_U},         {"t", R_V},
    {"texture_u", R_U}, {"texture_v", R_V}, {"texture_s", R_U}, {"texture_t", R_V},
};

/* Find the vertex and face elements and the properties we read. */
static rsw_status ply_bind(ply_file *f) {
  f->vertex_elem = f->face_elem = f->face_prop = -1;
  for (int r = 0; r < R__COUNT; r++) f->role_prop[r] = -1;
  for (int e = 0; e < f->n_elems; e++) {
    if (strcmp(f->elems[e].name, "vertex") == 0 && f->vertex_elem < 0) f->vertex_elem = e;
    if (strcmp(f->elems[e].name, "face") == 0 && f->face_elem < 0) f->face_elem = e;
  }
  if (f->vertex_elem < 0) return rsw_fail(f->err, RSW_ERR_FILE, f->path, "bad PLY header: no vertex element");
  const ply_elem *ve = &f->elems[f->vertex_elem];
  for (int i = 0; i < ve->n_props; i++)
    for (size_t k = 0; k < sizeof ply_roles / sizeof *ply_roles; k++)
      if (strcmp(ve->props[i].name, ply_roles[k].name) == 0 && f->role_prop[ply_roles[k].role] < 0) {
        if (ve->props[i].count_type != PLY_INVALID)
          return rsw_fail(f->err, RSW_ERR_FILE, f->path, "bad PLY header: vertex property %s is a list",
                          ve->props[i].name);
        f->role_prop[ply_roles[k].role] = i;
      }
  for (int r = R_X; r <= R_Z; r++)
    if (f->role_prop[r] < 0)
      return rsw_fail(f->err, RSW_ERR_FILE, f->path, "bad PLY header: vertex element lacks %c",
                      "xyz"[r - R_X]);
  /* Normals need all three, uvs both. */
  if (f->role_prop[R_NX] < 0 || f->role_prop[R_NY] < 0 || f->role_prop[R_NZ] < 0)
    f->role_prop[R_NX] = f->role_prop[R_NY] = f->role_prop[R_NZ] = -1;
  if (f->role_prop[R_U] < 0 || f->role_prop[R_V] < 0) f->role_prop[R_U] = f->role_prop[R_V] = -1;
  if (f->face_elem < 0 || f->elems[f->face_elem].count == 0)
    return rsw_fail(f->err, RSW_ERR_FILE, f->path, "PLY file has no faces");
  const ply_elem *fe = &f->elems[f->face_elem];
  for (int i = 0; i < fe->n_props; i++)
    if (strcmp(fe->props[i].name, "vertex_indices") == 0 || strcmp(fe->props[i].name, "vertex_index") == 0) {
      f->face_prop = i;
      break;
    }
  if (f->face_prop < 0)
    return rsw_fail(f->err, RSW_ERR_FILE, f->path, "bad PLY header: face element has no vertex_indices");
  const ply_prop *fp = &fe->props[f->face_prop];
  if (fp->count_type == PLY_INVALID || !ply_is_integer(fp->type))
    return rsw_fail(f->err, RSW_ERR_FILE, f->path, "bad PLY header: face %s must be a list of integers",
                    fp->name);
  return RSW_OK;
}

/* Fewest bytes one instance of el can take in the data section. */
static uint64_t ply_min_row_bytes(const ply_file *f, const ply_elem *el) {
  uint64_t b = 0;
  for (int i = 0; i < el->n_props; i++)
    b += f->ascii ? 2
                  : ply_type_size[el->props[i].count_type != PLY_INVALID ? el->props[i].count_type
                                                                         : el->props[i].type];
  return b;
}

/* Read one value of type t at the cursor. */
static rsw_status ply_value(ply_file *f, ply_type t, double *out) {
  if (f->ascii) {
    while (f->p < f->end && (is_blank((char)*f->p) || *f->p == '\n')) {
      if (*f->p == '\n') f->line++;
      f->p++;
    }
    if (f->p >= f->end) return ply_fail(f, RSW_ERR_FILE, "truncated: file ends inside the data");
    const char *s = (const char *)f->p;
    char *e;
    double x = strtod(s, &e);
    if (e == s || ((const unsigned char *)e < f->end && *e && !is_blank(*e) && *e != '\n')) {
      const char *t2 = s;
      while ((const unsigned char *)t2 < f->end && *t2 && !is_blank(*t2) && *t2 != '\n') t2++;
      return ply_fail(f, RSW_ERR_FILE, "bad number \"%.*s\"", (int)(t2 - s > 40 ? 40 : t2 - s), s);
    }
    if (ply_is_integer(t) && x != floor(x))
      return ply_fail(f, RSW_ERR_FILE,
                      "non-integer value %g for an integer "
                      "property",
                      x);
    f->p = (const unsigned char *)e;
    *out = x;
    return RSW_OK;
  }
  unsigned sz = ply_type_size[t];
  if ((size_t)(f->end - f->p) < sz) return ply_fail(f, RSW_ERR_FILE, "truncated: file ends inside the data");
  const unsigned char *b = f->p;
  /* Little-endian: assemble the bits byte by byte, whatever the host. */
  uint64_t u = 0;
  for (unsigned i = 0; i < sz; i++) u |= (uint64_t)b[i] << (8 * i);
  switch (t) {
  case PLY_I8: *out = (double)(int8_t)(uint8_t)u; break;
  case PLY_U8: *out = (double)(uint8_t)u; break;
  case PLY_I16: *out = (double)(int16_t)(uint16_t)u; break;
  case PLY_U16: *out = (double)(uint16_t)u; break;
  case PLY_I32: *out = (double)(int32_t)(uint32_t)u; break;
  case PLY_U32: *out = (double)(uint32_t)u; break;
  case PLY_F32: {
    uint32_t w = (uint32_t)u;
    float x;
    memcpy(&x, &w, 4);
    *out = x;
    break;
  }
  case PLY_F64: {
    double x;
    memcpy(&x, &u, 8);
    *out = x;
    break;
  }
  default: return ply_fail(f, RSW_ERR_FILE, "invalid property type");
  }
  f->p += sz;
  return RSW_OK;
}

/* Read a list's length at the cursor; checked against the bytes left. */
static rsw_status ply_list_count(ply_file *f, const ply_prop *pr, uint64_t *n) {
  double c;
  rsw_status st = ply_value(f, pr->count_type, &c);
  if (st != RSW_OK) return st;
  uint64_t min_item = f->ascii ? 1 : ply_type_size[pr->type];
  if (c < 0) return ply_fail(f, RSW_ERR_FILE, "list %s has negative length %g", pr->name, c);
  if (c > (double)(uint64_t)(f->end - f->p) / (double)min_item + 1)
    return ply_fail(f, RSW_ERR_FILE,
                    "truncated: list %s of %g items runs past the end of the "
                    "file",
                    pr->name, c);
  *n = (uint64_t)c;
  return RSW_OK;
}

/* Skip one property (scalar or list) at the cursor. */
static rsw_status ply_skip_prop(ply_file *f, const ply_prop *pr) {
  double x;
  if (pr->count_type == PLY_INVALID) return ply_value(f, pr->type, &x);
  uint64_t n;
  rsw_status st = ply_list_count(f, pr, &n);
  if (st != RSW_OK) return st;
  if (!f->ascii) {
    uint64_t bytes = n * ply_type_size[pr->type];
    if (bytes > (uint64_t)(f->end - f->p))
      return ply_fail(f, RSW_ERR_FILE, "truncated: list %s runs past the end", pr->name);
    f->p += bytes;
    return RSW_OK;
  }
  for (uint64_t i = 0; i < n; i++)
    if ((st = ply_value(f, pr->type, &x)) != RSW_OK) return st;
  return RSW_OK;
}

static rsw_status ply_read_vertices(ply_file *f, const ply_elem *el, mesh *m) {
  for (uint64_t i = 0; i < el->count; i++) {
    f->cur_index = i;
    double role[R__COUNT] = {0};
    for (int k = 0; k < el->n_props; k++) {
      const ply_prop *pr = &el->props[k];
      int r = -1;
      for (int q = 0; q < R__COUNT; q++)
        if (f->role_prop[q] == k) r = q;
      if (r < 0) {
        rsw_status st = ply_skip_prop(f, pr);
        if (st != RSW_OK) return st;
        continue;
      }
      double x;
      const unsigned char *at = f->p;
      rsw_status st = ply_value(f, pr->type, &x);
      if (st != RSW_OK) return st;
      if (!isfinite(x) || !isfinite((float)x)) {
        if (!f->ascii) f->p = at; /* name the value's first byte */
        return ply_fail(f, RSW_ERR_FILE, "non-finite %s = %g", pr->name, x);
      }
      role[r] = x;
    }
    for (int c = 0; c < 3; c++) m->pos[3 * i + c] = (float)role[R_X + c];
    if (m->nrm)
      for (int c = 0; c < 3; c++) m->nrm[3 * i + c] = (float)role[R_NX + c];
    if (m->uv) {
      m->uv[2 * i] = (float)role[R_U];
      m->uv[2 * i + 1] = (float)role[R_V];
    }
  }
  return RSW_OK;
}

static rsw_status ply_read_faces(ply_file *f, const ply_elem *el, mesh *m, size_t *cap_faces) {
  uint32_t nv = (uint32_t)f->elems[f->vertex_elem].count;
  for (uint64_t i = 0; i < el->count; i++) {
    f->cur_index = i;
    for (int k = 0; k < el->n_props; k++) {
      const ply_prop *pr = &el->props[k];
      rsw_status st;
      if (k != f->face_prop) {
        if ((st = ply_skip_prop(f, pr)) != RSW_OK) return st;
        continue;
      }
      uint64_t n;
      if ((st = ply_list_count(f, pr, &n)) != RSW_OK) return st;
      if (n < 3)
        return ply_fail(f, RSW_ERR_FILE, "face with %llu vertices (need 3 or more)", (unsigned long long)n);
      if ((uint64_t)m->n_faces + (n - 2) > MESH_MAX_ELEMENTS)
        return ply_fail(f, RSW_ERR_LIMIT, "more than %u triangles", (unsigned)MESH_MAX_ELEMENTS);
      if (!reserve((void **)&m->faces, cap_faces, ((size_t)m->n_faces + (size_t)(n - 2)) * 3,
                   sizeof *m->faces))
        return ply_fail(f, RSW_ERR_NOMEM, "no memory for faces");
      uint32_t first = 0, prev = 0;
      for (uint64_t j = 0; j < n; j++) {
        double x;
        const unsigned char *at = f->p;
        if ((st = ply_value(f, pr->type, &x)) != RSW_OK) return st;
        if (x < 0 || x >= (double)nv) {
          if (!f->ascii) f->p = at; /* name the index's first byte */
          return ply_fail(f, RSW_ERR_FILE, "vertex index %.0f out of range [0, %u)", x, nv);
        }
        uint32_t idx = (uint32_t)x;
        /* Fan: (v0, v[j-1], v[j]) for j >= 2. */
        if (j == 0) first = idx;
        if (j >= 2) {
          uint32_t *t = m->faces + 3 * (size_t)m->n_faces++;
          t[0] = first;
          t[1] = prev;
          t[2] = idx;
        }
        prev = idx;
      }
    }
  }
  return RSW_OK;
}

static rsw_status ply_skip_elem(ply_file *f, const ply_elem *el) {
  uint64_t fixed = 0;
  bool has_list = false;
  for (int k = 0; k < el->n_props; k++) {
    has_list |= el->props[k].count_type != PLY_INVALID;
    fixed += ply_type_size[el->props[k].type];
  }
  if (!f->ascii && !has_list) {
    /* count <= 2^31 and fixed <= 64 * 8: no overflow. */
    uint64_t bytes = el->count * fixed;
    if (bytes > (uint64_t)(f->end - f->p))
      return ply_fail(f, RSW_ERR_FILE,
                      "truncated: element %s needs %llu "
                      "bytes",
                      el->name, (unsigned long long)bytes);
    f->p += bytes;
    return RSW_OK;
  }
  for (uint64_t i = 0; i < el->count; i++) {
    f->cur_index = i;
    for (int k = 0; k < el->n_props; k++) {
      rsw_status st = ply_skip_prop(f, &el->props[k]);
      if (st != RSW_OK) return st;
    }
  }
  return RSW_OK;
}

/* Parse the header; on success f->p is the first data byte. */
static rsw_status ply_header(ply_file *f, char *data, size_t size) {
  if (size < 4 || memcmp(data, "ply", 3) != 0 || (data[3] != '\n' && data[3] != '\r'))
    return header_fail(f, 1, RSW_ERR_FILE, "file does not start with \"ply\"");
  char *p = data, *end = data + size;
  size_t ln = 0;
  bool done = false, have_format = false;
  while (!done) {
    char *nl = memchr(p, '\n', (size_t)(end - p));
    ln++;
    if (!nl) return header_fail(f, ln, RSW_ERR_FILE, "no end_header line");
    *nl = '\0';
    if (memchr(p, '\0', (size_t)(nl - p))) return header_fail(f, ln, RSW_ERR_FILE, "NUL byte in the header");
    if (ln > 1) {
      bool fmt = strncmp(p, "format", 6) == 0;
      if (!have_format && !fmt && strncmp(p, "comment", 7) != 0)
        return header_fail(f, ln, RSW_ERR_FILE, "format line missing before \"%.40s\"", p);
      rsw_status st = ply_header_line(f, p, ln, &done);
      if (st != RSW_OK) return st;
      have_format |= fmt;
    }
    p = nl + 1;
  }
  f->p = (const unsigned char *)p;
  f->line = ln + 1;
  return RSW_OK;
}

rsw_status mesh_load_ply(const char *path, mesh *out, rsw_err *err) {
  file_buf fb;
  rsw_status st = read_whole_file(path, &fb, err);
  if (st != RSW_OK) return st;
  ply_file *f = calloc(1, sizeof *f); /* ~270 KiB: not on the stack */
  if (!f) {
    free(fb.data);
    return rsw_fail(err, RSW_ERR_NOMEM, path, "no memory");
  }
  f->path = path;
  f->err = err;
  f->base = (const unsigned char *)fb.data;
  f->end = f->base + fb.size;
  f->cur_elem = "header";
  mesh m = {0};
  size_t cap_faces = 0;
  st = ply_header(f, fb.data, fb.size);
  if (st == RSW_OK) st = ply_bind(f);
  if (st == RSW_OK) {
    /* Every element must fit in the bytes that follow the header before we
     * allocate for it. */
    uint64_t left = (uint64_t)(f->end - f->p), need = 0;
    for (int e = 0; e < f->n_elems; e++) {
      const ply_elem *el = &f->elems[e];
      need += el->count * ply_min_row_bytes(f, el); /* <= 2^31 * 512 each */
    }
    /* ascii: the last value needs no separator. */
    if (f->ascii && need > 0) need--;
    if (need > left)
      st = rsw_fail(err, RSW_ERR_FILE, path,
                    "truncated: the header declares at least %llu bytes of "
                    "data but %llu follow",
                    (unsigned long long)need, (unsigned long long)left);
  }
  if (st == RSW_OK) {
    const ply_elem *ve = &f->elems[f->vertex_elem];
    size_t nv = (size_t)ve->count;
    m.n_verts = (uint32_t)nv;
    m.pos = malloc((nv ? nv : 1) * 3 * sizeof *m.pos);
    if (f->role_prop[R_NX] >= 0) m.nrm = malloc((nv ? nv : 1) * 3 * sizeof *m.nrm);
    if (f->role_prop[R_U] >= 0) m.uv = malloc((nv ? nv : 1) * 2 * sizeof *m.uv);
    if (!m.pos || (f->role_prop[R_NX] >= 0 && !m.nrm) || (f->role_prop[R_U] >= 0 && !m.uv))
      st = rsw_fail(err, RSW_ERR_NOMEM, path, "no memory for %zu vertices", nv);
  }
  for (int e = 0; st == RSW_OK && e < f->n_elems; e++) {
    const ply_elem *el = &f->elems[e];
    f->cur_elem = el->name;
    f->cur_index = 0;
    if (e == f->vertex_elem)
      st = ply_read_vertices(f, el, &m);
    else if (e == f->face_elem)
      st = ply_read_faces(f, el, &m, &cap_faces);
    else
      st = ply_skip_elem(f, el);
  }
  if (st == RSW_OK && m.n_faces == 0) st = rsw_fail(err, RSW_ERR_FILE, path, "PLY file has no faces");
  free(f);
  free(fb.data);
  if (st != RSW_OK) {
    mesh_free(&m);
    return st;
  }
  *out = m;
  return RSW_OK;
}
