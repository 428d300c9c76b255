/* Mitsuba XML scene reader (scene format 2.x / 3.x) -> document tree.
 *
 * The only file that includes expat.h. expat streams start/end/text events;
 * a fixed stack of frames (one per open element) tracks where we are:
 *
 *   FR_SCENE      the root <scene>            (an object: holds properties)
 *   FR_OBJECT     <shape>, <bsdf>, ...        (holds properties and objects)
 *   FR_TRANSFORM  <transform name=...>        (holds transform operations)
 *   FR_LEAF       every other element         (must stay empty)
 *
 * Objects and properties are attached to their parent as soon as their start
 * tag is read, so the tree under `root` owns everything at every moment and
 * one node_free(root) cleans up after any error.
 *
 * Semantics follow Mitsuba 3 src/core/xml.cpp (parse_xml): element names and
 * their attributes, $param substitution, value="x, y, z" expansion, each
 * transform operation left-multiplied onto the accumulated transform, lookat
 * without `up` choosing coordinate_system(dir).first. Where Mitsuba is
 * lenient in ways that hide mistakes we are stricter, and say so below:
 *   - duplicate property names in one object are an error (Mitsuba errors
 *     too, later, in Properties);
 *   - <integer> is exact within +-2^53 (so a double holds it exactly);
 *   - numbers are plain decimal (no hex, inf, nan), finite; blanks around
 *     a single number are tolerated (as std::stof/stoll do); lists split on
 *     runs of commas and/or whitespace (string::tokenize(s, ", "));
 *   - <boolean> takes "true"/"false" in any case (Mitsuba lower-cases);
 *   - <vector>/<point>: x, y, z each default to 0 (Mitsuba 3 requires all
 *     three); a one-number value= is replicated, as Mitsuba does;
 *   - text content inside elements, DOCTYPEs, <include>, <alias>, <path> and
 *     file-based spectra are rejected with a clear error;
 *   - <default> may only appear directly under <scene>, before its use
 *     (parameters substitute in document order), and only once per name;
 *   - a -D define that no <default> declares is accepted and substituted
 *     wherever $name appears, as Mitsuba does (its parameter list is simply
 *     the defines plus the defaults); but one that no <default> declares
 *     and no $name uses is an error naming it (a misspelt -D rh0=0.3 would
 *     otherwise leave $rho at its default without a word).
 */
#include "node.h"

#include "../core/strdist.h"

#include <ctype.h>
#include <expat.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#define XML_MAX_DOC      ((size_t)256 << 20) /* bytes of XML text */
#define XML_MAX_ATTRS    16                  /* attributes on one element */
#define XML_MAX_ATTR_LEN ((size_t)16 << 20)  /* one value after $ expansion */
#define XML_MAX_PARAMS   RSW_MAX_PROPS       /* defines + <default>s */
#define XML_MAX_TOKEN    128                 /* characters in one number */
#define XML_INT_LIMIT    9007199254740992.0  /* 2^53 */

typedef enum frame_kind {
  FR_SCENE,
  FR_OBJECT,
  FR_TRANSFORM,
  FR_LEAF
} frame_kind;

typedef struct xml_frame {
  frame_kind kind;
  const char *elem;  /* element name (static, from the tag table) */
  node *obj;         /* FR_SCENE, FR_OBJECT: the node being filled */
  node *owner;       /* FR_TRANSFORM: node holding the transform property */
  size_t prop_index; /* FR_TRANSFORM: its index in owner->props */
  xform acc;         /* FR_TRANSFORM: ops applied so far */
} xml_frame;

/* A substitution parameter: a -D define (borrowed strings) or a <default>
 * (owned strings). */
typedef struct param {
  const char *name, *value;
  char *own_name, *own_value;
  bool from_define;
  bool declared; /* a <default> of this name was seen */
  bool used;     /* a $name was substituted by it */
} param;

/* Explicit ids seen so far (open addressing; keys borrowed from nodes). */
typedef struct id_slot {
  const char *id;
  unsigned long line;
} id_slot;

typedef struct id_table {
  id_slot *slots;
  size_t cap, n; /* cap is 0 or a power of two */
} id_table;

typedef struct xml_ctx {
  XML_Parser parser;
  const char *file;   /* source name as used in locations */
  unsigned long line; /* line of the element or text being handled */
  const char *elem;   /* element being handled, for messages */
  char loc[256];      /* "file:line" of that element */
  rsw_err err;
  bool failed;
  node *root;
  char *variant;
  xml_frame stack[RSW_MAX_DEPTH];
  size_t depth;
  size_t n_nodes;
  const scene_limits *lim;
  size_t bytes;    /* document tree memory so far (node_mem_*), counted
                     before (or as) it is allocated */
  size_t expanded; /* bytes $ substitution has produced in this document */
  param *params;
  size_t n_params, cap_params;
  id_table ids;
  /* Attributes of the current element, after $ substitution (owned). */
  size_t n_attrs;
  const char *attr_name[XML_MAX_ATTRS];
  char *attr_value[XML_MAX_ATTRS];
} xml_ctx;

/* ---- errors --------------------------------------------------------------- */

static void set_loc(xml_ctx *c, unsigned long line) {
  c->line = line;
  snprintf(c->loc, sizeof c->loc, "%s:%lu", c->file, line);
}

/* Record the first error at the current element's line and stop expat.
 * Returns code so handlers can "report and return". */
