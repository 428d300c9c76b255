/* Server-sent events (sse.c): the body of GET /jobs/{id}/events, one
 * event per job context as the service reports them, as an MHD response
 * whose thread waits on the service. server.c queues it. */
#ifndef RSW_HTTP_SSE_H
#define RSW_HTTP_SSE_H

#include <stdbool.h>
#include <stdint.h>

#include "../service/service.h"

/* Event streams poll the service this often for shutdown, and send a
 * keep-alive comment after this long without an event (proxies drop
 * silent connections; it also reveals clients that went away). */
#define SSE_POLL_MS 500
#define SSE_PING_MS 15000

/* What a stream needs of the server that made it (copied into the
 * stream; ctx must outlive every stream: the server waits for count to
 * bring its streams back to zero before it goes). */
typedef struct sse_host {
  service *svc;
  void *ctx;
  bool (*must_end)(void *ctx);         /* shutting down, past the grace period: end now */
  void (*count)(void *ctx, int delta); /* +1 when a stream is made, -1 when it is freed */
} sse_host;

struct MHD_Connection;
struct MHD_Response;

/* The event stream of job `job` from events after `after` (Last-Event-ID),
 * with its headers (text/event-stream, no-cache); NULL when out of memory
 * or no thread could be started. */
struct MHD_Response *sse_response(const sse_host *h, struct MHD_Connection *c, const char *job,
                                  uint64_t after);

#endif
