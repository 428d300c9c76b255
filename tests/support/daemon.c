/* The daemon harness of the C tests (see daemon.h). */
#include "daemon.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

double tdaemon_now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void sleep_ms(int ms) {
  struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
  nanosleep(&ts, NULL);
}

const char *tdaemon_bin_dir(void) {
  const char *e = getenv("RSW_BIN_DIR");
  return e && *e ? e : "build/bin";
}

static char *slurp(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  size_t cap = 4096, n = 0;
  char *p = malloc(cap);
  while (p) {
    if (n + 1024 + 1 > cap) {
      char *q = realloc(p, cap *= 2);
      if (!q) {
        free(p);
        p = NULL;
        break;
      }
      p = q;
    }
    size_t k = fread(p + n, 1, cap - n - 1, f);
    n += k;
    if (k == 0) break;
  }
  fclose(f);
  if (p) p[n] = '\0';
  return p;
}

char *tdaemon_log(const tdaemon *d) {
  return slurp(d->log);
}

bool tdaemon_start(tdaemon *d, const char *dir, const char *name, const char *const *extra,
                   double timeout_s) {
  memset(d, 0, sizeof *d);
  snprintf(d->name, sizeof d->name, "%s", name);
  char exe[512], port_file[256];
  snprintf(exe, sizeof exe, "%s/raysweepd", tdaemon_bin_dir());
  snprintf(port_file, sizeof port_file, "%s/%s.port", dir, name);
  snprintf(d->log, sizeof d->log, "%s/%s.log", dir, name);
  unlink(port_file);
  pid_t pid = fork();
  if (pid < 0) return false;
  if (pid == 0) {
    int fd = open(d->log, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      dup2(fd, 1);
      dup2(fd, 2);
      close(fd);
    }
    const char *argv[72];
    int n = 0;
    argv[n++] = exe;
    argv[n++] = "serve";
    argv[n++] = "--listen";
    argv[n++] = "127.0.0.1:0";
    argv[n++] = "--port-file";
    argv[n++] = port_file;
    for (int i = 0; extra && extra[i] && n < 70; i++) argv[n++] = extra[i];
    argv[n] = NULL;
    execv(exe, (char *const *)argv);
    _exit(127);
  }
  d->pid = pid;
  if (!(timeout_s > 0)) timeout_s = 20.0;
  double t0 = tdaemon_now();
  while (tdaemon_now() - t0 < timeout_s) {
    int st;
    if (waitpid(pid, &st, WNOHANG) == pid) {
      d->pid = 0;
      char *log = tdaemon_log(d);
      fprintf(stdout, "  daemon %s exited before listening: %s\n", name, log ? log : "");
      free(log);
      return false;
    }
    /* The port file is written whole with a final newline. */
    char *txt = slurp(port_file);
    int port = txt ? atoi(txt) : 0;
    bool done = txt && strchr(txt, '\n') != NULL;
    free(txt);
    if (port > 0 && (done || tdaemon_now() - t0 > 0.2)) {
      d->port = port;
      snprintf(d->base_url, sizeof d->base_url, "http://127.0.0.1:%d", port);
      return true;
    }
    sleep_ms(10);
  }
  kill(pid, SIGKILL);
  waitpid(pid, NULL, 0);
  d->pid = 0;
  fprintf(stdout, "  daemon %s: no port file after %.0f s\n", name, timeout_s);
  return false;
}

int tdaemon_stop(tdaemon *d, double limit_s, double *secs) {
  if (!d->pid) return -3;
  double t0 = tdaemon_now();
  kill(d->pid, SIGTERM);
  int st = 0, rc = -2;
  while (tdaemon_now() - t0 < limit_s) {
    if (waitpid(d->pid, &st, WNOHANG) == d->pid) {
      rc = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
      break;
    }
    sleep_ms(5);
  }
  if (secs) *secs = tdaemon_now() - t0;
  if (rc == -2) {
    kill(d->pid, SIGKILL);
    waitpid(d->pid, NULL, 0);
  }
  d->pid = 0;
  return rc;
}