static rsw_status xfail(xml_ctx *c, rsw_status code, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static rsw_status xfail(xml_ctx *c, rsw_status code, const char *fmt, ...) {
  if (!c->failed) {
    char msg[sizeof c->err.msg];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (c->elem)
      rsw_fail(&c->err, code, c->loc, "<%s>: %s", c->elem, msg);
    else
      rsw_fail(&c->err, code, c->loc, "%s", msg);
    c->failed = true;
    if (c->parser) XML_StopParser(c->parser, XML_FALSE);
  }
  return code;
}

/* ---- strict number parsing ------------------------------------------------ */

/* Plain decimal: [+-] (digits [. digits] | . digits) [(e|E) [+-] digits].
 * strtod alone would also take hex, "inf", "nan" and leading blanks. */
static bool is_decimal(const char *s) {
  const char *p = s;
  if (*p == '+' || *p == '-') p++;
  size_t int_digits = 0, frac_digits = 0;
  while (isdigit((unsigned char)*p)) p++, int_digits++;
  if (*p == '.') {
    p++;
    while (isdigit((unsigned char)*p)) p++, frac_digits++;
  }
  if (int_digits + frac_digits == 0) return false;
  if (*p == 'e' || *p == 'E') {
    p++;
    if (*p == '+' || *p == '-') p++;
    if (!isdigit((unsigned char)*p)) return false;
    while (isdigit((unsigned char)*p)) p++;
  }
  return *p == '\0';
}

/* Copy s without surrounding whitespace into buf (Mitsuba's stof/stoll
 * tolerate both); false when it does not fit. */
static bool trim_copy(const char *s, char *buf, size_t cap) {
  while (isspace((unsigned char)*s)) s++;
  size_t n = strlen(s);
  while (n > 0 && isspace((unsigned char)s[n - 1])) n--;
  if (n + 1 > cap) return false;
  memcpy(buf, s, n);
  buf[n] = '\0';
  return true;
}

static bool parse_double(const char *raw, double *out) {
  char s[XML_MAX_TOKEN];
  if (!trim_copy(raw, s, sizeof s) || !is_decimal(s)) return false;
  char *end;
  double v = strtod(s, &end);
  if (*end != '\0' || !isfinite(v)) return false;
  *out = v;
  return true;
}

/* Integer with |v| <= 2^53, so that the double in prop.num holds it exactly. */
static bool parse_int(const char *raw, double *out) {
  char s[XML_MAX_TOKEN];
  if (!trim_copy(raw, s, sizeof s)) return false;
  const char *p = s;
  bool neg = false;
  if (*p == '+' || *p == '-') neg = (*p++ == '-');
  if (!isdigit((unsigned char)*p)) return false;
  uint64_t v = 0;
  for (; isdigit((unsigned char)*p); p++) {
    v = v * 10 + (uint64_t)(*p - '0');
    if (v > ((uint64_t)1 << 53)) return false;
  }
  if (*p != '\0') return false;
  *out = neg ? -(double)v : (double)v;
  return true;
}

static bool is_sep(char ch) {
  return ch == ',' || isspace((unsigned char)ch);
}

/* Copy the next token (a run of non-separators) into buf; false at the end.
 * Separators are runs of commas and/or whitespace, as Mitsuba's
 * string::tokenize(s, ", "). *too_long is set for tokens past buf. */
static bool next_token(const char **s, char *buf, size_t cap, bool *too_long) {
  const char *p = *s;
  while (*p && is_sep(*p)) p++;
  if (!*p) return false;
  size_t n = 0;
  *too_long = false;
  while (*p && !is_sep(*p)) {
    if (n + 1 < cap)
      buf[n++] = *p;
    else
      *too_long = true;
    p++;
  }
  buf[n] = '\0';
  *s = p;
  return true;
}

/* Parse up to `max` numbers from attribute `what`; *n gets the count. */
static rsw_status parse_numbers(xml_ctx *c, const char *what, const char *s, double *out, size_t max,
                                size_t *n) {
  char tok[XML_MAX_TOKEN];
  bool too_long;
  *n = 0;
  while (next_token(&s, tok, sizeof tok, &too_long)) {
    if (*n == max) return xfail(c, RSW_ERR_INVALID, "%s has more than %zu numbers", what, max);
    if (too_long || !parse_double(tok, &out[*n]))
      return xfail(c, RSW_ERR_INVALID, "%s: could not parse number \"%s%s\"", what, tok,
                   too_long ? "..." : "");
    (*n)++;
  }
  return RSW_OK;
}

/* ---- attributes ----------------------------------------------------------- */

static void attrs_clear(xml_ctx *c) {
  for (size_t i = 0; i < c->n_attrs; i++) free(c->attr_value[i]);
  c->n_attrs = 0;
}

static const char *attr(const xml_ctx *c, const char *name) {
  for (size_t i = 0; i < c->n_attrs; i++)
    if (strcmp(c->attr_name[i], name) == 0) return c->attr_value[i];
  return NULL;
}

/* Every attribute present must be in `allowed` (NULL-terminated); every
 * name in `required` (NULL-terminated, may be NULL) must be present. */
static rsw_status attrs_check(xml_ctx *c, const char *const *allowed, const char *const *required) {
  for (size_t i = 0; i < c->n_attrs; i++) {
    bool ok = false;
    for (const char *const *a = allowed; *a && !ok; a++) ok = strcmp(*a, c->attr_name[i]) == 0;
    if (!ok) return xfail(c, RSW_ERR_PARSE, "unexpected attribute \"%s\"", c->attr_name[i]);
  }
  for (const char *const *r = required; r && *r; r++)
    if (!attr(c, *r)) return xfail(c, RSW_ERR_MISSING, "missing attribute \"%s\"", *r);
  return RSW_OK;
}

/* Names, ids and types: non-empty, bounded, and (as in Mitsuba) no leading
 * underscore, which Mitsuba reserves for generated identifiers. */
static rsw_status check_ident(xml_ctx *c, const char *what, const char *s) {
  if (!s[0]) return xfail(c, RSW_ERR_INVALID, "attribute \"%s\" is empty", what);
  if (strlen(s) > RSW_MAX_NAME)
    return xfail(c, RSW_ERR_LIMIT, "attribute \"%s\" is longer than %d characters", what, RSW_MAX_NAME);
  if (s[0] == '_')
    return xfail(c, RSW_ERR_INVALID, "attribute \"%s\" = \"%s\": a leading underscore is reserved", what, s);
  return RSW_OK;
}

/* ---- $param substitution ------------------------------------------------- */

static param *param_find(xml_ctx *c, const char *name) {
  for (size_t i = 0; i < c->n_params; i++)
    if (strcmp(c->params[i].name, name) == 0) return &c->params[i];
  return NULL;
}

static param *param_add(xml_ctx *c) {
  if (c->n_params >= XML_MAX_PARAMS) return NULL;
  if (c->n_params == c->cap_params) {
    size_t cap = c->cap_params ? 2 * c->cap_params : 16;
    param *p = realloc(c->params, cap * sizeof *p);
    if (!p) return NULL;
    c->params = p;
    c->cap_params = cap;
  }
  param *p = &c->params[c->n_params++];
  memset(p, 0, sizeof *p);
  return p;
}

/* The parameter whose name starts at s (just after a '$'), the longest
 * such name winning, or NULL; *name_len gets its length. */
static param *param_at(xml_ctx *c, const char *s, size_t *name_len) {
  param *best = NULL;
  *name_len = 0;
  for (size_t i = 0; i < c->n_params; i++) {
    size_t len = strlen(c->params[i].name);
    if (len > *name_len && strncmp(s, c->params[i].name, len) == 0) {
      best = &c->params[i];
      *name_len = len;
    }
  }
  return best;
}

/* Replace every $name in raw by its parameter value; owned result or NULL
 * (error recorded). At each '$' the longest parameter name that follows
 * wins, which is what Mitsuba's replace-longest-names-first amounts to.
 * Substituted text is not rescanned, so expansion is bounded: one value by
 * XML_MAX_ATTR_LEN, and what substitution adds to the whole document by
 * its memory cap (a few bytes of "$p$p$p..." would otherwise make up to
 * 16 MiB per attribute, over and over). The first pass measures and
 * checks, so a value over a bound is never allocated. */
static char *substitute(xml_ctx *c, const char *attr_name, const char *raw) {
  if (!strchr(raw, '$')) {
    char *r = rsw_strdup(raw);
    if (!r) xfail(c, RSW_ERR_NOMEM, "out of memory");
    return r;
  }
  size_t out = 0, added = 0, name_len;
  const char *p = raw, *d;
  for (; (d = strchr(p, '$')); p = d + 1 + name_len) {
    out += (size_t)(d - p);
    param *best = param_at(c, d + 1, &name_len);
    if (!best) {
      size_t id = 0;
      while (d[1 + id] && (isalnum((unsigned char)d[1 + id]) || d[1 + id] == '_') && id < 64) id++;
      xfail(c, RSW_ERR_INVALID,
            "attribute \"%s\": undefined parameter \"$%.*s\" (declare it with <default> "
            "or pass -D)",
            attr_name, (int)id, d + 1);
      return NULL;
    }
    size_t vlen = strlen(best->value);
    if (out + vlen > XML_MAX_ATTR_LEN) {
      xfail(c, RSW_ERR_LIMIT, "attribute \"%s\" is longer than %zu bytes after substitution", attr_name,
            XML_MAX_ATTR_LEN);
      return NULL;
    }
    if (vlen > c->lim->max_tree_bytes - c->expanded - added) { /* (c->expanded + added <= the cap) */
      xfail(c, RSW_ERR_LIMIT,
            "attribute \"%s\": $ substitution has added more text to the document's attributes than "
            "its memory cap of %zu bytes (%.0f MiB); split the scene or raise the cap",
            attr_name, c->lim->max_tree_bytes, c->lim->max_tree_bytes / 1048576.0);
      return NULL;
    }
    out += vlen;
    added += vlen;
    best->used = true;
  }
  out += strlen(p);
  char *r = malloc(out + 1);
  if (!r) {
    xfail(c, RSW_ERR_NOMEM, "out of memory");
    return NULL;
  }
  c->expanded += added;
  char *w = r;
  for (p = raw; (d = strchr(p, '$')); p = d + 1 + name_len) {
    memcpy(w, p, (size_t)(d - p));
    w += d - p;
    const param *best = param_at(c, d + 1, &name_len);
    size_t vlen = strlen(best->value);
    memcpy(w, best->value, vlen);
    w += vlen;
  }
  strcpy(w, p);
  return r;
}

static rsw_status attrs_load(xml_ctx *c, const XML_Char **atts) {
  for (size_t i = 0; atts[2 * i]; i++) {
    if (c->n_attrs == XML_MAX_ATTRS) return xfail(c, RSW_ERR_LIMIT, "more than %d attributes", XML_MAX_ATTRS);
    char *v = substitute(c, atts[2 * i], atts[2 * i + 1]);
    if (!v) return c->err.code;
    c->attr_name[c->n_attrs] = atts[2 * i]; /* valid during the start handler */
    c->attr_value[c->n_attrs++] = v;
  }
  return RSW_OK;
}

/* ---- explicit ids ----------------------------------------------------------- */

static size_t hash_str(const char *s) { /* FNV-1a */
  uint64_t h = 1469598103934665603ull;
  for (; *s; s++) h = (h ^ (unsigned char)*s) * 1099511628211ull;
  return (size_t)h;
}

static id_slot *ids_lookup(id_table *t, const char *id) {
  size_t mask = t->cap - 1;
  for (size_t i = hash_str(id) & mask;; i = (i + 1) & mask)
    if (!t->slots[i].id || strcmp(t->slots[i].id, id) == 0) return &t->slots[i];
}

/* Insert id (borrowed); if present, *prev_line gets the first line and false
 * is returned with *nomem false. */
static bool ids_insert(id_table *t, const char *id, unsigned long line, unsigned long *prev_line,
                       bool *nomem) {
  *nomem = false;
  if (2 * (t->n + 1) > t->cap) {
    size_t cap = t->cap ? 2 * t->cap : 64;
    id_slot *s = calloc(cap, sizeof *s);
    if (!s) {
      *nomem = true;
      return false;
    }
    id_table nt = {s, cap, 0};
    for (size_t i = 0; i < t->cap; i++)
      if (t->slots[i].id) *ids_lookup(&nt, t->slots[i].id) = t->slots[i];
    nt.n = t->n;
    free(t->slots);
    *t = nt;
  }
  id_slot *slot = ids_lookup(t, id);
  if (slot->id) {
    *prev_line = slot->line;
    return false;
  }
  slot->id = id;
  slot->line = line;
  t->n++;
  return true;
}

/* ---- element handlers ------------------------------------------------------ */

typedef rsw_status (*tag_start_fn)(xml_ctx *c, xml_frame *parent, xml_frame *self);

/* Where an element may appear. */
typedef enum placement {
  IN_ROOT,      /* <scene> only */
  IN_OBJECT,    /* child of <scene> or of an object */
  IN_SCENE,     /* child of <scene> only */
  IN_TRANSFORM, /* child of <transform> only */
} placement;

typedef struct tag_def {
  const char *name;
  placement place;
  tag_start_fn start;
} tag_def;

/* Count `bytes` more of document tree (in `owner`) against the memory
 * cap; callers count what they are about to allocate, or have just grown. */
static rsw_status charge(xml_ctx *c, const node *owner, size_t bytes) {
  if (bytes > c->lim->max_tree_bytes - c->bytes) /* (c->bytes <= the cap) */
    return xfail(c, RSW_ERR_LIMIT,
                 "the scene document needs more than its memory cap of %zu bytes (%.0f MiB) here, in %s "
                 "'%s' (opened at %s); split the scene or raise the cap",
                 c->lim->max_tree_bytes, c->lim->max_tree_bytes / 1048576.0, owner->type,
                 owner->id ? owner->id : "", owner->loc);
  c->bytes += bytes;
  return RSW_OK;
}

/* Add a property to `owner`, rejecting a second property of the same
 * (non-empty) name, as Mitsuba's Properties does (node_find is hashed on
 * large objects, so a group of 100,000 named members stays linear). An
 * ordinary object takes at most lim->max_props properties; containers (the
 * scene, a shapegroup) any number within the tree's memory cap. */
static prop *add_prop(xml_ctx *c, node *owner, const char *name, prop_kind kind) {
  if (name[0]) {
    const prop *old = node_find(owner, name);
    if (old) {
      xfail(c, RSW_ERR_DUPLICATE, "duplicate property \"%s\" (first given at %s)", name, old->loc);
      return NULL;
    }
  }
  if (!node_type_is_container(owner->type) && owner->n_props >= c->lim->max_props) {
    xfail(c, RSW_ERR_LIMIT,
          "%s '%s' (opened at %s) has more than the %zu properties an object may have (only the "
          "scene and shapegroups take more)",
          owner->type, owner->id ? owner->id : "", owner->loc, c->lim->max_props);
    return NULL;
  }
  size_t arrays = node_mem_arrays(owner);
  prop *p = node_add_prop(owner, name, kind, c->loc);
  if (!p) {
    if (owner->n_props >= RSW_MAX_NODES)
      xfail(c, RSW_ERR_LIMIT, "more than %d properties in %s '%s'", RSW_MAX_NODES, owner->type,
            owner->id ? owner->id : "");
    else
      xfail(c, RSW_ERR_NOMEM, "out of memory");
    return NULL;
  }
  /* The new slot and index growth, the name and loc; the value's own
   * memory (a string, spectrum samples, a child node) is counted by the
   * caller as it is made. */
  if (charge(c, owner, node_mem_arrays(owner) - arrays + node_mem_prop(p))) return NULL;
  return p;
}

/* name= of a property element: required, a valid identifier. */
static const char *prop_name(xml_ctx *c) {
  const char *name = attr(c, "name");
  if (!name) {
    xfail(c, RSW_ERR_MISSING, "missing attribute \"name\"");
    return NULL;
  }
  return check_ident(c, "name", name) ? NULL : name;
}

static rsw_status start_scene(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  static const char *const allowed[] = {"version", "variant", NULL};
  static const char *const required[] = {"version", NULL};
  if (attrs_check(c, allowed, required)) return c->err.code;
  /* version="major.minor.patch", three unsigned integers (Mitsuba's
   * Version(const char *)). */
  const char *v = attr(c, "version");
  unsigned long part[3];
  const char *p = v;
  for (int i = 0; i < 3; i++) {
    if (!isdigit((unsigned char)*p))
      return xfail(c, RSW_ERR_PARSE, "version \"%s\" is not of the form X.Y.Z", v);
    char *end;
    part[i] = strtoul(p, &end, 10);
    p = end;
    if (i < 2 && *p++ != '.') return xfail(c, RSW_ERR_PARSE, "version \"%s\" is not of the form X.Y.Z", v);
  }
  if (*p) return xfail(c, RSW_ERR_PARSE, "version \"%s\" is not of the form X.Y.Z", v);
  if (part[0] != 2 && part[0] != 3)
    return xfail(c, RSW_ERR_UNSUPPORTED, "scene version %s is not supported (versions 2.x.x and 3.x.x are)",
                 v);
  const char *variant = attr(c, "variant");
  if (variant) {
    /* As scene/loader.c variant_parse (this reader stays below the kernel). */
    static const char *const known[] = {"mono",
                                        "rgb",
                                        "scalar_mono",
                                        "scalar_mono_double",
                                        "scalar_rgb",
                                        "mono_polarized",
                                        "rgb_polarized",
                                        "scalar_mono_polarized",
                                        "scalar_mono_polarized_double",
                                        "scalar_rgb_polarized"};
    bool ok = false;
    for (size_t i = 0; i < sizeof known / sizeof known[0]; i++) ok |= strcmp(variant, known[i]) == 0;
    if (!ok)
      return xfail(c, RSW_ERR_INVALID,
                   "variant \"%s\" is not \"mono\", \"rgb\", \"mono_polarized\" or \"rgb_polarized\"",
                   variant);
    if (!(c->variant = rsw_strdup(variant))) return xfail(c, RSW_ERR_NOMEM, "out of memory");
  }
  if (!(c->root = node_new("scene", "scene", c->loc))) return xfail(c, RSW_ERR_NOMEM, "out of memory");
  c->n_nodes = 1;
  if (charge(c, c->root, node_mem_self(c->root))) return c->err.code;
  self->kind = FR_SCENE;
  self->obj = c->root;
  return RSW_OK;
}

/* <shape type="..." [id="..."] [name="..."]>: a nested object, attached to
 * its parent under `name` (or "" when unnamed). */
static rsw_status start_object(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  static const char *const allowed[] = {"type", "id", "name", NULL};
  static const char *const required[] = {"type", NULL};
  if (attrs_check(c, allowed, required)) return c->err.code;
  const char *type = attr(c, "type"), *id = attr(c, "id"), *name = attr(c, "name");
  if (check_ident(c, "type", type)) return c->err.code;
  if (id && check_ident(c, "id", id)) return c->err.code;
  if (name && check_ident(c, "name", name)) return c->err.code;
  if (c->n_nodes >= RSW_MAX_NODES)
    return xfail(c, RSW_ERR_LIMIT, "more than %d objects in one document", RSW_MAX_NODES);
  prop *p = add_prop(c, parent->obj, name ? name : "", PROP_NODE);
  if (!p) return c->err.code;
  node *n = node_new(self->elem, type, c->loc);
  if (!n) return xfail(c, RSW_ERR_NOMEM, "out of memory");
  p->child = n; /* the tree owns n from here on */
  c->n_nodes++;
  if (id && !(n->id = rsw_strdup(id))) return xfail(c, RSW_ERR_NOMEM, "out of memory");
  if (charge(c, parent->obj, node_mem_self(n))) return c->err.code;
  if (id) {
    n->id_explicit = true;
    unsigned long first = 0;
    bool nomem;
    if (!ids_insert(&c->ids, n->id, c->line, &first, &nomem))
      return nomem ? xfail(c, RSW_ERR_NOMEM, "out of memory")
                   : xfail(c, RSW_ERR_DUPLICATE, "duplicate id \"%s\" (first used at %s:%lu)", id, c->file,
                           first);
  }
  self->kind = FR_OBJECT;
  self->obj = n;
  return RSW_OK;
}

/* Property groups of `molecular_atmosphere` (docs/atmosphere.md), which
 * Mitsuba's XML has no element for: <thermoprops>, <particle_layer> (each
 * one a property named particle_layers, in order) and <distribution
 * type="...">, holding ordinary properties. Their owner reads them as
 * groups; they are never built as plugins. */
static rsw_status start_group(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  static const char *const allowed[] = {"type", "name", NULL};
  bool dist = strcmp(self->elem, "distribution") == 0;
  static const char *const req_type[] = {"type", NULL};
  static const char *const req_none[] = {NULL};
  if (attrs_check(c, allowed, dist ? req_type : req_none)) return c->err.code;
  const char *type = attr(c, "type"), *name = attr(c, "name");
  const char *def_name = dist                                     ? "distribution"
                         : strcmp(self->elem, "thermoprops") == 0 ? "thermoprops"
                                                                  : "particle_layers";
  if (name && strcmp(name, def_name) != 0)
    return xfail(c, RSW_ERR_INVALID, "<%s> is the property '%s' (got name=\"%s\")", self->elem, def_name,
                 name);
  if (type && check_ident(c, "type", type)) return c->err.code;
  if (c->n_nodes >= RSW_MAX_NODES)
    return xfail(c, RSW_ERR_LIMIT, "more than %d objects in one document", RSW_MAX_NODES);
  /* particle layers repeat their name: added unnamed (no duplicate check), then named */
  bool repeat = strcmp(def_name, "particle_layers") == 0;
  prop *p = add_prop(c, parent->obj, repeat ? "" : def_name, PROP_NODE);
  if (!p) return c->err.code;
  if (repeat) {
    char *nm = rsw_strdup(def_name);
    if (!nm) return xfail(c, RSW_ERR_NOMEM, "out of memory");
    free(p->name);
    p->name = nm;
  }
  node *n = node_new(NULL, type ? type : dist ? "uniform" : self->elem, c->loc);
  if (!n) return xfail(c, RSW_ERR_NOMEM, "out of memory");
  p->child = n;
  c->n_nodes++;
  if (!(n->id = rsw_strdup(def_name))) return xfail(c, RSW_ERR_NOMEM, "out of memory");
  if (charge(c, parent->obj, node_mem_self(n))) return c->err.code;
  self->kind = FR_OBJECT;
  self->obj = n;
  return RSW_OK;
}

static const char *const name_value[] = {"name", "value", NULL};

/* Shared start of <integer>, <float>, <boolean>, <string>, <rgb>: checks
 * attributes and returns the new property, or NULL (error recorded). */
static prop *start_simple(xml_ctx *c, xml_frame *parent, prop_kind kind, const char **value) {
  if (attrs_check(c, name_value, name_value)) return NULL;
  const char *name = prop_name(c);
  if (!name) return NULL;
  *value = attr(c, "value");
  return add_prop(c, parent->obj, name, kind);
}

static rsw_status start_integer(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  const char *v;
  prop *p = start_simple(c, parent, PROP_NUMBER, &v);
  if (!p) return c->err.code;
  if (!parse_int(v, &p->num))
    return xfail(c, RSW_ERR_INVALID, "%s: could not parse integer \"%s\" (decimal digits, |value| <= 2^53)",
                 attr(c, "name"), v);
  p->is_int = true;
  return RSW_OK;
}

static rsw_status start_float(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  const char *v;
  prop *p = start_simple(c, parent, PROP_NUMBER, &v);
  if (!p) return c->err.code;
  if (!parse_double(v, &p->num))
    return xfail(c, RSW_ERR_INVALID, "%s: could not parse finite number \"%s\"", attr(c, "name"), v);
  return RSW_OK;
}

/* "true"/"false", any case (Mitsuba lower-cases the value first). */
static rsw_status start_boolean(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  const char *v;
  prop *p = start_simple(c, parent, PROP_BOOL, &v);
  if (!p) return c->err.code;
  if (strcasecmp(v, "true") == 0)
    p->b = true;
  else if (strcasecmp(v, "false") == 0)
    p->b = false;
  else
    return xfail(c, RSW_ERR_INVALID, "%s: boolean \"%s\" is not \"true\" or \"false\"", attr(c, "name"), v);
  return RSW_OK;
}

static rsw_status start_string(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  const char *v;
  prop *p = start_simple(c, parent, PROP_STRING, &v);
  if (!p) return c->err.code;
  if (charge(c, parent->obj, strlen(v) + 1)) return c->err.code;
  if (!(p->str = rsw_strdup(v))) return xfail(c, RSW_ERR_NOMEM, "out of memory");
  return RSW_OK;
}

/* value="r, g, b" or a single value used for all three (Mitsuba). */
static rsw_status start_rgb(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  const char *v;
  prop *p = start_simple(c, parent, PROP_SPECTRUM, &v);
  if (!p) return c->err.code;
  double rgb[3];
  size_t n;
  if (parse_numbers(c, "value", v, rgb, 3, &n)) return c->err.code;
  if (n == 1)
    rgb[1] = rgb[2] = rgb[0];
  else if (n != 3)
    return xfail(c, RSW_ERR_INVALID, "value \"%s\" must have 1 or 3 numbers", v);
  p->spec.kind = SPEC_RGB;
  memcpy(p->spec.rgb, rgb, sizeof rgb);
  return RSW_OK;
}

/* Append one wavelength:value pair, growing the owned arrays (counted
 * against the cap of `owner`'s document as they grow). */
static rsw_status spec_push(xml_ctx *c, const node *owner, spectrum *s, size_t *cap, double wl, double val) {
  if (s->n == RSW_MAX_SPECTRUM)
    return xfail(c, RSW_ERR_LIMIT, "more than %d spectrum samples", RSW_MAX_SPECTRUM);
  if (s->n == *cap) {
    size_t nc = *cap ? 2 * *cap : 16;
    if (charge(c, owner, 2 * (nc - *cap) * sizeof(double))) return c->err.code;
    double *wl_new = realloc(s->wl, nc * sizeof *wl_new);
    if (!wl_new) return xfail(c, RSW_ERR_NOMEM, "out of memory");
    s->wl = wl_new;
    double *val_new = realloc(s->val, nc * sizeof *val_new);
    if (!val_new) return xfail(c, RSW_ERR_NOMEM, "out of memory");
    s->val = val_new;
    *cap = nc;
  }
  s->wl[s->n] = wl;
  s->val[s->n++] = val;
  return RSW_OK;
}

/* value="0.5" -> uniform; value="400:0.1, 500:0.2, ..." -> tabulated
 * (wavelengths in nm, strictly increasing, at least two pairs);
 * filename= is not supported (scenes are self-contained). */
static rsw_status start_spectrum(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  static const char *const allowed[] = {"name", "value", "filename", NULL};
  if (attrs_check(c, allowed, NULL)) return c->err.code;
  const char *name = prop_name(c);
  if (!name) return c->err.code;
  const char *v = attr(c, "value");
  if (attr(c, "filename"))
    return xfail(c, RSW_ERR_UNSUPPORTED,
                 "spectra read from files (filename=) are unsupported; give value=\"wl:v, ...\"");
  if (!v) return xfail(c, RSW_ERR_MISSING, "missing attribute \"value\"");
  prop *p = add_prop(c, parent->obj, name, PROP_SPECTRUM);
  if (!p) return c->err.code;
  spectrum *s = &p->spec;
  if (!strchr(v, ':')) {
    size_t n;
    if (parse_numbers(c, "value", v, &s->value, 1, &n)) return c->err.code;
    if (n != 1) return xfail(c, RSW_ERR_INVALID, "value is empty");
    s->kind = SPEC_UNIFORM;
    return RSW_OK;
  }
  s->kind = SPEC_TABLE;
  const char *q = v;
  char tok[2 * XML_MAX_TOKEN];
  bool too_long;
  size_t cap = 0;
  while (next_token(&q, tok, sizeof tok, &too_long)) {
    if (too_long) return xfail(c, RSW_ERR_INVALID, "value: token \"%s...\" is too long", tok);
    char *colon = strchr(tok, ':');
    if (!colon) return xfail(c, RSW_ERR_INVALID, "\"%s\" is not a wavelength:value pair", tok);
    *colon = '\0';
    double wl, val;
    if (!parse_double(tok, &wl) || !parse_double(colon + 1, &val))
      return xfail(c, RSW_ERR_INVALID, "could not parse wavelength:value pair \"%s:%s\"", tok, colon + 1);
    if (!(wl > 0)) return xfail(c, RSW_ERR_INVALID, "wavelength %g nm is not positive", wl);
    if (s->n > 0 && !(wl > s->wl[s->n - 1]))
      return xfail(c, RSW_ERR_INVALID, "wavelengths must be strictly increasing (%g nm follows %g nm)", wl,
                   s->wl[s->n - 1]);
    if (spec_push(c, parent->obj, s, &cap, wl, val)) return c->err.code;
  }
  if (s->n < 2)
    return xfail(c, RSW_ERR_INVALID, "a tabulated spectrum needs at least two wavelength:value pairs");
  /* Trim to size, so that the tree holds (and node_mem_prop counts)
   * exactly n samples. */
  double *wl = realloc(s->wl, s->n * sizeof *wl);
  if (wl) s->wl = wl;
  double *val = realloc(s->val, s->n * sizeof *val);
  if (val) s->val = val;
  if (wl && val) c->bytes -= 2 * (cap - s->n) * sizeof(double);
  return RSW_OK;
}

/* x/y/z attributes (each defaulting to def) or value= with 1 number
 * (replicated) or 3; mixing both is an error (Mitsuba's
 * expand_value_to_xyz + parse_vector). */
static rsw_status read_xyz(xml_ctx *c, double def, vec3 *out) {
  const char *v = attr(c, "value");
  const char *xyz[3] = {attr(c, "x"), attr(c, "y"), attr(c, "z")};
  if (v) {
    if (xyz[0] || xyz[1] || xyz[2])
      return xfail(c, RSW_ERR_INVALID, "cannot mix \"value\" with \"x\"/\"y\"/\"z\"");
    double a[3];
    size_t n;
    if (parse_numbers(c, "value", v, a, 3, &n)) return c->err.code;
    if (n == 1)
      a[1] = a[2] = a[0];
    else if (n != 3)
      return xfail(c, RSW_ERR_INVALID, "value \"%s\" must have 1 or 3 numbers", v);
    *out = v3(a[0], a[1], a[2]);
    return RSW_OK;
  }
  double a[3] = {def, def, def};
  static const char *const names[3] = {"x", "y", "z"};
  for (int i = 0; i < 3; i++)
    if (xyz[i] && !parse_double(xyz[i], &a[i]))
      return xfail(c, RSW_ERR_INVALID, "%s: could not parse finite number \"%s\"", names[i], xyz[i]);
  *out = v3(a[0], a[1], a[2]);
  return RSW_OK;
}

/* <vector> and <point>: both become PROP_VEC3 (Mitsuba stores both as
 * array3f). */
static rsw_status start_vec3(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  static const char *const allowed[] = {"name", "value", "x", "y", "z", NULL};
  static const char *const required[] = {"name", NULL};
  if (attrs_check(c, allowed, required)) return c->err.code;
  const char *name = prop_name(c);
  if (!name) return c->err.code;
  vec3 v;
  if (read_xyz(c, 0.0, &v)) return c->err.code;
  prop *p = add_prop(c, parent->obj, name, PROP_VEC3);
  if (!p) return c->err.code;
  p->vec = v;
  return RSW_OK;
}

/* <ref id="..." [name="..."]/>: a reference resolved by the builder. */
static rsw_status start_ref(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  static const char *const allowed[] = {"id", "name", NULL};
  static const char *const required[] = {"id", NULL};
  if (attrs_check(c, allowed, required)) return c->err.code;
  const char *id = attr(c, "id"), *name = attr(c, "name");
  if (check_ident(c, "id", id)) return c->err.code;
  if (name && check_ident(c, "name", name)) return c->err.code;
  prop *p = add_prop(c, parent->obj, name ? name : "", PROP_REF);
  if (!p) return c->err.code;
  if (charge(c, parent->obj, strlen(id) + 1)) return c->err.code;
  if (!(p->ref = rsw_strdup(id))) return xfail(c, RSW_ERR_NOMEM, "out of memory");
  return RSW_OK;
}

/* <default name="x" value="y"/>: declares $x unless a -D define gives it. */
static rsw_status start_default(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  if (attrs_check(c, name_value, name_value)) return c->err.code;
  const char *name = attr(c, "name"), *value = attr(c, "value");
  if (!name[0]) return xfail(c, RSW_ERR_INVALID, "attribute \"name\" is empty");
  if (strlen(name) > RSW_MAX_NAME)
    return xfail(c, RSW_ERR_LIMIT, "name is longer than %d characters", RSW_MAX_NAME);
  param *old = param_find(c, name);
  if (old) {
    if (old->declared) return xfail(c, RSW_ERR_DUPLICATE, "parameter \"%s\" declared twice", name);
    old->declared = true; /* the define overrides this default */
    return RSW_OK;
  }
  param *p = param_add(c);
  if (!p)
    return c->n_params >= XML_MAX_PARAMS ? xfail(c, RSW_ERR_LIMIT, "more than %d parameters", XML_MAX_PARAMS)
                                         : xfail(c, RSW_ERR_NOMEM, "out of memory");
  p->own_name = rsw_strdup(name);
  p->own_value = rsw_strdup(value);
  p->name = p->own_name;
  p->value = p->own_value;
  p->declared = true;
  if (!p->own_name || !p->own_value) {
    /* keep the entry valid for lookups until cleanup */
    p->name = p->own_name ? p->own_name : "";
    p->value = "";
    return xfail(c, RSW_ERR_NOMEM, "out of memory");
  }
  return RSW_OK;
}

static rsw_status start_transform(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  static const char *const allowed[] = {"name", NULL};
  if (attrs_check(c, allowed, allowed)) return c->err.code;
  const char *name = prop_name(c);
  if (!name) return c->err.code;
  prop *p = add_prop(c, parent->obj, name, PROP_TRANSFORM);
  if (!p) return c->err.code;
  p->xf = xf_identity();
  self->kind = FR_TRANSFORM;
  self->owner = parent->obj;
  self->prop_index = parent->obj->n_props - 1;
  self->acc = xf_identity();
  return RSW_OK;
}

/* Left-multiply op onto the transform being built: acc = op * acc, so ops
 * apply to points in document order (Mitsuba: transform = op * transform). */
static rsw_status apply_op(xml_ctx *c, xml_frame *tf, const xform *op) {
  xform r = xf_mul(op, &tf->acc);
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++)
      if (!isfinite(r.m[i][j]) || !isfinite(r.inv[i][j]))
        return xfail(c, RSW_ERR_INVALID, "the accumulated transform is not finite");
  tf->acc = r;
  return RSW_OK;
}

