/* SHA-256 for content addresses (scene ids, blob names, request digests),
 * shared by the daemon and libraysweep. OpenSSL's EVP interface does the
 * hashing; this header exposes no OpenSSL type. */
#ifndef RSW_COMMON_SHA256_H
#define RSW_COMMON_SHA256_H

#include <stdbool.h>
#include <stddef.h>

/* An incremental digest. begin() may fail (out of memory): then update()
 * and end() are no-ops and end() returns false. end() always releases. */
typedef struct rsw_sha256_ctx {
  void *md;
  bool failed;
} rsw_sha256_ctx;

bool rsw_sha256_begin(rsw_sha256_ctx *c);
void rsw_sha256_update(rsw_sha256_ctx *c, const void *data, size_t len);
bool rsw_sha256_end(rsw_sha256_ctx *c, unsigned char out[32]);

/* One-shot digests. rsw_sha256_file reads the file streamed (a regular
 * file only, opened without blocking: rsw_file.h); false on an open or
 * read error (errno tells) or when the digest cannot be made. */
bool rsw_sha256(const void *data, size_t len, unsigned char out[32]);
bool rsw_sha256_file(const char *path, unsigned char out[32]);
/* The digest of what is left to read from an open descriptor (read to its
 * end); false on a read error (errno tells). */
bool rsw_sha256_fd(int fd, unsigned char out[32]);

/* Lowercase hex of n bytes into out (2n + 1 chars). */
void rsw_hex(const unsigned char *data, size_t n, char *out);
/* True when s is exactly 64 lowercase hex digits. */
bool rsw_is_sha256_hex(const char *s);

#endif
