/* Server-sent events: GET /jobs/{id}/events (server.c hands the stream
 * to MHD; see sse.h).
 *
 * event: context | end
 * id: <sequence>
 * data: <json>            (one data: line per line of the JSON)
 * <blank line>
 *
 * A stream has a thread of its own that waits for the job's events and
 * appends their text to `out`; the content reader (on MHD's event loop)
 * copies what is there, and when nothing is, suspends the connection and
 * returns 0; the thread resumes it once it appended something. The stream
 * is freed by whichever of the two (the thread, MHD's sse_free) lets go
 * last. */
#include "sse.h"

#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cjson/cJSON.h>
#include <microhttpd.h>

#include "encode.h"

typedef struct sse_stream {
  sse_host host; /* a copy */
  struct MHD_Connection *conn;
  char job[128];
  uint64_t after;
  pthread_mutex_t mu;
  http_buf out; /* formatted and not yet handed to MHD */
  size_t out_off;
  bool ended;     /* nothing will be appended any more */
  bool failed;    /* out of memory: end with an error */
  bool suspended; /* the reader suspended the connection */
  bool released;  /* MHD let go (sse_free): do not touch conn */
  int refs;       /* the thread and MHD */
} sse_stream;

static void sse_format(http_buf *b, const char *event, uint64_t id, const char *data) {
  http_buf_printf(b, "event: %s\n", event);
  if (id) http_buf_printf(b, "id: %llu\n", (unsigned long long)id);
  for (const char *line = data;;) {
    size_t n = strcspn(line, "\r\n");
    http_buf_puts(b, "data: ");
    http_buf_append(b, line, n);
    http_buf_puts(b, "\n");
    line += n;
    if (*line == '\r' && line[1] == '\n') line++;
    if (!*line || !*++line) break;
  }
  http_buf_puts(b, "\n");
}

static sse_stream *sse_new(const sse_host *h, struct MHD_Connection *c, const char *job, uint64_t after) {
  sse_stream *st = calloc(1, sizeof *st);
  if (!st) return NULL;
  st->host = *h;
  st->conn = c;
  snprintf(st->job, sizeof st->job, "%s", job);
  st->after = after;
  st->refs = 1; /* MHD's, until sse_free */
  pthread_mutex_init(&st->mu, NULL);
  h->count(h->ctx, +1);
  return st;
}

static void sse_release(sse_stream *st) {
  pthread_mutex_lock(&st->mu);
  bool last = --st->refs == 0;
  pthread_mutex_unlock(&st->mu);
  if (!last) return;
  sse_host h = st->host;
  http_buf_free(&st->out);
  pthread_mutex_destroy(&st->mu);
  free(st);
  h.count(h.ctx, -1);
}

/* Append text (or end the stream) and wake the reader. */
static void sse_push(sse_stream *st, const http_buf *text, bool end) {
  pthread_mutex_lock(&st->mu);
  if (text && text->len) {
    /* Compact what the reader consumed, then append. */
    if (st->out_off) {
      memmove(st->out.p, st->out.p + st->out_off, st->out.len - st->out_off);
      st->out.len -= st->out_off;
      if (st->out.p) st->out.p[st->out.len] = '\0';
      st->out_off = 0;
    }
    http_buf_append(&st->out, text->p, text->len);
    if (st->out.failed) st->failed = true;
  }
  if (end) st->ended = true;
  if (st->suspended && !st->released) {
    st->suspended = false;
    MHD_resume_connection(st->conn);
  }
  pthread_mutex_unlock(&st->mu);
}

/* Is the job over (its `end` event, if any, appended already: the service
 * sets the state and appends `end` under one lock)? */
static bool job_is_terminal(service *svc, const char *job) {
  svc_error e = {0};
  char *json = NULL;
  if (service_job_get(svc, job, &json, &e) != RSW_OK) {
    free(json);
    return true; /* gone: next_event reports it */
  }
  cJSON *j = json ? cJSON_Parse(json) : NULL;
  free(json);
  const cJSON *st = cJSON_GetObjectItemCaseSensitive(j, "state");
  bool done = cJSON_IsString(st) &&
              (strcmp(st->valuestring, "succeeded") == 0 || strcmp(st->valuestring, "failed") == 0 ||
               strcmp(st->valuestring, "cancelled") == 0);
  cJSON_Delete(j);
  return done;
}

