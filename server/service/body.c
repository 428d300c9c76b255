/* Request bodies read strictly (svc_parse_body, svc_check_body). */
#include <stdio.h>
#include <string.h>

#include "../kernel/core/jsonscan.h"
#include "service_internal.h"

rsw_status svc_check_body(const char *body, size_t len, svc_error *e) {
  if (!body || len == 0)
    return svc_fail(e, RSW_ERR_PARSE, "", "the body is empty: a JSON object is required");
  /* cJSON stops after the first value: the rest must be blank ("{} xyz"
   * and "{}{}" were accepted as {}). */
  long end = json_value_end(body, len);
  if (end >= 0) {
    size_t p = (size_t)end;
    while (p < len && (body[p] == ' ' || body[p] == '\t' || body[p] == '\n' || body[p] == '\r')) p++;
    if (p < len)
      return svc_fail(e, RSW_ERR_PARSE, "",
                      "the body is not valid JSON: unexpected content after the document at byte %zu", p);
  }
  char member[128];
  if (json_find_nul_escape(body, len, member, sizeof member) >= 0) {
    rsw_status st = svc_fail(e, RSW_ERR_INVALID, "",
                             "%s%s%sa string contains \\u0000 (NUL), which no key, id or value may hold",
                             member[0] ? "'" : "", member, member[0] ? "': " : "");
    snprintf(e->key, sizeof e->key, "%s", member);
    return st;
  }
  return RSW_OK;
}

rsw_status svc_parse_body(const char *body, size_t len, cJSON **out, svc_error *e) {
  *out = NULL;
  rsw_status st = svc_check_body(body, len, e);
  if (st) return st;
  const char *end = NULL;
  cJSON *j = cJSON_ParseWithLengthOpts(body, len, &end, 0);
  if (!j) {
    size_t off = end && end >= body && end <= body + len ? (size_t)(end - body) : 0;
    return svc_fail(e, RSW_ERR_PARSE, "", "the body is not valid JSON (near byte %zu)", off);
  }
  *out = j;
  return RSW_OK;
}
