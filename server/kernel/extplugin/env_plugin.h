/* Environment plugins: shared objects written against
 * include/raysweep/plugin.h, loaded once at daemon start
 * (`raysweepd render|serve --plugin-dir DIR`) and registered as emitter
 * types next to the built-in ones (registry_find() falls back to
 * plugins_find()).
 *
 * The loaded set is process-wide: it is written only by plugins_load_dir()
 * and plugins_unload(), which run before any render thread exists (at
 * start and at exit), and is read-only in between. That is the one piece
 * of global state here, forced by the registry being global. */
#ifndef RSW_PLUGINS_ENV_PLUGIN_H
#define RSW_PLUGINS_ENV_PLUGIN_H

#include "../kernel.h"

/* dlopen every `*.so` in dir (sorted by name, RTLD_NOW | RTLD_LOCAL), call
 * its entry and check it: entry symbol present, table non-NULL,
 * abi_version == RSW_PLUGIN_ABI_VERSION, type name [a-z][a-z0-9_]* not
 * clashing with a built-in type or an already loaded plugin, parameter
 * descriptions well formed, required callbacks present. Any failure
 * unloads what this call loaded and returns an error naming the file.
 * Not thread-safe: call before rendering starts. */
rsw_status plugins_load_dir(const char *dir, rsw_err *err);

/* The daemon's variant: load each plugin of dir independently; one that
 * fails is refused (report is called with its error, naming the file) and
 * the others still load, so a bad plugin never stops the service. Returns
 * the number refused, or (size_t)-1 when dir cannot be read (err set). */
size_t plugins_load_dir_lenient(const char *dir, void (*report)(void *user, const rsw_err *e), void *user,
                                rsw_err *err);

/* dlclose every loaded plugin (call at exit, after every scene that uses
 * one has been freed). */
void plugins_unload(void);

/* The registry record of a loaded plugin type, or NULL. */
const plugin *plugins_find(const char *name);
/* Number of loaded plugin types, and the i-th one's record and pretty
 * name / file (for listings such as GET /v1). */
size_t plugins_count(void);
const plugin *plugins_at(size_t i, const char **pretty_name, const char **file);

#endif