static const char *const xyz_value[] = {"value", "x", "y", "z", NULL};

static rsw_status start_translate(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  if (attrs_check(c, xyz_value, NULL)) return c->err.code;
  vec3 t;
  if (read_xyz(c, 0.0, &t)) return c->err.code;
  xform op = xf_translate(t);
  return apply_op(c, parent, &op);
}

/* Axis from x/y/z or value=, angle in degrees, counter-clockwise. */
static rsw_status start_rotate(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  static const char *const allowed[] = {"value", "x", "y", "z", "angle", NULL};
  static const char *const required[] = {"angle", NULL};
  if (attrs_check(c, allowed, required)) return c->err.code;
  vec3 axis;
  double angle;
  if (read_xyz(c, 0.0, &axis)) return c->err.code;
  if (!parse_double(attr(c, "angle"), &angle))
    return xfail(c, RSW_ERR_INVALID, "angle: could not parse finite number \"%s\"", attr(c, "angle"));
  if (!(v3_len(axis) > 0) || !isfinite(v3_len(axis)))
    return xfail(c, RSW_ERR_INVALID, "rotation axis is zero or not finite");
  xform op = xf_rotate(axis, angle);
  return apply_op(c, parent, &op);
}

/* value= uniform or 3 factors, or x/y/z each defaulting to 1. */
static rsw_status start_scale(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  if (attrs_check(c, xyz_value, NULL)) return c->err.code;
  vec3 s;
  if (read_xyz(c, 1.0, &s)) return c->err.code;
  if (s.x == 0 || s.y == 0 || s.z == 0)
    return xfail(c, RSW_ERR_INVALID, "scale factor 0 makes the transform singular");
  xform op = xf_scale(s);
  return apply_op(c, parent, &op);
}

