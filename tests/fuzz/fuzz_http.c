/* HTTP request handling: raw request bytes into the real server
 * (server/http over the service), started once per process on an
 * ephemeral loopback port. Each input is written to a fresh connection
 * (placeholders as in tests/corpus/http: "{SCENE}" becomes the harness
 * scene's id, so routes under a scene are reached; {AUTH} nothing; {CL}
 * the body length), the write side is shut, and the answer read (to the
 * end of the first complete response, at most 1 s). Invariants:
 *  - an answer, if any, starts with an HTTP/1.x status line;
 *  - a problem+json answer is valid UTF-8 and valid JSON (FUZZ_HTTP_LAX=1
 *    in the environment skips this check);
 *  - after every input the daemon still answers GET /v1/health/live 200.
 * Renders are bounded by the service's 256 pixel samples per request. */
#include <arpa/inet.h>
#include <cjson/cJSON.h>
#include <errno.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/time.h>

#include "../../server/http/http.h"
#include "fuzz_service.h"

static http_server *srv;
static int port;
static bool lax;

static void http_end(void) {
  if (fuzz_svc) service_shutdown(fuzz_svc);
  http_server_stop(srv);
  srv = NULL;
}

int LLVMFuzzerInitialize(int *argc, char ***argv) {
  (void)argc;
  (void)argv;
  signal(SIGPIPE, SIG_IGN);
  fuzz_service_start();
  http_opts ho = {
      .size = sizeof ho, .host = "127.0.0.1", .port = 0, .max_body = 1 << 20, .max_connections = 64};
  rsw_err err = {0};
  FUZZ_CHECK(http_server_start(fuzz_svc, &ho, &srv, &err) == RSW_OK, "http_server_start: %s", err.msg);
  port = http_server_port(srv);
  atexit(http_end); /* runs before fuzz_service_end (registered earlier) */
  const char *l = getenv("FUZZ_HTTP_LAX");
  lax = l && *l && strcmp(l, "0") != 0;
  return 0;
}

static int connect_lo(void) {
  int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return -1;
  struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)port)};
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  struct timeval tv = {1,
                       0}; /* loopback answers take microseconds; a request the server waits on costs this */
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  if (connect(fd, (struct sockaddr *)&a, sizeof a) != 0) {
    close(fd);
    return -1;
  }
  return fd;
}

/* Is the (NUL-terminated) text one complete final response: headers and a
 * Content-Length body, a chunked body up to its last chunk, or the headers
 * of an answer to HEAD or of a 204/304? (Otherwise read until close.) */
static bool response_complete(const char *buf, size_t n, bool head) {
  const char *end = strstr(buf, "\r\n\r\n");
  if (!end || n < 12) return false;
  if (buf[9] == '1') return false; /* 100 Continue: a final answer follows */
  size_t hl = (size_t)(end + 4 - buf);
  if (head || strncmp(buf + 9, "204", 3) == 0 || strncmp(buf + 9, "304", 3) == 0) return true;
  const char *cl = strcasestr(buf, "\r\ncontent-length:");
  if (cl && cl < end) return n >= hl + strtoull(cl + 17, NULL, 10);
  const char *te = strcasestr(buf, "\r\ntransfer-encoding: chunked");
  if (te && te < end) return n >= hl + 5 && memcmp(buf + n - 5, "0\r\n\r\n", 5) == 0;
  return false;
}

/* Send req, shut the write side, read the answer (up to cap-1 bytes, NUL
 * terminated) until the server closes or 1 s passes. Returns its length. */
static size_t exchange(const char *req, size_t len, char *out, size_t cap) {
  int fd = connect_lo();
  FUZZ_CHECK(fd >= 0, "cannot connect to the daemon: %s", strerror(errno));
  size_t off = 0;
  while (off < len) {
    ssize_t w = send(fd, req + off, len - off, MSG_NOSIGNAL);
    if (w <= 0) break; /* the server may close early (e.g. 413): fine */
    off += (size_t)w;
  }
  shutdown(fd, SHUT_WR);
  bool head = len >= 5 && memcmp(req, "HEAD ", 5) == 0;
  size_t got = 0;
  while (got + 1 < cap) {
    ssize_t r = recv(fd, out + got, cap - 1 - got, 0);
    if (r <= 0) break;
    got += (size_t)r;
    out[got] = '\0';
    if (response_complete(out, got, head)) break; /* do not wait for a keep-alive close */
  }
  out[got] = '\0';
  close(fd);
  return got;
}

