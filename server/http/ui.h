/* The web viewer (ui/): static files compiled into raysweepd by
 * tools/embed-ui.sh and served at /ui/ without a token (the files hold no
 * data; every API call the page makes sends the token). */
#ifndef RSW_HTTP_UI_H
#define RSW_HTTP_UI_H

#include <stddef.h>

#include "routes.h"

typedef struct http_ui_asset {
  const char *name;         /* file name under /ui/ ("index.html") */
  const char *content_type; /* from the extension */
  const char *etag; /* quoted strong tag: the first 96 bits of the SHA-256 in hex (fits http_resp.etag) */
  const unsigned char *bytes;
  size_t len;
} http_ui_asset;

/* The generated table (build/gen/ui_assets.c). */
extern const http_ui_asset http_ui_assets[];
extern const size_t http_ui_n_assets;

/* GET /ui: 301 to /ui/. GET /ui/: index.html. GET /ui/{file}: that file,
 * or 404. Each answer carries its ETag and Cache-Control: no-cache, and a
 * matching If-None-Match gets 304 with no body. */
void http_ui_redirect(http_req *r);
void http_root_redirect(http_req *r); /* GET /: 302 to /ui/ */
void http_ui_index(http_req *r);
void http_ui_file(http_req *r);

#endif