/* 16 numbers (row-major 4x4) or 9 (row-major 3x3 -> upper-left block of a
 * 4x4 whose last row and column are those of the identity, as Mitsuba). */
static rsw_status start_matrix(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  static const char *const allowed[] = {"value", NULL};
  if (attrs_check(c, allowed, allowed)) return c->err.code;
  double a[16];
  size_t n;
  if (parse_numbers(c, "value", attr(c, "value"), a, 16, &n)) return c->err.code;
  double m[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};
  if (n == 16) {
    for (int i = 0; i < 4; i++)
      for (int j = 0; j < 4; j++) m[i][j] = a[4 * i + j];
  } else if (n == 9) {
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) m[i][j] = a[3 * i + j];
  } else {
    return xfail(c, RSW_ERR_INVALID, "matrix needs 16 or 9 numbers, got %zu", n);
  }
  xform op;
  if (!xf_from_matrix(m, &op)) return xfail(c, RSW_ERR_INVALID, "matrix is singular");
  return apply_op(c, parent, &op);
}

/* An attribute holding exactly three numbers ("x, y, z"). */
static rsw_status named_vec3(xml_ctx *c, const char *name, vec3 *out) {
  double a[3];
  size_t n;
  const char *v = attr(c, name);
  if (parse_numbers(c, name, v, a, 3, &n)) return c->err.code;
  if (n != 3) return xfail(c, RSW_ERR_INVALID, "%s=\"%s\" must have 3 numbers", name, v);
  *out = v3(a[0], a[1], a[2]);
  return RSW_OK;
}