static void *sse_main(void *arg) {
  sse_stream *st = arg;
  const sse_host *h = &st->host;
  int waited_ms = 0;
  bool end = false;
  while (!end) {
    pthread_mutex_lock(&st->mu);
    bool gone = st->released;
    pthread_mutex_unlock(&st->mu);
    if (gone) break;
    if (h->must_end(h->ctx)) {
      sse_push(st, NULL, true);
      break;
    }
    http_buf text = {0};
    uint64_t seq = 0;
    char *json = NULL;
    bool is_end = false;
    svc_error e = {0};
    /* Resumed at or past the last event of a finished job: nothing more
     * will come, so the stream ends at once. The `end` event is not sent
     * again: its id is at most Last-Event-ID, so the client has it. The
     * state is read before looking for an event, so an end that arrives
     * in between is still sent. */
    bool terminal = job_is_terminal(h->svc, st->job);
    rsw_status s = service_job_next_event(h->svc, st->job, st->after, terminal ? 0 : SSE_POLL_MS, &seq, &json,
                                          &is_end, &e);
    if (s != RSW_OK) { /* the job went away (deleted): say why, then end */
      int status;
      char *problem = http_problem_from_svc(&e, &status);
      sse_format(&text, "error", 0, problem ? problem : "{}");
      free(problem);
      end = true;
    } else if (json) {
      sse_format(&text, is_end ? "end" : "context", seq, json);
      free(json);
      if (seq > st->after) st->after = seq;
      end = is_end;
      waited_ms = 0;
    } else if (terminal) {
      end = true;
    } else if ((waited_ms += SSE_POLL_MS) >= SSE_PING_MS) {
      http_buf_puts(&text, ": ping\n\n");
      waited_ms = 0;
    }
    if (text.failed) end = true;
    if (text.len || end) sse_push(st, &text, end);
    http_buf_free(&text);
  }
  sse_release(st);
  return NULL;
}

static bool sse_start(sse_stream *st) {
  pthread_t t;
  pthread_attr_t at;
  pthread_attr_init(&at);
  pthread_attr_setdetachstate(&at, PTHREAD_CREATE_DETACHED);
  pthread_mutex_lock(&st->mu);
  st->refs++;
  pthread_mutex_unlock(&st->mu);
  bool ok = pthread_create(&t, &at, sse_main, st) == 0;
  pthread_attr_destroy(&at);
  if (!ok) {
    pthread_mutex_lock(&st->mu);
    st->refs--;
    pthread_mutex_unlock(&st->mu);
  }
  return ok;
}

/* MHD's event loop: copy what the thread formatted, or suspend. */
static ssize_t sse_read(void *cls, uint64_t pos, char *buf, size_t max) {
  sse_stream *st = cls;
  (void)pos;
  pthread_mutex_lock(&st->mu);
  ssize_t ret;
  if (st->out_off < st->out.len) {
    size_t n = st->out.len - st->out_off;
    if (n > max) n = max;
    memcpy(buf, st->out.p + st->out_off, n);
    st->out_off += n;
    ret = (ssize_t)n;
  } else if (st->failed) {
    ret = MHD_CONTENT_READER_END_WITH_ERROR;
  } else if (st->ended) {
    ret = MHD_CONTENT_READER_END_OF_STREAM;
  } else {
    st->suspended = true;
    MHD_suspend_connection(st->conn);
    ret = 0;
  }
  pthread_mutex_unlock(&st->mu);
  return ret;
}

static void sse_free(void *cls) {
  sse_stream *st = cls;
  pthread_mutex_lock(&st->mu);
  st->released = true;
  pthread_mutex_unlock(&st->mu);
  sse_release(st);
}

struct MHD_Response *sse_response(const sse_host *h, struct MHD_Connection *c, const char *job,
                                  uint64_t after) {
  sse_stream *st = sse_new(h, c, job, after);
  if (!st) return NULL;
  struct MHD_Response *mr = MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 4096, sse_read, st, sse_free);
  if (!mr) {
    sse_release(st);
    return NULL;
  }
  if (!sse_start(st)) {
    MHD_destroy_response(mr); /* sse_free releases the stream */
    return NULL;
  }
  MHD_add_response_header(mr, MHD_HTTP_HEADER_CONTENT_TYPE, "text/event-stream");
  MHD_add_response_header(mr, MHD_HTTP_HEADER_CACHE_CONTROL, "no-cache");
  return mr;
}
