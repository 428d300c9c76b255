/* make bench: dataset_nc. A sweep of 200 contexts (a 10 x 20 grid over two
 * coords) of one 64 x 64 mono hdistant-like film each (with per-pixel
 * angles, the same in every film) encoded as one NetCDF-4 dataset in memory
 * (common/dataset_nc.c, what GET /v1/jobs/{id}/dataset does after copying
 * the films). One JSON line:
 *   encode_s      wall time of nc_dataset_encode (median of 5)
 *   film_mib      the films' float32 bytes, MiB
 *   file_mib      the encoded file, MiB
 *   mib_per_s     film_mib / encode_s */
#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench.h"
#include "dataset_nc.h"

#define NA 10
#define NB 20
#define W  64
#define H  64

int main(void) {
  enum {
    N = NA * NB
  };
  static float data[N][H * W];
  static double angles[H * W * 2];
  static char idbuf[N][16];
  const char *ids[N];
  cJSON *co[N];
  const void *cp[N];
  nc_var vars[N];
  nc_film films[N];
  const char *ch[1] = {"Y"};
  for (int p = 0; p < H * W; p++) angles[2 * p] = p % 90, angles[2 * p + 1] = p % 360;
  for (int i = 0; i < N; i++) {
    snprintf(idbuf[i], sizeof idbuf[i], "c%05d", i);
    ids[i] = idbuf[i];
    co[i] = cJSON_CreateObject();
    cJSON_AddNumberToObject(co[i], "wavelength", 400 + 10 * (i / NB));
    cJSON_AddNumberToObject(co[i], "alpha", 0.05 * (i % NB));
    cp[i] = co[i];
    for (int p = 0; p < H * W; p++) data[i][p] = (float)(i + p) * 1e-3f;
    vars[i] = (nc_var){"radiance", data[i]};
    films[i] = (nc_film){.context = (size_t)i,
                         .sensor = "hdistant",
                         .width = W,
                         .height = H,
                         .channels = 1,
                         .channel_names = ch,
                         .spp = 64,
                         .seed = (uint64_t)i,
                         .angles = angles,
                         .vars = &vars[i],
                         .n_vars = 1};
  }
  nc_coords coords;
  rsw_err err = {0};
  if (nc_coords_build(cp, N, "/contexts", &coords, &err) != RSW_OK) {
    fprintf(stderr, "bench_dataset_nc: %s\n", err.msg);
    return 1;
  }
  nc_dataset d = {.size = sizeof d,
                  .scene = "bench",
                  .variant = "mono",
                  .n_contexts = N,
                  .context_ids = ids,
                  .coords = &coords,
                  .films = films,
                  .n_films = N};
  double t[5];
  size_t len = 0;
  for (int r = 0; r < 5; r++) {
    void *bytes = NULL;
    double t0 = bench_wall_s();
    if (nc_dataset_encode(&d, &bytes, &len, &err) != RSW_OK) {
      fprintf(stderr, "bench_dataset_nc: %s\n", err.msg);
      return 1;
    }
    t[r] = bench_wall_s() - t0;
    free(bytes);
  }
  qsort(t, 5, sizeof t[0], bench_cmp_double);
  double film_mib = (double)N * W * H * 4 / (1 << 20);
  printf("{\"bench\":\"dataset_nc\",\"contexts\":%d,\"film\":\"%dx%d\",\"encode_s\":%.4f,\"film_mib\":%.2f,"
         "\"file_mib\":%.2f,\"mib_per_s\":%.1f}\n",
         N, W, H, t[2], film_mib, (double)len / (1 << 20), film_mib / t[2]);
  nc_coords_free(&coords);
  for (int i = 0; i < N; i++) cJSON_Delete(co[i]);
  return 0;
}
