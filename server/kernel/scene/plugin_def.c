/* The plugin record boilerplate's functions (plugin_def.h): below the
 * plugins, which call them. */
#include "plugin_def.h"

#include <stdlib.h>

void plugin_free_object(object *o) {
  free(o);
}

bool plugin_pages_any(const object *o) {
  (void)o;
  return true;
}

void *plugin_object_new(size_t size, const plugin *p) {
  object *o = calloc(1, size);
  if (o) o->plugin = p;
  return o;
}

bsdf *bsdf_object_new(size_t size, const plugin *p, unsigned flags) {
  bsdf *b = plugin_object_new(size, p);
  if (!b) return NULL;
  b->ops = p->ops;
  b->flags = flags;
  return b;
}

rsw_status plugin_created(loader *ld, node *n, object *o, object **out) {
  if (!o) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "%s: out of memory", n->type);
  o->id = n->id;
  *out = o;
  return RSW_OK;
}