/* origin, target, optional up. Without up (or with up = 0) Mitsuba takes
 * the first vector of coordinate_system(normalize(target - origin)). */
static rsw_status start_lookat(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  static const char *const allowed[] = {"origin", "target", "up", NULL};
  static const char *const required[] = {"origin", "target", NULL};
  if (attrs_check(c, allowed, required)) return c->err.code;
  vec3 origin, target, up = v3(0, 0, 0);
  if (named_vec3(c, "origin", &origin) || named_vec3(c, "target", &target)) return c->err.code;
  if (attr(c, "up") && named_vec3(c, "up", &up)) return c->err.code;
  vec3 dir = v3_sub(target, origin);
  if (!(v3_len(dir) > 0) || !v3_finite(dir)) return xfail(c, RSW_ERR_INVALID, "origin and target coincide");
  if (v3_len2(up) == 0) {
    vec3 second;
    coordinate_system(v3_norm(dir), &up, &second);
  }
  xform op;
  if (!xf_look_at(origin, target, up, &op))
    return xfail(c, RSW_ERR_INVALID, "up is parallel to the viewing direction");
  return apply_op(c, parent, &op);
}

static rsw_status start_unsupported(xml_ctx *c, xml_frame *parent, xml_frame *self) {
  return xfail(c, RSW_ERR_UNSUPPORTED,
               "this element is not supported (scenes must be "
               "self-contained, without includes or aliases)");
}

