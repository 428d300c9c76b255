/* The unknown-plugin-type error (plugin_names.c). */
#ifndef RSW_SCENE_PLUGIN_NAMES_H
#define RSW_SCENE_PLUGIN_NAMES_H

#include "../kernel.h"

/* Records "unknown plugin type 'T' (did you mean 'U'?); known C plugins:
 * ..." at `where` and returns RSW_ERR_UNKNOWN_PLUGIN. tag: the XML element
 * name, or NULL for JSON (the class then comes from the last segment of
 * `where`, a JSON pointer, or from the closest name). */
rsw_status registry_unknown_type(rsw_err *err, const char *where, const char *type, const char *tag);

#endif
