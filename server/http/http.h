/* The HTTP front of raysweepd: a libmicrohttpd daemon serving the routes of
 * proto/API-NOTES.md over a service (server/service/service.h). A few
 * event-loop threads parse and check requests; each handler that may block
 * runs on a thread of its own (see server.c for why), and the CPU work is
 * the service's.
 *
 * This header mentions no microhttpd type; server/http/server.c and its
 * event streams, server/http/sse.c, are the only files that include
 * microhttpd.h. */
#ifndef RSW_HTTP_H
#define RSW_HTTP_H

#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>

#include "../service/service.h"
#include "rsw_error.h"

typedef struct http_server http_server;

typedef struct http_opts {
  size_t size;                     /* sizeof(http_opts) */
  const char *host;                /* IPv4 literal or name resolving to IPv4 ("127.0.0.1") */
  int port;                        /* 0: an ephemeral port (see http_server_port) */
  const char *token;               /* bearer token (NULL or "": no auth); copied */
  size_t max_body;                 /* request bodies over this many bytes get 413
                         (0: HTTP_DEFAULT_MAX_BODY) */
  unsigned max_connections;        /* open connections at most (0: HTTP_DEFAULT_MAX_CONNECTIONS);
                               above all but HTTP_RESERVED_CONNECTIONS of them, requests
                               other than the health probes get 503 + Retry-After */
  double header_timeout_s;         /* a connection must send a request's headers within this
                               long of connecting or of its previous request's end
                               (0: HTTP_DEFAULT_HEADER_TIMEOUT_S) */
  unsigned max_connections_per_ip; /* 0: no per-address limit */
} http_opts;

#define HTTP_DEFAULT_MAX_BODY         ((size_t)256 << 20)
#define HTTP_DEFAULT_MAX_CONNECTIONS  1024u
#define HTTP_DEFAULT_HEADER_TIMEOUT_S 10.0
#define HTTP_RESERVED_CONNECTIONS     16u

/* Start listening. Borrows svc (which must outlive the server) and opts.
 * A non-loopback host without a token is refused (RSW_ERR_USAGE), as is an
 * IPv6 literal (RSW_ERR_UNSUPPORTED); a host that does not resolve or a
 * port that cannot be bound is RSW_ERR_IO. *out only on success. */
rsw_status http_server_start(service *svc, const http_opts *opts, http_server **out, rsw_err *err);

/* The port actually bound (the ephemeral one when opts.port was 0). */
int http_server_port(const http_server *srv);

/* Stop: event streams end, connections close, threads are joined. Call
 * service_shutdown first so blocked renders return. NULL is a no-op. */
void http_server_stop(http_server *srv);

/* True when host is an IPv4 loopback address or "localhost". */
bool http_host_is_loopback(const char *host);

/* `METHOD PATH` per line, path templates as in the API notes. */
void http_routes_print(FILE *f);

#endif