static bool utf8_valid(const unsigned char *s, size_t n) {
  size_t i = 0;
  while (i < n) {
    unsigned c = s[i];
    size_t k;
    unsigned min;
    if (c < 0x80) {
      i++;
      continue;
    } else if ((c & 0xE0) == 0xC0) {
      k = 1, min = 0x80, c &= 0x1F;
    } else if ((c & 0xF0) == 0xE0) {
      k = 2, min = 0x800, c &= 0x0F;
    } else if ((c & 0xF8) == 0xF0) {
      k = 3, min = 0x10000, c &= 0x07;
    } else {
      return false;
    }
    if (i + k >= n) return false;
    for (size_t j = 1; j <= k; j++) {
      if (i + j >= n || (s[i + j] & 0xC0) != 0x80) return false;
      c = (c << 6) | (s[i + j] & 0x3F);
    }
    if (c < min || c > 0x10FFFF || (c >= 0xD800 && c <= 0xDFFF)) return false;
    i += k + 1;
  }
  return true;
}

static char resp[1 << 20];

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size > FUZZ_MAX_INPUT) return 0;
  /* An answer to HEAD has no body: bytes after its headers are the answer
   * to whatever the connection read next (a pipelined request, or garbage
   * libmicrohttpd answers itself), not this answer's body. (The request
   * starts as the input does: no placeholder starts with "HEAD ".) */
  const bool head = size >= 5 && memcmp(data, "HEAD ", 5) == 0;
  /* Placeholders of tests/corpus/http (whose cases are seeds here):
   * {SCENE} the harness scene's id, {AUTH} nothing (no token), {CL} the
   * length of what follows the first blank line. */
  char *req = malloc(size * 64 + 64);
  if (!req) return 0;
  size_t n = 0;
  bool has_cl = false;
  for (size_t i = 0; i < size;) {
    if (i + 7 <= size && memcmp(data + i, "{SCENE}", 7) == 0) {
      size_t il = strlen(fuzz_scene_id);
      memcpy(req + n, fuzz_scene_id, il);
      n += il;
      i += 7;
    } else if (i + 6 <= size && memcmp(data + i, "{AUTH}", 6) == 0) {
      i += 6;
    } else if (i + 4 <= size && memcmp(data + i, "{CL}", 4) == 0) {
      has_cl = true;
      memcpy(req + n, "{CL}", 4);
      n += 4;
      i += 4;
    } else {
      req[n++] = (char)data[i++];
    }
  }
  if (has_cl) {
    char *sep = memmem(req, n, "\r\n\r\n", 4);
    size_t body = sep ? n - (size_t)(sep + 4 - req) : 0;
    char num[24];
    int nl = snprintf(num, sizeof num, "%zu", body);
    char *out = malloc(n * 5 + 1); /* each 4-byte {CL} becomes at most 20 */
    if (!out) {
      free(req);
      return 0;
    }
    size_t m = 0;
    for (size_t i = 0; i < n;) {
      if (i + 4 <= n && memcmp(req + i, "{CL}", 4) == 0 && (!sep || req + i < sep)) {
        memcpy(out + m, num, (size_t)nl);
        m += (size_t)nl;
        i += 4;
      } else {
        out[m++] = req[i++];
      }
    }
    free(req);
    req = out;
    n = m;
  }
  size_t got = exchange(req, n, resp, sizeof resp);
  free(req);
  if (got > 0) {
    FUZZ_CHECK(got >= 12 && memcmp(resp, "HTTP/1.", 7) == 0, "not an HTTP answer: %.80s", resp);
    char *hdr_end = strstr(resp, "\r\n\r\n");
    if (hdr_end && !lax && !head) {
      *hdr_end = '\0';
      bool problem = strcasestr(resp, "\r\ncontent-type: application/problem+json") != NULL;
      bool chunked = strcasestr(resp, "\r\ntransfer-encoding: chunked") != NULL;
      *hdr_end = '\r';
      const char *body = hdr_end + 4;
      size_t blen = got - (size_t)(body - resp);
      if (problem && !chunked && blen > 0) {
        FUZZ_CHECK(utf8_valid((const unsigned char *)body, blen),
                   "a problem+json body that is not UTF-8: %.300s", body);
        cJSON *j = cJSON_ParseWithLength(body, blen);
        FUZZ_CHECK(j != NULL, "a problem+json body that is not JSON: %.300s", body);
        cJSON_Delete(j);
      }
    }
  }
  /* Still alive. */
  static const char live[] = "GET /v1/health/live HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
  char small[4096];
  /* Each exchange waits 1 s; on a loaded machine (an ASan build beside
   * other work) a live daemon can be slower than that, so an empty answer
   * is retried for up to 10 s before it counts as a dead daemon. */
  got = 0;
  for (int attempt = 0; attempt < 10 && got == 0; attempt++)
    got = exchange(live, sizeof live - 1, small, sizeof small);
  FUZZ_CHECK(got >= 12 && memcmp(small + 9, "200", 3) == 0, "health/live after the input: %.80s", small);
  return 0;
}
