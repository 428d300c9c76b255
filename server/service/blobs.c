/* Content-addressed blobs: PUT /v1/blobs/{sha256}, HEAD, and
 * POST /v1/blobs:missing. */
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "buf.h"
#include "rsw_sha256.h"
#include "service_internal.h"

rsw_status service_blob_put(service *svc, const char *h, const void *data, size_t len, bool *created,
                            svc_error *e) {
  if (!rsw_is_sha256_hex(h))
    return svc_fail(e, RSW_ERR_BAD_REQUEST, h, "a blob is named by its SHA-256: 64 lowercase hex digits");
  unsigned char d[32];
  char dh[65];
  if (!rsw_sha256(data, len, d)) return svc_fail(e, RSW_ERR_NOMEM, h, "hashing failed");
  rsw_hex(d, 32, dh);
  if (strcmp(dh, h) != 0) return svc_fail(e, RSW_ERR_INVALID, h, "the body's SHA-256 is %s, not %s", dh, h);
  char path[8192];
  snprintf(path, sizeof path, "%s/%s", svc->blob_dir, h);
  struct stat sb; /* a regular file of that name: stored already (anything else is replaced) */
  if (lstat(path, &sb) == 0 && S_ISREG(sb.st_mode)) {
    *created = false;
    return RSW_OK;
  }
  /* Durable before it is acknowledged (temporary file created O_EXCL |
   * O_NOFOLLOW, fsync, rename, fsync of the directory). */
  if (!svc_write_file(path, data, len)) {
    int err = errno;
    if (err == ENOSPC || err == EDQUOT || err == EROFS || err == EIO)
      return svc_fail(e, RSW_ERR_STATE_DIR, h, "cannot store the blob in the server's blob directory: %s",
                      strerror(err));
    return svc_fail(e, RSW_ERR_IO, h, "cannot store the blob: %s", strerror(err));
  }
  *created = true;
  return RSW_OK;
}

long long service_blob_size(service *svc, const char *h) {
  if (!rsw_is_sha256_hex(h)) return -1;
  char path[8192];
  snprintf(path, sizeof path, "%s/%s", svc->blob_dir, h);
  struct stat sb;
  return stat(path, &sb) == 0 ? (long long)sb.st_size : -1;
}

bool service_blob_exists(service *svc, const char *h) {
  if (!rsw_is_sha256_hex(h)) return false;
  char path[8192];
  snprintf(path, sizeof path, "%s/%s", svc->blob_dir, h);
  struct stat sb;
  return stat(path, &sb) == 0;
}

rsw_status service_blobs_missing(service *svc, const char *body, size_t len, char **json_out, svc_error *e) {
  unsigned jm = svc_json_mark();
  cJSON *j = cJSON_ParseWithLength(body, len);
  if (!j) return svc_fail(e, RSW_ERR_PARSE, "", "the body is not valid JSON");
  rsw_status st = svc_check_body(body, len, e);
  if (st) {
    cJSON_Delete(j);
    return st;
  }
  if (!cJSON_IsObject(j)) {
    cJSON_Delete(j);
    return svc_fail(e, RSW_ERR_TYPE, "", "the body must be a JSON object {\"digests\": [...]}");
  }
  for (const cJSON *k = j->child; k; k = k->next)
    if (strcmp(k->string, "digests") != 0) {
      char w[300];
      snprintf(w, sizeof w, "/%s", k->string);
      cJSON_Delete(j);
      return svc_fail(e, RSW_ERR_UNUSED_PROPERTY, w, "unknown field '%s' (expected digests)", w + 1);
    }
  const cJSON *d = cJSON_GetObjectItemCaseSensitive(j, "digests");
  if (!cJSON_IsArray(d)) {
    cJSON_Delete(j);
    return svc_fail(e, RSW_ERR_TYPE, "/digests", "expected {\"digests\": [sha256 hex, ...]}");
  }
  cJSON *o = cJSON_CreateObject();
  cJSON *m = cJSON_AddArrayToObject(o, "missing");
  int i = 0;
  for (const cJSON *x = d->child; x; x = x->next, i++) {
    if (!cJSON_IsString(x) || !rsw_is_sha256_hex(x->valuestring)) {
      cJSON_Delete(o);
      cJSON_Delete(j);
      char ptr[32];
      snprintf(ptr, sizeof ptr, "/digests/%d", i);
      return svc_fail(e, RSW_ERR_INVALID, ptr, "not a SHA-256 hex digest");
    }
    if (!service_blob_exists(svc, x->valuestring)) svc_json_push(m, cJSON_CreateString(x->valuestring));
  }
  cJSON_Delete(j);
  return svc_json_out(json_out, o, jm, e);
}
