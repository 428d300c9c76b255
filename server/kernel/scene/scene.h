/* Loading, finalising and freeing a scene. */
#ifndef RSW_SCENE_SCENE_H
#define RSW_SCENE_SCENE_H

#include "../kernel.h"
#include "node.h"

typedef struct scene_load_opts {
  size_t size;                 /* sizeof(scene_load_opts): lets it grow */
  const char *variant;         /* "mono"/"rgb" overriding the document's, or NULL */
  const scene_define *defines; /* XML -D overrides */
  size_t n_defines;
  const char *base_dir; /* where relative file names resolve; NULL: "." */
  /* Optional: resolve a file name written in the scene (a mesh, a bitmap)
   * to a readable path (malloc'ed into *path_out), or fail naming it. The
   * daemon confines names to its data root and maps "sha256:<hex>" to its
   * blob store. NULL: relative to base_dir, any path allowed. */
  rsw_status (*resolve)(void *user, const char *name, char **path_out, rsw_err *err);
  void *resolve_user;
} scene_load_opts;

/* Build a scene from a document tree. Takes ownership of root (freed on
 * failure too). doc_variant is the variant the document declared (or NULL);
 * opts->variant overrides it; default rgb. */
rsw_status scene_build(node *root, const char *doc_variant, const scene_load_opts *opts, scene **out,
                       rsw_err *err);

/* Read a JSON or XML file (by extension; .xml is XML, anything else is
 * sniffed: a leading '<' means XML) and build it. */
rsw_status scene_load_file(const char *path, const scene_load_opts *opts, scene **out, rsw_err *err);
/* Same from memory; `name` is used in error locations. */
rsw_status scene_load_memory(const char *text, size_t len, const char *name, bool is_xml,
                             const scene_load_opts *opts, scene **out, rsw_err *err);

/* The scene plugin's create() (scene/scene.c): builds the root's children
 * through ld->hooks and sorts them into s (ld->scene). */
struct loader;
rsw_status scene_create(struct loader *ld, node *n, object **out);
extern const plugin plugin_scene;

/* Recompute the scene's bounds and what emitters and sensors derive from
 * them (after geometry changed). */
rsw_status scene_refresh_bounds(scene *s, rsw_err *err);

/* Evaluate every object's wavelength-dependent state for a render. */
rsw_status scene_prepare(scene *s, const render_ctx *rc, rsw_err *err);
/* Whether some object's state depends on the render's wavelength (its
 * plugin's spectral hook says so): a wavelength sweep of a scene where
 * none does renders the same thing at every wavelength. Reads the scene
 * only (not thread-safe with an update of it). */
bool scene_wavelength_dependent(const scene *s);
/* Answers the scene's emitters replaced by black during the last render
 * at its channel `channel` (the film: a bundle's wavelength index, 0 for
 * a render of one wavelength; emitter_ops.failures: environment plugins'
 * NaN or negative radiance at that wavelength, bad pdfs or directions,
 * failed set_param), summed; the first one's message into msg (len
 * bytes; "" when none). */
size_t emitter_failures(const scene *s, int channel, char *msg, size_t len);
/* The first object that cannot render a bundle of more than three
 * wavelengths (pages, render_ctx.bundle > 3), with *why its reason (a
 * phrase to follow the object's name), or NULL when the scene can. */
const object *scene_page_blocker(const scene *s, const char **why);

/* Sensor by id, or by decimal index when `id` is all digits. NULL if none. */
sensor *scene_find_sensor(const scene *s, const char *id, size_t *index_out);
/* What rendering sensor se's film takes in memory, in bytes, at most
 * (checked before a render allocates anything, so that a film too large
 * for the server is refused up front): per pixel the accumulator (4
 * doubles, 7 for a Stokes film), the developed film (channels floats) and
 * its encoded copy, and for the distant family the viewing angles (2
 * doubles) twice (film and encoded metadata). *channels (optional) gets
 * the film's channel count. Saturates at UINT64_MAX. */
uint64_t sensor_film_bytes(const sensor *se, rsw_variant variant, int *channels);

/* Free the scene, every object it owns and its document. NULL is a no-op. */
void scene_free(scene *s);

/* The primitives the scene's acceleration structure holds: each mesh's
 * triangles, one per analytic shape, and per instancing shape its
 * placements (an instanced group's members counted once, as Embree holds
 * them once). What render.c sizes its waves by. */
size_t scene_primitive_count(const scene *s);

#endif
