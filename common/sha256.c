/* SHA-256 helpers (rsw_sha256.h) over OpenSSL's EVP interface. */
#include "rsw_sha256.h"

#include "rsw_file.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include <openssl/evp.h>

bool rsw_sha256_begin(rsw_sha256_ctx *c) {
  EVP_MD_CTX *md = EVP_MD_CTX_new();
  c->md = md;
  c->failed = !md || EVP_DigestInit_ex(md, EVP_sha256(), NULL) != 1;
  if (c->failed) { /* callers return at once on failure: nothing to end */
    EVP_MD_CTX_free(md);
    c->md = NULL;
  }
  return !c->failed;
}

void rsw_sha256_update(rsw_sha256_ctx *c, const void *data, size_t len) {
  if (c->failed || !len) return;
  if (EVP_DigestUpdate((EVP_MD_CTX *)c->md, data, len) != 1) c->failed = true;
}

bool rsw_sha256_end(rsw_sha256_ctx *c, unsigned char out[32]) {
  unsigned int len = 0;
  bool ok = !c->failed && EVP_DigestFinal_ex((EVP_MD_CTX *)c->md, out, &len) == 1 && len == 32;
  EVP_MD_CTX_free((EVP_MD_CTX *)c->md);
  c->md = NULL;
  return ok;
}

bool rsw_sha256(const void *data, size_t len, unsigned char out[32]) {
  rsw_sha256_ctx c;
  rsw_sha256_begin(&c);
  rsw_sha256_update(&c, data, len);
  return rsw_sha256_end(&c, out);
}

bool rsw_sha256_fd(int fd, unsigned char out[32]) {
  rsw_sha256_ctx c;
  rsw_sha256_begin(&c);
  unsigned char buf[1 << 16];
  int read_error = 0;
  for (;;) {
    ssize_t r = read(fd, buf, sizeof buf);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) read_error = errno ? errno : EIO;
    if (r <= 0) break;
    rsw_sha256_update(&c, buf, (size_t)r);
  }
  bool ok = rsw_sha256_end(&c, out);
  if (read_error) {
    errno = read_error;
    return false;
  }
  return ok;
}

bool rsw_sha256_file(const char *path, unsigned char out[32]) {
  int fd = rsw_open_regular(path, false);
  if (fd < 0) return false;
  bool ok = rsw_sha256_fd(fd, out);
  int saved = errno;
  close(fd);
  errno = saved;
  return ok;
}

void rsw_hex(const unsigned char *data, size_t n, char *out) {
  static const char digits[] = "0123456789abcdef";
  for (size_t i = 0; i < n; i++) {
    out[2 * i] = digits[data[i] >> 4];
    out[2 * i + 1] = digits[data[i] & 15];
  }
  out[2 * n] = '\0';
}

bool rsw_is_sha256_hex(const char *s) {
  if (!s) return false;
  size_t i = 0;
  for (; s[i]; i++) {
    if (i == 64) return false;
    if (!((s[i] >= '0' && s[i] <= '9') || (s[i] >= 'a' && s[i] <= 'f'))) return false;
  }
  return i == 64;
}
