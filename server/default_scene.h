/* The scene raysweepd serve preloads when no --scene is given: the
 * hdistant seed scene (proto/examples/hdistant_seed.xml), embedded as
 * text by a Makefile rule into build/gen/default_scene.c. */
#ifndef RSW_DEFAULT_SCENE_H
#define RSW_DEFAULT_SCENE_H

#include <stddef.h>

extern const char rsw_default_scene_xml[];
extern const size_t rsw_default_scene_xml_len; /* bytes, without the NUL */

#endif
