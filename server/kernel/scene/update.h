/* Parameter updates (params.h): values as parsed from JSON and atomic
 * updates of a scene's entries. */
#ifndef RSW_SCENE_UPDATE_H
#define RSW_SCENE_UPDATE_H

#include "params.h"

/* ---- values ----------------------------------------------------------------- */

/* A value given for an update, as parsed from JSON (see param_value_parse). */
typedef enum param_value_kind {
  PV_NUMBER, /* 0.3 */
  PV_BOOL,   /* true */
  PV_ARRAY,  /* [0.1, 0.2, 0.3], [16 numbers], [[4 rows of 4]] (flattened) */
  PV_TABLE,  /* {"wavelengths": [...], "values": [...]} or
                 {"type": "spectrum", "value": [[wl, v], ...]} */
} param_value_kind;

typedef struct param_value {
  param_value_kind kind;
  double num;
  bool b;
  double *arr; /* PV_ARRAY: n numbers (owned) */
  size_t n;
  size_t rows;    /* PV_ARRAY given as nested rows: number of rows, else 0 */
  spectrum table; /* PV_TABLE (owned) */
} param_value;

/* Parse a JSON text ("0.3", "[0.1,0.2,0.3]", a 16-number matrix, a
 * tabulated spectrum object). `where` names the input in errors. */
rsw_status param_value_parse(const char *json, const char *where, param_value *out, rsw_err *err);
/* The same from a parsed JSON value (a request body's member): no text in
 * between, so the value is the wire's double exactly. */
struct cJSON;
rsw_status param_value_from_json(const struct cJSON *j, const char *where, param_value *out, rsw_err *err);
void param_value_free(param_value *v);

/* ---- updates -------------------------------------------------------------------- */

typedef struct param_update {
  const char *key; /* key, alias or TYPE:ID:PATH */
  param_value value;
} param_update;

typedef struct update_report {
  unsigned classes;                            /* UPDATE_* bits of the entries that changed */
  size_t changed;                              /* entries whose value changed (equal values are
                         no-ops) */
  double seconds;                              /* wall time of the whole update */
  unsigned refits, rebuilds, instance_updates; /* acceleration work done */
} update_report;

/* Validate every entry of the map (key exists, writable, type and shape,
 * legal value); if any fails, change nothing and return its error naming
 * the key. Otherwise apply all, refresh derived state (frames, areas,
 * emitter distributions, bounding sphere, sensor offsets, Embree) and fill
 * *report (may be NULL). Not thread-safe with renders of the same scene. */
rsw_status scene_update(scene *s, const param_update *items, size_t n, update_report *report, rsw_err *err);

/* The checks of scene_update without applying anything: every key
 * resolves (no key twice), is writable, and its value has the right type,
 * shape and range for the scene as it is. (The mesh-area check that needs
 * the new vertices together is left to scene_update.) For validating
 * overrides before they are used, e.g. every context of a job at submit.
 * Only reads the scene. */
rsw_status scene_update_check(const scene *s, const param_update *items, size_t n, rsw_err *err);

#endif
