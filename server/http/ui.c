/* Serving the web viewer's files (see ui.h). Everything is in memory and
 * nothing blocks: these routes run on the event loop, like the health
 * probes. */
#include "ui.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The page may load its own files and talk to its own origin, nothing
 * else: no inline script, no CDN, no framing. */
#define UI_CSP                                                                                               \
  "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; "      \
  "frame-ancestors 'none'; base-uri 'none'; form-action 'none'"

/* Does an If-None-Match header (a list of tags, W/ prefixes allowed, or
 * "*") name etag? */
static bool etag_listed(const char *inm, const char *etag) {
  if (!inm) return false;
  size_t elen = strlen(etag);
  const char *p = inm;
  while (*p) {
    while (*p == ' ' || *p == '\t' || *p == ',') p++;
    if (!*p) break;
    size_t n = strcspn(p, ",");
    size_t m = n;
    while (m && (p[m - 1] == ' ' || p[m - 1] == '\t')) m--;
    const char *t = p;
    if (m == 1 && t[0] == '*') return true;
    if (m >= 2 && t[0] == 'W' && t[1] == '/') t += 2, m -= 2; /* weak comparison (RFC 9110 13.1.2) */
    if (m == elen && memcmp(t, etag, elen) == 0) return true;
    p += n;
  }
  return false;
}

static void serve(http_req *r, const http_ui_asset *a) {
  http_resp_clear(&r->resp);
  snprintf(r->resp.etag, sizeof r->resp.etag, "%s", a->etag);
  r->resp.cache_control = "no-cache";
  if (etag_listed(r->if_none_match, a->etag)) {
    r->resp.status = 304;
    return;
  }
  char *body = malloc(a->len);
  if (!body) {
    http_resp_problem(r, 500, "RSW_ERR_NOMEM", "the file could not be copied (out of memory)");
    return;
  }
  memcpy(body, a->bytes, a->len);
  r->resp.status = 200;
  r->resp.content_type = a->content_type;
  r->resp.csp = UI_CSP;
  r->resp.body = body;
  r->resp.len = a->len;
}

void http_ui_redirect(http_req *r) {
  http_resp_clear(&r->resp);
  r->resp.status = 301;
  snprintf(r->resp.location, sizeof r->resp.location, "/ui/");
}

/* The root: a browser pointed at the daemon lands on the viewer. 302, not
 * 301: the root may one day answer something else, and browsers cache 301s. */
void http_root_redirect(http_req *r) {
  http_resp_clear(&r->resp);
  r->resp.status = 302;
  snprintf(r->resp.location, sizeof r->resp.location, "/ui/");
}

void http_ui_file(http_req *r) {
  const char *name = r->params[0];
  for (size_t i = 0; i < http_ui_n_assets; i++)
    if (strcmp(http_ui_assets[i].name, name) == 0) {
      serve(r, &http_ui_assets[i]);
      return;
    }
  http_resp_problem(r, 404, "RSW_ERR_NOT_FOUND", "the viewer has no file %.200s (see /ui/)", name);
}

void http_ui_index(http_req *r) {
  r->params[0] = "index.html";
  http_ui_file(r);
}