static const tag_def tag_table[] = {
    {"scene", IN_ROOT, start_scene},
    {"sensor", IN_OBJECT, start_object},
    {"film", IN_OBJECT, start_object},
    {"sampler", IN_OBJECT, start_object},
    {"rfilter", IN_OBJECT, start_object},
    {"integrator", IN_OBJECT, start_object},
    {"emitter", IN_OBJECT, start_object},
    {"shape", IN_OBJECT, start_object},
    {"bsdf", IN_OBJECT, start_object},
    {"texture", IN_OBJECT, start_object},
    {"medium", IN_OBJECT, start_object},
    {"phase", IN_OBJECT, start_object},
    {"volume", IN_OBJECT, start_object},
    {"extremum", IN_OBJECT, start_object},
    {"thermoprops", IN_OBJECT, start_group},
    {"particle_layer", IN_OBJECT, start_group},
    {"distribution", IN_OBJECT, start_group},
    {"integer", IN_OBJECT, start_integer},
    {"float", IN_OBJECT, start_float},
    {"boolean", IN_OBJECT, start_boolean},
    {"string", IN_OBJECT, start_string},
    {"rgb", IN_OBJECT, start_rgb},
    {"spectrum", IN_OBJECT, start_spectrum},
    {"vector", IN_OBJECT, start_vec3},
    {"point", IN_OBJECT, start_vec3},
    {"ref", IN_OBJECT, start_ref},
    {"transform", IN_OBJECT, start_transform},
    {"default", IN_SCENE, start_default},
    {"translate", IN_TRANSFORM, start_translate},
    {"rotate", IN_TRANSFORM, start_rotate},
    {"scale", IN_TRANSFORM, start_scale},
    {"matrix", IN_TRANSFORM, start_matrix},
    {"lookat", IN_TRANSFORM, start_lookat},
    {"include", IN_OBJECT, start_unsupported},
    {"alias", IN_OBJECT, start_unsupported},
    {"path", IN_OBJECT, start_unsupported},
};

