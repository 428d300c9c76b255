/* Parameter-map templates (Eradiate's KernelSceneParameterMap, see
 * docs/experiments.md "Templates"): parameter keys mapped to functions of
 * a kernel context's coordinates, rendered for each context into the
 * {key: value} overrides that context is rendered with, exactly as if the
 * client had sent them as the context's `params`.
 *
 * Forms (the value of templates[KEY]; a coordinate operand is a
 * coordinate's name, a constant operand a number):
 *   {"value": V}                                  V itself (any override value)
 *   {"coord": NAME}                               the coordinate's value
 *   {"coord": NAME, "x": [...], "y": [...]}       linear interpolation over the
 *        coordinate; x strictly increasing; y numbers, or arrays of one
 *        length (vectors, per-layer profiles); outside [x0, xn]: refused
 *   {"sun": {"zenith": Z, "azimuth": A}}          a directional emitter's
 *        `direction`: -(sin z cos a, sin z sin a, cos z), degrees, zenith
 *        from +z, azimuth from +x counter-clockwise (Eradiate's convention)
 *   {"view": {"zenith": Z, "azimuth": A}}         a distant sensor's
 *        `direction` (where it looks: the same vector)
 *   {"view": {"construct": "hplane", "zeniths": [Z...], "azimuth": A}}
 *   {"view": {"construct": "from_angles", "angles": [[Z, A], ...]}}
 *        an mdistant's `directions` (3 N numbers), Eradiate's
 *        MultiDistantMeasure constructors; hplane zeniths are signed (a
 *        negative zenith looks from azimuth + 180).
 * The coordinate `wavelength` is the context's wavelength (nm).
 *
 * Rendering is cheap (microseconds per context: a few interpolations and
 * the cJSON values they make); it allocates only the values it adds. */
#ifndef RSW_SERVICE_TEMPLATES_H
#define RSW_SERVICE_TEMPLATES_H

#include <stdbool.h>
#include <stddef.h>

#include <cjson/cJSON.h>

#include "../kernel/scene/scene.h"
#include "service.h"

typedef struct tmpl_set tmpl_set;

/* Compile the templates of a scene (scene_tmpl: the document's top-level
 * "templates", may be NULL) and of a job (job_tmpl: the body's
 * "templates", may be NULL; a key of the job's replaces the scene's for
 * the same parameter). Every form is checked and every key looked up in
 * sc (an unknown key is RSW_ERR_UNKNOWN_NAME with the closest keys in e).
 * job_params (the job's own "params", may be NULL): a key there also
 * templated by the job is refused (RSW_ERR_DUPLICATE); one templated by the
 * scene only is dropped (explicit values win). Errors point at
 * "<scene_ptr>/KEY..." (scene_ptr: e.g. "scene.json#/templates") or
 * "/templates/KEY...". *out is NULL when neither has a template; owned,
 * tmpl_free. Reads sc's parameter table only (fixed at load). */
rsw_status tmpl_compile(const scene *sc, const cJSON *scene_tmpl, const char *scene_ptr,
                        const cJSON *job_tmpl, const cJSON *job_params, tmpl_set **out, svc_error *e);
void tmpl_free(tmpl_set *t);
/* Whether some template reads the coordinate called name. */
bool tmpl_uses_coord(const tmpl_set *t, const char *name);

/* Render every template for one context into out (a JSON object holding
 * the context's explicit overrides, job-level under context-level): a
 * template whose parameter out already names (by any key of it) is
 * skipped, the others add {key: value}. coords: the context's "coords"
 * object (may be NULL); wavelength: the context's wavelength in nm, the
 * value of the coordinate `wavelength` (NaN or <= 0: none). ctx_ptr names
 * the context in errors ("/contexts/3"): a coordinate missing, not a
 * number, not finite or outside a table's x range is an error at
 * "<ctx_ptr>/coords/NAME"; an out-of-range angle at "/templates/KEY".
 * Thread-safe for one t (t is only read). Works for any (coords,
 * wavelength) pair, e.g. each wavelength node of a band. */
rsw_status tmpl_render(const tmpl_set *t, const scene *sc, const cJSON *coords, double wavelength, cJSON *out,
                       const char *ctx_ptr, svc_error *e);
/* Whether key (as written in out by tmpl_render) came from a template of
 * t, and which pointer names it ("/templates/KEY", or the scene's). */
bool tmpl_origin(const tmpl_set *t, const char *key, char *ptr, size_t cap);
/* An error about a rendered value (e->key): when a template of t made it,
 * e points at that template, its message prefixed "rendered for CTX: ",
 * and true. */
bool tmpl_blame(const tmpl_set *t, const char *ctx, svc_error *e);

/* The coordinate `wavelength` (cw) sets the context's wavelength: a
 * positive finite number of nm, in a mono scene, equal to the context's
 * "wavelength" (w, may be NULL) when both are given; errors at
 * "<ptr>/coords/wavelength". */
rsw_status tmpl_check_coord_wavelength(const scene *sc, const cJSON *w, const cJSON *cw, const char *ptr,
                                       svc_error *e);

/* ---- the silent no-op sweep -------------------------------------------------------- */

/* One context as the warning check sees it: its coords (may be NULL), its
 * wavelength (nm; <= 0 none) and a digest of everything else it renders
 * with besides the seed it did not choose (overrides after templates,
 * sensors, spp, an explicit seed). */
typedef struct tmpl_ctx_sig {
  const cJSON *coords;
  double wavelength;
  unsigned char digest[32];
} tmpl_ctx_sig;

/* The job's warnings (a JSON array, owned; NULL when none or out of
 * memory): {"code": "coordinate_unused", "coordinate": NAME, "detail"}
 * when the contexts differ in a coordinate but, among contexts equal in
 * every other coordinate, never in what they render; {"code":
 * "wavelength_unused", "coordinate": "wavelength", ...} when they differ in
 * wavelength and nothing depends on it (spectral: whether the scene, its
 * overrides or a template depends on the wavelength; the digests include
 * the wavelength only when it does). */
cJSON *tmpl_sweep_warnings(const tmpl_ctx_sig *ctx, size_t n, bool spectral);
/* A context's digest (tmpl_ctx_sig): params (its overrides, or the part
 * that differs between contexts), the wavelength when spectral, and the
 * context's (ctx) spp, explicit seed and sensors (d_sensors: the job's
 * default sensors). */
void tmpl_ctx_digest(const cJSON *params, double wl, bool spectral, const cJSON *ctx, const cJSON *d_sensors,
                     unsigned char out[32]);

#endif
