/* The error for an unknown plugin type: the closest known name ("did you
 * mean") and the known plugins of the class the document asked for.
 * The class comes from the XML tag (<bsdf type=...>), else from the JSON
 * slot the object sits in (".../bsdf", ".../interior"), else from the
 * closest name; without any, every known plugin is listed. */
#include <stdio.h>
#include <string.h>

#include "../core/strdist.h"
#include "loader.h"
#include "plugin_names.h"

/* A JSON slot that names a class: the class's own name, or a medium's
 * interior / exterior. CLS__COUNT when none. */
static obj_class slot_class(const char *loc) {
  const char *s = loc ? strrchr(loc, '/') : NULL;
  if (!s) return CLS__COUNT;
  s++;
  if (strcmp(s, "interior") == 0 || strcmp(s, "exterior") == 0) return CLS_MEDIUM;
  for (int c = 0; c < CLS__COUNT; c++)
    if (c != CLS_SCENE && strcmp(s, obj_class_name((obj_class)c)) == 0) return (obj_class)c;
  return CLS__COUNT;
}

static obj_class tag_class(const char *tag) {
  for (int c = 0; tag && c < CLS__COUNT; c++)
    if (strcmp(tag, obj_class_name((obj_class)c)) == 0) return (obj_class)c;
  return CLS__COUNT;
}

/* The scene root is not a plugin a document names (`periodic`, also of
 * the scene class, is). */
static bool listed(const plugin *p, obj_class cls) {
  return strcmp(p->name, "scene") != 0 && (cls == CLS__COUNT || p->cls == cls);
}

static const plugin *closest(const char *type, obj_class cls) {
  const plugin *best = NULL;
  size_t best_d = 3; /* at most two edits away */
  for (size_t i = 0; rsw_plugins[i]; i++) {
    if (!listed(rsw_plugins[i], cls)) continue;
    size_t d = rsw_edit_distance(type, rsw_plugins[i]->name);
    if (d < best_d) best_d = d, best = rsw_plugins[i];
  }
  return best;
}

rsw_status registry_unknown_type(rsw_err *err, const char *where, const char *type, const char *tag) {
  obj_class cls = tag ? tag_class(tag) : slot_class(where);
  const plugin *best = closest(type, cls);
  if (!best && cls != CLS__COUNT && !tag) best = closest(type, CLS__COUNT);
  if (cls == CLS__COUNT && best) cls = best->cls;
  char known[600];
  size_t k = 0;
  known[0] = '\0';
  for (size_t i = 0; rsw_plugins[i] && k < sizeof known; i++) {
    if (!listed(rsw_plugins[i], cls)) continue;
    k += (size_t)snprintf(known + k, sizeof known - k, "%s%s", k ? ", " : "", rsw_plugins[i]->name);
  }
  char mean[300];
  if (best)
    snprintf(mean, sizeof mean, " (did you mean '%s'?)", best->name);
  else
    mean[0] = '\0';
  return rsw_fail(err, RSW_ERR_UNKNOWN_PLUGIN, where, "unknown plugin type '%s'%s; known %s%splugins: %s",
                  type, mean, cls == CLS__COUNT ? "" : obj_class_name(cls), cls == CLS__COUNT ? "" : " ",
                  known);
}