static const tag_def *find_tag(const char *name) {
  for (size_t i = 0; i < sizeof tag_table / sizeof tag_table[0]; i++)
    if (strcmp(tag_table[i].name, name) == 0) return &tag_table[i];
  return NULL;
}

/* Is an element placed as `t` allowed under `parent` (NULL: the root)? */
static rsw_status check_placement(xml_ctx *c, const tag_def *t, const xml_frame *parent) {
  if (!parent)
    return t->place == IN_ROOT ? RSW_OK : xfail(c, RSW_ERR_PARSE, "the root element must be <scene>");
  if (t->place == IN_ROOT) return xfail(c, RSW_ERR_PARSE, "<scene> can only be the root element");
  if (parent->kind == FR_LEAF)
    return xfail(c, RSW_ERR_PARSE, "cannot occur inside <%s> (it takes no child elements)", parent->elem);
  if (parent->kind == FR_TRANSFORM && t->place != IN_TRANSFORM)
    return xfail(c, RSW_ERR_PARSE, "<transform> can only contain translate, rotate, scale, matrix, lookat");
  if (t->place == IN_TRANSFORM && parent->kind != FR_TRANSFORM)
    return xfail(c, RSW_ERR_PARSE, "transform operations can only occur inside <transform>");
  if (t->place == IN_SCENE && parent->kind != FR_SCENE)
    return xfail(c, RSW_ERR_PARSE, "can only occur directly inside <scene>");
  return RSW_OK;
}

/* ---- expat callbacks -------------------------------------------------------- */

static void XMLCALL on_start(void *ud, const XML_Char *name, const XML_Char **atts) {
  xml_ctx *c = ud;
  if (c->failed) return;
  set_loc(c, (unsigned long)XML_GetCurrentLineNumber(c->parser));
  c->elem = name;
  if (c->depth >= RSW_MAX_DEPTH) {
    xfail(c, RSW_ERR_LIMIT, "elements nested deeper than %d", RSW_MAX_DEPTH);
    return;
  }
  const tag_def *t = find_tag(name);
  if (!t) {
    xfail(c, RSW_ERR_PARSE, "unknown element");
    return;
  }
  c->elem = t->name;
  xml_frame *parent = c->depth ? &c->stack[c->depth - 1] : NULL;
  if (check_placement(c, t, parent)) return;
  xml_frame f;
  memset(&f, 0, sizeof f);
  f.kind = FR_LEAF;
  f.elem = t->name;
  rsw_status st = attrs_load(c, atts);
  if (!st) st = t->start(c, parent, &f);
  attrs_clear(c);
  if (st) return;
  c->stack[c->depth++] = f;
}

static void XMLCALL on_end(void *ud, const XML_Char *name) {
  xml_ctx *c = ud;
  if (c->failed || c->depth == 0) return;
  xml_frame *f = &c->stack[--c->depth];
  if (f->kind == FR_TRANSFORM) f->owner->props[f->prop_index].xf = f->acc;
}

/* Mitsuba scenes carry no text content; anything but whitespace is a
 * mistake (often a stray character or an unescaped '<'). */