int tdaemon_run(const char *const *args, char *errbuf, size_t len) {
  char exe[512];
  snprintf(exe, sizeof exe, "%s/raysweepd", tdaemon_bin_dir());
  int pipefd[2];
  if (pipe(pipefd)) return -2;
  pid_t pid = fork();
  if (pid < 0) {
    close(pipefd[0]);
    close(pipefd[1]);
    return -2;
  }
  if (pid == 0) {
    dup2(pipefd[1], 2);
    close(pipefd[0]);
    const char *argv[64];
    int n = 0;
    argv[n++] = exe;
    for (int i = 0; args[i] && n < 62; i++) argv[n++] = args[i];
    argv[n] = NULL;
    execv(exe, (char *const *)argv);
    _exit(127);
  }
  close(pipefd[1]);
  size_t got = 0;
  ssize_t r;
  while (len > 1 && (r = read(pipefd[0], errbuf + got, len - 1 - got)) != 0) {
    if (r < 0) {
      if (errno == EINTR) continue;
      break;
    }
    got += (size_t)r;
    if (got == len - 1) { /* full: drain the rest so the child never blocks */
      char sink[4096];
      while ((r = read(pipefd[0], sink, sizeof sink)) > 0 || (r < 0 && errno == EINTR)) {}
      break;
    }
  }
  if (len) errbuf[got] = '\0';
  close(pipefd[0]);
  int status;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {}
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

int tdaemon_connect(const tdaemon *d) {
  int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  struct sockaddr_in sin = {.sin_family = AF_INET, .sin_port = htons((uint16_t)d->port)};
  sin.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (connect(fd, (const struct sockaddr *)&sin, sizeof sin) != 0) {
    close(fd);
    return -1;
  }
  int one = 1;
  setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  return fd;
}

void thttp_resp_free(thttp_resp *r) {
  free(r->headers);
  free(r->body);
  memset(r, 0, sizeof *r);
}

const char *thttp_header(const thttp_resp *r, const char *name, char *out, size_t n) {
  if (!r->headers || !n) return NULL;
  size_t nl = strlen(name);
  for (const char *line = r->headers; line && *line;) {
    const char *eol = strstr(line, "\r\n");
    size_t ll = eol ? (size_t)(eol - line) : strlen(line);
    if (ll > nl && line[nl] == ':' && strncasecmp(line, name, nl) == 0) {
      const char *v = line + nl + 1;
      while (*v == ' ' || *v == '\t') v++;
      size_t vl = (size_t)(line + ll - v);
      if (vl >= n) vl = n - 1;
      memcpy(out, v, vl);
      out[vl] = '\0';
      return out;
    }
    line = eol ? eol + 2 : NULL;
  }
  return NULL;
}

static bool send_all(int fd, const char *p, size_t n) {
  while (n) {
    ssize_t k = send(fd, p, n, MSG_NOSIGNAL);
    if (k < 0 && errno == EINTR) continue;
    if (k <= 0) return false;
    p += k;
    n -= (size_t)k;
  }
  return true;
}

bool tdaemon_http(const tdaemon *d, const char *method, const char *path, const char *const *headers,
                  const void *body, size_t len, double timeout_s, thttp_resp *r) {
  memset(r, 0, sizeof *r);
  double t0 = tdaemon_now();
  int fd = tdaemon_connect(d);
  if (fd < 0) return false;
  size_t hcap = 1024 + strlen(path);
  for (int i = 0; headers && headers[i]; i++) hcap += strlen(headers[i]) + 2;
  char *req = malloc(hcap);
  if (!req) {
    close(fd);
    return false;
  }
  size_t hl = (size_t)snprintf(req, hcap, "%s %s HTTP/1.1\r\nHost: 127.0.0.1:%d\r\nConnection: close\r\n",
                               method, path, d->port);
  for (int i = 0; headers && headers[i]; i++)
    hl += (size_t)snprintf(req + hl, hcap - hl, "%s\r\n", headers[i]);
  if (body) hl += (size_t)snprintf(req + hl, hcap - hl, "Content-Length: %zu\r\n", len);
  hl += (size_t)snprintf(req + hl, hcap - hl, "\r\n");
  bool ok = send_all(fd, req, hl) && (!body || send_all(fd, body, len));
  free(req);
  size_t cap = 8192, n = 0;
  char *buf = malloc(cap);
  while (ok && buf) {
    double left = timeout_s - (tdaemon_now() - t0);
    if (left <= 0) {
      ok = false;
      break;
    }
    struct pollfd p = {.fd = fd, .events = POLLIN};
    int pr = poll(&p, 1, (int)(left * 1000) + 1);
    if (pr < 0 && errno == EINTR) continue;
    if (pr <= 0) {
      ok = false;
      break;
    }
    if (n + 4096 + 1 > cap) {
      char *q = realloc(buf, cap *= 2);
      if (!q) {
        ok = false;
        break;
      }
      buf = q;
    }
    ssize_t k = recv(fd, buf + n, cap - n - 1, 0);
    if (k < 0 && errno == EINTR) continue;
    if (k < 0) { /* a reset after a complete answer still counts */
      break;
    }
    if (k == 0) break;
    n += (size_t)k;
  }
  close(fd);
  r->secs = tdaemon_now() - t0;
  if (!buf) return false;
  buf[n] = '\0';
  char *end = strstr(buf, "\r\n\r\n");
  if (!ok || !end || strncmp(buf, "HTTP/1.", 7) != 0) {
    free(buf);
    return false;
  }
  r->status = atoi(buf + 9);
  size_t hlen = (size_t)(end - buf) + 2;
  r->headers = malloc(hlen + 1);
  size_t blen = n - (size_t)(end + 4 - buf);
  r->body = malloc(blen + 1);
  if (!r->headers || !r->body) {
    free(buf);
    thttp_resp_free(r);
    return false;
  }
  memcpy(r->headers, buf, hlen);
  r->headers[hlen] = '\0';
  memcpy(r->body, end + 4, blen);
  r->body[blen] = '\0';
  r->len = blen;
  free(buf);
  return true;
}
