/* The scene builder plus one tiny render: a JSON or XML document (a
 * leading '<' after blanks picks XML) is read, built (every plugin's
 * create, the parameter table, the Embree scene) and its first sensor
 * rendered at 1 spp on one thread when its film is at most 4x4 and the
 * path depth is bounded (deeper integrators are clamped to depth 4, so a
 * render costs microseconds). Mesh and instance-list file names resolve to
 * three small in-memory files (m.obj, m.ply, i.txt); any other name is
 * refused, as the daemon refuses names outside its data root.
 *
 * Invariant: a load error names itself, a render either fails with an
 * error or gives a film of the sensor's size. */
#include <math.h>
#include <time.h>

#include "../../server/kernel/render.h"
#include "../../server/kernel/scene/scene.h"
#include "fuzz.h"

static const char obj_text[] = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                               "vn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n";
static const char ply_text[] = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                               "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                               "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
static const char list_text[] = "# two placements\n1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n0.5 0.5 0 0 0 1 0.2\n";

static char obj_path[64], ply_path[64], list_path[64];

int LLVMFuzzerInitialize(int *argc, char ***argv) {
  (void)argc;
  (void)argv;
  fuzz_memfile((const uint8_t *)obj_text, sizeof obj_text - 1, obj_path, sizeof obj_path);
  fuzz_memfile((const uint8_t *)ply_text, sizeof ply_text - 1, ply_path, sizeof ply_path);
  fuzz_memfile((const uint8_t *)list_text, sizeof list_text - 1, list_path, sizeof list_path);
  return 0;
}

static rsw_status resolve(void *user, const char *name, char **path_out, rsw_err *err) {
  (void)user;
  const char *p = strcmp(name, "m.obj") == 0   ? obj_path
                  : strcmp(name, "m.ply") == 0 ? ply_path
                  : strcmp(name, "i.txt") == 0 ? list_path
                                               : NULL;
  if (!p) return rsw_fail(err, RSW_ERR_FILE, name, "no such file in the fuzz harness");
  *path_out = strdup(p);
  return *path_out ? RSW_OK : rsw_fail(err, RSW_ERR_NOMEM, name, "out of memory");
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size > FUZZ_MAX_INPUT) return 0;
  size_t i = 0;
  while (i < size && (data[i] == ' ' || data[i] == '\n' || data[i] == '\r' || data[i] == '\t')) i++;
  bool is_xml = i < size && data[i] == '<';
  scene_load_opts o = {.size = sizeof o, .resolve = resolve};
  scene *s = NULL;
  rsw_err err = {0};
  rsw_status st = scene_load_memory((const char *)data, size, "fuzz", is_xml, &o, &s, &err);
  if (st != RSW_OK) {
    FUZZ_CHECK(s == NULL, "a scene with an error");
    FUZZ_CHECK(err.msg[0] != '\0', "a load error without a message (status %d)", (int)st);
    return 0;
  }
  FUZZ_CHECK(s != NULL, "RSW_OK without a scene");
  if (s->n_sensors > 0 && s->sensors[0]->film && s->integrator) {
    const film *fm = s->sensors[0]->film;
    if (fm->width >= 1 && fm->height >= 1 && fm->width <= 4 && fm->height <= 4) {
      if (s->integrator->max_depth < 0 || s->integrator->max_depth > 4) s->integrator->max_depth = 4;
      render_opts ro = {.size = sizeof ro, .sensor = 0, .spp = 1, .seed = 1, .threads = 1};
      ro.deadline = now_s() + 2.0;
      film_image img = {0};
      render_result_stats stats = {0};
      rsw_err rerr = {0};
      st = render_sensor(s, &ro, &img, &stats, &rerr);
      if (st == RSW_OK) {
        FUZZ_CHECK(img.data != NULL, "a film without data");
        FUZZ_CHECK(img.width == fm->width && img.height == fm->height, "film %dx%d, sensor %dx%d", img.width,
                   img.height, fm->width, fm->height);
      } else {
        FUZZ_CHECK(rerr.msg[0] != '\0', "a render error without a message (status %d)", (int)st);
      }
      film_image_free(&img);
    }
  }
  scene_free(s);
  return 0;
}