static void XMLCALL on_text(void *ud, const XML_Char *s, int len) {
  xml_ctx *c = ud;
  if (c->failed) return;
  for (int i = 0; i < len; i++)
    if (!isspace((unsigned char)s[i])) {
      set_loc(c, (unsigned long)XML_GetCurrentLineNumber(c->parser));
      c->elem = c->depth ? c->stack[c->depth - 1].elem : NULL;
      xfail(c, RSW_ERR_PARSE, "unexpected text \"%.*s\"", len - i > 32 ? 32 : len - i, s + i);
      return;
    }
}

/* DTDs can declare entities (and with them expansion bombs); Mitsuba scenes
 * never need one. */
static void XMLCALL on_doctype(void *ud, const XML_Char *name, const XML_Char *sysid, const XML_Char *pubid,
                               int has_internal_subset) {
  xml_ctx *c = ud;
  if (c->failed) return;
  set_loc(c, (unsigned long)XML_GetCurrentLineNumber(c->parser));
  c->elem = NULL;
  xfail(c, RSW_ERR_UNSUPPORTED, "DOCTYPE declarations are not supported");
}

/* ---- entry point ------------------------------------------------------------- */

static void ctx_release(xml_ctx *c) {
  attrs_clear(c);
  for (size_t i = 0; i < c->n_params; i++) {
    free(c->params[i].own_name);
    free(c->params[i].own_value);
  }
  free(c->params);
  free(c->ids.slots);
  if (c->parser) XML_ParserFree(c->parser);
}

static rsw_status load_defines(xml_ctx *c, const scene_define *defines, size_t n_defines) {
  if (n_defines && !defines) return rsw_fail(&c->err, RSW_ERR_USAGE, "-D", "defines missing");
  for (size_t i = 0; i < n_defines; i++) {
    const scene_define *d = &defines[i];
    if (!d->name || !d->name[0] || !d->value)
      return rsw_fail(&c->err, RSW_ERR_USAGE, "-D", "define %zu has no name or value", i);
    if (strlen(d->name) > RSW_MAX_NAME)
      return rsw_fail(&c->err, RSW_ERR_USAGE, "-D", "define name longer than %d characters", RSW_MAX_NAME);
    if (param_find(c, d->name))
      return rsw_fail(&c->err, RSW_ERR_USAGE, "-D", "parameter \"%s\" defined twice", d->name);
    param *p = param_add(c);
    if (!p)
      return rsw_fail(&c->err, c->n_params >= XML_MAX_PARAMS ? RSW_ERR_LIMIT : RSW_ERR_NOMEM, "-D",
                      "cannot store %zu defines", n_defines);
    p->name = d->name;
    p->value = d->value;
    p->from_define = true;
  }
  return RSW_OK;
}

/* A define that no <default> declares and no $name used: an error naming
 * it, with the parameters the document declares and the closest of them. */
static rsw_status unused_define(xml_ctx *c) {
  for (size_t i = 0; i < c->n_params; i++) {
    const param *d = &c->params[i];
    if (!d->from_define || d->declared || d->used) continue;
    char names[512] = "";
    size_t at = 0, best_dist = (size_t)-1;
    const char *best = NULL;
    for (size_t j = 0; j < c->n_params; j++) {
      const param *q = &c->params[j];
      if (!q->declared) continue;
      if (at < sizeof names)
        at += (size_t)snprintf(names + at, sizeof names - at, "%s%s", at ? ", " : "", q->name);
      size_t dist = rsw_edit_distance(d->name, q->name);
      if (dist < best_dist) best_dist = dist, best = q->name;
    }
    char where[RSW_MAX_NAME + 8];
    snprintf(where, sizeof where, "-D %s", d->name);
    if (best && best_dist <= 2)
      return rsw_fail(&c->err, RSW_ERR_UNKNOWN_NAME, where,
                      "the document neither declares nor uses a parameter \"%s\"; did you mean \"%s\"? (it "
                      "declares: %s)",
                      d->name, best, names);
    return rsw_fail(&c->err, RSW_ERR_UNKNOWN_NAME, where,
                    "the document neither declares nor uses a parameter \"%s\" (%s%s)", d->name,
                    names[0] ? "it declares: " : "it declares none", names);
  }
  return RSW_OK;
}

/* Location prefix: the source name, cut from the left so that "name:line"
 * always fits in rsw_err.where. */
static const char *short_name(const char *source_name) {
  const char *s = source_name && source_name[0] ? source_name : "<xml>";
  size_t n = strlen(s);
  return n > 200 ? s + (n - 200) : s;
}

rsw_status scene_read_xml(const char *text, size_t len, const char *source_name, const scene_define *defines,
                          size_t n_defines, node **root_out, char **variant_out, rsw_err *err) {
  return scene_read_xml_limited(text, len, source_name, defines, n_defines, NULL, root_out, variant_out, err);
}

rsw_status scene_read_xml_limited(const char *text, size_t len, const char *source_name,
                                  const scene_define *defines, size_t n_defines, const scene_limits *lim,
                                  node **root_out, char **variant_out, rsw_err *err) {
  xml_ctx c;
  memset(&c, 0, sizeof c);
  c.lim = lim ? lim : &scene_limits_default;
  c.file = short_name(source_name);
  set_loc(&c, 1);
  rsw_status st = RSW_OK;

  if (len > XML_MAX_DOC) {
    rsw_fail(&c.err, RSW_ERR_LIMIT, c.loc, "XML document of %zu bytes exceeds the %zu-byte limit", len,
             XML_MAX_DOC);
    goto done;
  }
  if (!text) len = 0;
  if (load_defines(&c, defines, n_defines)) goto done;

  c.parser = XML_ParserCreate(NULL);
  if (!c.parser) {
    rsw_fail(&c.err, RSW_ERR_NOMEM, c.loc, "out of memory creating the XML parser");
    goto done;
  }
  XML_SetUserData(c.parser, &c);
  XML_SetElementHandler(c.parser, on_start, on_end);
  XML_SetCharacterDataHandler(c.parser, on_text);
  XML_SetStartDoctypeDeclHandler(c.parser, on_doctype);
  if (XML_Parse(c.parser, text ? text : "", (int)len, XML_TRUE) == XML_STATUS_ERROR && !c.failed) {
    enum XML_Error code = XML_GetErrorCode(c.parser);
    set_loc(&c, (unsigned long)XML_GetCurrentLineNumber(c.parser));
    rsw_fail(&c.err, code == XML_ERROR_NO_MEMORY ? RSW_ERR_NOMEM : RSW_ERR_PARSE, c.loc,
             "malformed XML: %s (column %lu)", XML_ErrorString(code),
             (unsigned long)XML_GetCurrentColumnNumber(c.parser) + 1);
    goto done;
  }
  if (c.failed) goto done;
  if (!c.root) { /* expat guarantees a root element; be defensive */
    rsw_fail(&c.err, RSW_ERR_PARSE, c.loc, "no <scene> element");
    goto done;
  }
  if (unused_define(&c)) goto done;
  node_assign_ids(c.root, &c.err);

done:
  st = c.err.code;
  if (st == RSW_OK) {
    *root_out = c.root;
    if (variant_out)
      *variant_out = c.variant;
    else
      free(c.variant);
    c.root = NULL;
    c.variant = NULL;
  } else if (err) {
    rsw_err_clear(err);
    rsw_fail(err, st, c.err.where, "%s", c.err.msg);
  }
  node_free(c.root);
  free(c.variant);
  ctx_release(&c);
  return st;
}
