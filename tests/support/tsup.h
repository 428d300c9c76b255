/* Helpers for validation tests: load a scene from a string, render it. */
#ifndef RSW_TSUP_H
#define RSW_TSUP_H

#include "../../server/kernel/render.h"
#include "../../server/kernel/scene/scene.h"

/* Load a JSON (or XML when text starts with '<') scene from memory;
 * prints the error and returns NULL on failure. */
scene *tsup_load(const char *text, const char *variant);
/* Same from a file under the repository root. */
scene *tsup_load_file(const char *path, const char *variant);
/* Render sensor 0 (spp 0 = the scene's); returns false (and prints) on
 * failure. */
bool tsup_render(scene *s, uint32_t spp, uint64_t seed, int threads, film_image *out);
/* Mean and standard error of the mean over all pixels of channel c. */
void tsup_stats(const film_image *img, int c, double *mean, double *sem);

#endif
