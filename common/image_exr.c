/* OpenEXR reading and writing through the OpenEXR Core C API.
 *
 * This is the only file in the server that includes openexr.h. We give the
 * library our own stream functions (pread/pwrite on a descriptor we own)
 * rather than its default file I/O, for two reasons: the default file
 * implementation keeps its handle in the context's user_data slot, which
 * is where our stream (and the first error message the library reports)
 * lives; and it lets the writer own the temporary file and the final
 * rename(). */
#include "image_exr.h"

#include <errno.h>
#include <fcntl.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* Via the OpenEXR/ prefix: the headers include each other with quotes,
 * so no -I/usr/include/OpenEXR is needed. */
#include <OpenEXR/openexr.h>

/* ---- float16 <-> float32 --------------------------------------------------
 * IEEE 754 binary16: 1 sign, 5 exponent (bias 15), 10 mantissa bits. */

/* Round to nearest even. Overflow (|f| >= 65520, the midpoint between the
 * largest half 65504 and 2^16) gives inf; NaN stays a quiet NaN. */
static uint16_t half_from_float(float f) {
  uint32_t u;
  memcpy(&u, &f, sizeof u);
  uint32_t sign = u & 0x80000000u;
  u ^= sign;
  uint16_t h;
  if (u >= 0x47800000u) { /* |f| >= 2^16, inf or NaN */
    h = u > 0x7f800000u ? 0x7e00u : 0x7c00u;
  } else if (u < 0x38800000u) { /* |f| < 2^-14: half subnormal or zero */
    /* Adding 0.5f aligns the float's mantissa so that its low bits are the
     * half's subnormal mantissa (2^-24 units), rounded by the FPU (nearest
     * even); subtracting 0.5f's bit pattern leaves those bits. */
    float a;
    memcpy(&a, &u, sizeof a);
    a += 0.5f;
    uint32_t r;
    memcpy(&r, &a, sizeof r);
    h = (uint16_t)(r - 0x3f000000u);
  } else {
    /* Rebias the exponent (127 -> 15) and round the 13 dropped mantissa
     * bits to nearest even; a carry out of the mantissa bumps the exponent,
     * up to inf, which is right. */
    uint32_t odd = (u >> 13) & 1u;
    u += ((uint32_t)(15 - 127) << 23) + 0xfffu + odd;
    h = (uint16_t)(u >> 13);
  }
  return (uint16_t)(h | (sign >> 16));
}

static float float_from_half(uint16_t h) {
  uint32_t sign = (uint32_t)(h & 0x8000u) << 16;
  uint32_t e = (h >> 10) & 0x1fu, m = h & 0x3ffu;
  uint32_t u;
  if (e == 0) { /* zero or subnormal: m 2^-24 */
    float f = (float)m * 0x1p-24f;
    memcpy(&u, &f, sizeof u);
    u |= sign;
  } else if (e == 31) {
    u = sign | 0x7f800000u | (m << 13);
  } else {
    u = sign | ((e + 127 - 15) << 23) | (m << 13);
  }
  float f;
  memcpy(&f, &u, sizeof f);
  return f;
}

/* ---- stream callbacks ---------------------------------------------------- */

/* Where the library's bytes go or come from: a descriptor (fd >= 0), or,
 * for exr_encode_image, a growable memory buffer (fd < 0), or, for
 * exr_decode_image, borrowed bytes (src). */
typedef struct exr_stream {
  int fd;
  char msg[512]; /* first message the library reported, or "" */
  uint8_t *mem;  /* memory sink: malloc'ed bytes, mem_len of them valid */
  size_t mem_len, mem_cap;
  const uint8_t *src; /* memory source (fd < 0): src_len bytes */
  size_t src_len;
} exr_stream;

/* The stream of the library call running on this thread, for the error
 * handler. The handler must not ask the context for its user data: it is
 * called with the context's mutex held (e.g. exr_write_header reporting a
 * failed write, exr_encoding_run a failed allocation), and
 * exr_get_user_data takes that mutex again; the non-recursive lock never
 * returned (issue 13: a full disk or an allocation failure hung the
 * render and the request forever). The library calls the handler
 * synchronously on the caller's thread, so a thread-local pointer set
 * around our calls into it is the context's stream. */
static _Thread_local exr_stream *t_stream;

static void stream_error_handler(exr_const_context_t ctxt, exr_result_t code, const char *msg) {
  (void)ctxt;
  exr_stream *st = t_stream;
  if (!st) return;
  if (st->msg[0]) return; /* the first error is the cause; keep it */
  snprintf(st->msg, sizeof st->msg, "%s [%s]", msg ? msg : "", exr_get_error_code_as_string(code));
}

static int64_t stream_read(exr_const_context_t ctxt, void *ud, void *buffer, uint64_t sz, uint64_t offset,
                           exr_stream_error_func_ptr_t error_cb) {
  exr_stream *st = ud;
  uint8_t *p = buffer;
  uint64_t done = 0;
  if (offset > (uint64_t)INT64_MAX || sz > (uint64_t)INT64_MAX - offset) {
    error_cb(ctxt, EXR_ERR_READ_IO, "read past any possible file end");
    return -1;
  }
  if (st->fd < 0) { /* a memory source: what is there of [offset, offset + sz) */
    if (offset >= st->src_len) return 0;
    done = sz < st->src_len - offset ? sz : st->src_len - offset;
    memcpy(p, st->src + offset, (size_t)done);
    return (int64_t)done;
  }
  while (done < sz) {
    ssize_t n = pread(st->fd, p + done, (size_t)(sz - done), (off_t)(offset + done));
    if (n < 0) {
      if (errno == EINTR) continue;
      error_cb(ctxt, EXR_ERR_READ_IO, "read at byte %llu failed: %s", (unsigned long long)(offset + done),
               strerror(errno));
      return -1;
    }
    if (n == 0) break; /* end of file: the library reports the short read */
    done += (uint64_t)n;
  }
  return (int64_t)done;
}

static int64_t stream_size(exr_const_context_t ctxt, void *ud) {
  exr_stream *st = ud;
  struct stat sb;
  if (st->fd < 0) return (int64_t)st->src_len;
  if (fstat(st->fd, &sb) != 0) return -1;
  return (int64_t)sb.st_size;
}

/* Memory sink: the library writes at increasing offsets (and patches the
 * chunk offset table behind the header at the end), so grow by doubling up
 * to the largest image EXR_MAX_SAMPLES allows plus headroom for headers. */
static int64_t mem_write(exr_const_context_t ctxt, exr_stream *st, const uint8_t *p, uint64_t sz,
                         uint64_t offset, exr_stream_error_func_ptr_t error_cb) {
  const uint64_t cap_max = (uint64_t)EXR_MAX_SAMPLES * 4 + ((uint64_t)1 << 24);
  if (offset + sz > cap_max) {
    error_cb(ctxt, EXR_ERR_WRITE_IO, "in-memory EXR would exceed %llu bytes", (unsigned long long)cap_max);
    return -1;
  }
  size_t end = (size_t)(offset + sz);
  if (end > st->mem_cap) {
    size_t cap = st->mem_cap ? st->mem_cap : 4096;
    while (cap < end) cap *= 2;
    uint8_t *q = realloc(st->mem, cap);
    if (!q) {
      error_cb(ctxt, EXR_ERR_OUT_OF_MEMORY, "no memory for %zu EXR bytes", cap);
      return -1;
    }
    st->mem = q;
    st->mem_cap = cap;
  }
  if (offset > st->mem_len) /* a gap the library fills later: zero it */
    memset(st->mem + st->mem_len, 0, (size_t)offset - st->mem_len);
  memcpy(st->mem + offset, p, (size_t)sz);
  if (end > st->mem_len) st->mem_len = end;
  return (int64_t)sz;
}

static int64_t stream_write(exr_const_context_t ctxt, void *ud, const void *buffer, uint64_t sz,
                            uint64_t offset, exr_stream_error_func_ptr_t error_cb) {
  exr_stream *st = ud;
  const uint8_t *p = buffer;
  uint64_t done = 0;
  if (offset > (uint64_t)INT64_MAX || sz > (uint64_t)INT64_MAX - offset) {
    error_cb(ctxt, EXR_ERR_WRITE_IO, "write past any possible file end");
    return -1;
  }
  if (st->fd < 0) return mem_write(ctxt, st, p, sz, offset, error_cb);
  while (done < sz) {
    ssize_t n = pwrite(st->fd, p + done, (size_t)(sz - done), (off_t)(offset + done));
    if (n < 0) {
      if (errno == EINTR) continue;
      error_cb(ctxt, EXR_ERR_WRITE_IO, "write at byte %llu failed: %s", (unsigned long long)(offset + done),
               strerror(errno));
      return -1;
    }
    done += (uint64_t)n;
  }
  return (int64_t)done;
}

static exr_context_initializer_t stream_init(exr_stream *st) {
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.error_handler_fn = stream_error_handler;
  init.user_data = st;
  init.read_fn = stream_read;
  init.size_fn = stream_size;
  init.write_fn = stream_write;
  return init;
}

/* Report a library failure: "<what>: <library message> [EXR_ERR_...]". */
static rsw_status exr_fail(rsw_err *err, rsw_status code, const char *path, const exr_stream *st,
                           exr_result_t rv, const char *what) {
  if (st->msg[0]) return rsw_fail(err, code, path, "%s: %s", what, st->msg);
  return rsw_fail(err, code, path, "%s: %s [%s]", what, exr_get_default_error_message(rv),
                  exr_get_error_code_as_string(rv));
}

/* ---- writing ------------------------------------------------------------- */

/* What the chunk writer needs besides the pipeline: the writable context
 * (the pipeline only holds a const one). */
typedef struct chunk_sink {
  exr_context_t ctx;
} chunk_sink;

/* The pipeline's write step, replacing the library's default one.
 *
 * A reader decides that a chunk is stored raw when its packed size equals
 * its unpacked size (OpenEXR Core and the C++ library alike), and the
 * writer is meant to store the raw bytes whenever compression does not make
 * them smaller. Debian's OpenEXR 3.1.5 falls back to raw only when the ZIP
 * output is strictly larger: a chunk that deflates to exactly its raw size
 * is stored as zlib bytes that every reader then takes as pixels (OpenEXR
 * issue #2306, fixed upstream by PR #2307). So whenever the compressed
 * chunk is not smaller than the packed one we write the packed (raw)
 * bytes ourselves; the ZIP encoder leaves packed_buffer untouched (it
 * reorders into a scratch buffer). With NONE there is no compress step
 * and compressed_buffer is packed_buffer already. */
static exr_result_t write_chunk_raw_unless_smaller(exr_encode_pipeline_t *enc) {
  const chunk_sink *sink = enc->encoding_user_data;
  const void *bytes = enc->compressed_buffer;
  uint64_t n = enc->compressed_bytes;
  if (n >= enc->packed_bytes) {
    bytes = enc->packed_buffer;
    n = enc->packed_bytes;
  }
  return exr_write_scanline_chunk(sink->ctx, enc->part_index, enc->chunk.start_y, bytes, n);
}

/* Encode every scanline chunk of part 0 from the HWC buffer `pix`
 * (elem_size bytes a sample, of pixel type ptype). */
static exr_result_t write_chunks(exr_context_t ctx, int width, int height, int n_channels,
                                 const char *const *channel_names, const uint8_t *pix, size_t elem_size,
                                 exr_pixel_type_t ptype) {
  int32_t lines = 0;
  exr_result_t rv = exr_get_scanlines_per_chunk(ctx, 0, &lines);
  if (rv != EXR_ERR_SUCCESS) return rv;
  if (lines < 1) return EXR_ERR_INVALID_ARGUMENT;
  exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
  chunk_sink sink = {.ctx = ctx};
  bool started = false;
  size_t pixel_stride = (size_t)n_channels * elem_size;
  for (int y = 0; y < height && rv == EXR_ERR_SUCCESS; y += lines) {
    exr_chunk_info_t cinfo;
    rv = exr_write_scanline_chunk_info(ctx, 0, y, &cinfo);
    if (rv != EXR_ERR_SUCCESS) break;
    rv = started ? exr_encoding_update(ctx, 0, &cinfo, &enc) : exr_encoding_initialize(ctx, 0, &cinfo, &enc);
    if (rv != EXR_ERR_SUCCESS) break;
    for (int c = 0; c < enc.channel_count; c++) {
      exr_coding_channel_info_t *ch = &enc.channels[c];
      int idx = 0;
      while (idx < n_channels && strcmp(channel_names[idx], ch->channel_name) != 0) idx++;
      if (idx == n_channels) return EXR_ERR_INVALID_ARGUMENT;
      ch->user_data_type = (uint16_t)ptype;
      ch->user_bytes_per_element = (int16_t)elem_size;
      ch->user_pixel_stride = (int32_t)pixel_stride;
      ch->user_line_stride = (int32_t)(pixel_stride * (size_t)width);
      ch->encode_from_ptr = pix + ((size_t)y * (size_t)width * (size_t)n_channels + (size_t)idx) * elem_size;
    }
    if (!started) {
      rv = exr_encoding_choose_default_routines(ctx, 0, &enc);
      if (rv != EXR_ERR_SUCCESS) break;
      /* exr_encoding_initialize zeroes the pipeline and exr_encoding_update
       * keeps these two, so they are set once. */
      enc.encoding_user_data = &sink;
      enc.write_fn = write_chunk_raw_unless_smaller;
      started = true;
    }
    rv = exr_encoding_run(ctx, 0, &enc);
  }
  exr_result_t drv = exr_encoding_destroy(ctx, &enc);
  return rv != EXR_ERR_SUCCESS ? rv : drv;
}

static rsw_status check_write_args(const char *path, int width, int height, int n_channels,
                                   const char *const *channel_names, const float *data, const exr_meta *meta,
                                   rsw_err *err) {
  const char *where = path ? path : "(null)";
  if (!path || !path[0]) return rsw_fail(err, RSW_ERR_INVALID, "", "EXR output path is empty");
  if (width < 1 || height < 1)
    return rsw_fail(err, RSW_ERR_INVALID, where, "image size %d x %d must be at least 1 x 1", width, height);
  if (n_channels < 1 || n_channels > EXR_MAX_CHANNELS)
    return rsw_fail(err, RSW_ERR_INVALID, where, "channel count %d outside [1, %d]", n_channels,
                    EXR_MAX_CHANNELS);
  if ((size_t)width * (size_t)height > EXR_MAX_SAMPLES / (size_t)n_channels)
    return rsw_fail(err, RSW_ERR_LIMIT, where, "image %d x %d x %d exceeds %zu samples", width, height,
                    n_channels, EXR_MAX_SAMPLES);
  if (!channel_names || !data) return rsw_fail(err, RSW_ERR_INVALID, where, "no channel names or pixel data");
  for (int c = 0; c < n_channels; c++) {
    const char *nm = channel_names[c];
    if (!nm || !nm[0] || strlen(nm) > 255)
      return rsw_fail(err, RSW_ERR_INVALID, where, "channel %d needs a name of 1 to 255 characters", c);
    for (int d = 0; d < c; d++)
      if (strcmp(channel_names[d], nm) == 0)
        return rsw_fail(err, RSW_ERR_INVALID, where, "channel name \"%s\" given twice", nm);
  }
  if (meta && meta->count && !meta->entries)
    return rsw_fail(err, RSW_ERR_INVALID, where, "metadata list is NULL");
  for (size_t i = 0; meta && i < meta->count; i++)
    if (!meta->entries[i].key || !meta->entries[i].key[0] || !meta->entries[i].value)
      return rsw_fail(err, RSW_ERR_INVALID, where, "metadata entry %zu needs a key and a value", i);
  return RSW_OK;
}

/* Write the whole file (header, chunks, offset table) through st, which
 * is a descriptor or a memory sink. label names the output in errors and is
 * what the library is told the file is called. */
static rsw_status write_to_stream(exr_stream *st, const char *label, int width, int height, int n_channels,
                                  const char *const *channel_names, const float *data, bool half,
                                  const exr_meta *meta, rsw_err *err) {
  size_t n_samples = (size_t)width * (size_t)height * (size_t)n_channels;
  uint16_t *halves = NULL;
  if (half) {
    halves = malloc(n_samples * sizeof *halves);
    if (!halves) return rsw_fail(err, RSW_ERR_NOMEM, label, "no memory for %zu float16 samples", n_samples);
    for (size_t i = 0; i < n_samples; i++) halves[i] = half_from_float(data[i]);
  }

  exr_stream *outer = t_stream;
  t_stream = st;
  exr_context_initializer_t init = stream_init(st);
  exr_context_t ctx = NULL;
  const char *what = "cannot start EXR file";
  exr_result_t rv = exr_start_write(&ctx, label, EXR_WRITE_FILE_DIRECTLY, &init);
  int part = 0;
  if (rv == EXR_ERR_SUCCESS) {
    what = "cannot define EXR header";
    rv = exr_add_part(ctx, NULL, EXR_STORAGE_SCANLINE, &part);
  }
  if (rv == EXR_ERR_SUCCESS)
    rv = exr_initialize_required_attr_simple(
        ctx, part, width, height, meta && meta->uncompressed ? EXR_COMPRESSION_NONE : EXR_COMPRESSION_ZIP);
  for (int c = 0; c < n_channels && rv == EXR_ERR_SUCCESS; c++)
    rv = exr_add_channel(ctx, part, channel_names[c], half ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT,
                         EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1);
  for (size_t i = 0; meta && i < meta->count && rv == EXR_ERR_SUCCESS; i++) {
    what = "cannot add EXR metadata";
    rv = exr_attr_set_string(ctx, part, meta->entries[i].key, meta->entries[i].value);
  }
  if (rv == EXR_ERR_SUCCESS) {
    what = "cannot write EXR header";
    rv = exr_write_header(ctx);
  }
  if (rv == EXR_ERR_SUCCESS) {
    what = "cannot write EXR pixels";
    rv = half ? write_chunks(ctx, width, height, n_channels, channel_names, (const uint8_t *)halves, 2,
                             EXR_PIXEL_HALF)
              : write_chunks(ctx, width, height, n_channels, channel_names, (const uint8_t *)data, 4,
                             EXR_PIXEL_FLOAT);
  }
  if (ctx) {
    /* exr_finish writes the chunk offset table; its failure is a failure
     * of the whole write. */
    exr_result_t frv = exr_finish(&ctx);
    if (rv == EXR_ERR_SUCCESS && frv != EXR_ERR_SUCCESS) {
      what = "cannot finish EXR file";
      rv = frv;
    }
  }
  t_stream = outer;
  free(halves);
  if (rv != EXR_ERR_SUCCESS) return exr_fail(err, RSW_ERR_IO, label, st, rv, what);
  return RSW_OK;
}

rsw_status exr_write_image(const char *path, int width, int height, int n_channels,
                           const char *const *channel_names, const float *data, bool half,
                           const exr_meta *meta, rsw_err *err) {
  rsw_status s = check_write_args(path, width, height, n_channels, channel_names, data, meta, err);
  if (s != RSW_OK) return s;

  char tmp[4096];
  int n = snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid());
  if (n < 0 || (size_t)n >= sizeof tmp)
    return rsw_fail(err, RSW_ERR_INVALID, path, "EXR output path too long");
  exr_stream st = {.fd = -1};
  st.fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (st.fd < 0) {
    int e = errno;
    return rsw_fail(err, RSW_ERR_IO, path, "cannot create %s: %s", tmp, strerror(e));
  }
  s = write_to_stream(&st, path, width, height, n_channels, channel_names, data, half, meta, err);
  if (s != RSW_OK) {
    close(st.fd);
    unlink(tmp);
    return s;
  }
  if (close(st.fd) != 0) {
    int e = errno;
    unlink(tmp);
    return rsw_fail(err, RSW_ERR_IO, path, "cannot close %s: %s", tmp, strerror(e));
  }
  if (rename(tmp, path) != 0) {
    int e = errno;
    unlink(tmp);
    return rsw_fail(err, RSW_ERR_IO, path, "cannot rename %s over it: %s", tmp, strerror(e));
  }
  return RSW_OK;
}

rsw_status exr_encode_image(int width, int height, int n_channels, const char *const *names,
                            const float *data, bool half, const exr_meta *meta, void **bytes_out,
                            size_t *len_out, rsw_err *err) {
  const char *label = "(EXR in memory)";
  if (!bytes_out || !len_out) return rsw_fail(err, RSW_ERR_INVALID, label, "no output pointers");
  rsw_status s = check_write_args(label, width, height, n_channels, names, data, meta, err);
  if (s != RSW_OK) return s;
  exr_stream st = {.fd = -1};
  s = write_to_stream(&st, label, width, height, n_channels, names, data, half, meta, err);
  if (s != RSW_OK) {
    free(st.mem);
    return s;
  }
  *bytes_out = st.mem;
  *len_out = st.mem_len;
  return RSW_OK;
}

/* ---- reading ------------------------------------------------------------- */

/* Where one channel's samples land while decoding: a plane of the image's
 * size in the file's own pixel type, converted to float afterwards (we do
 * the conversion ourselves so every type takes the same path). */
typedef struct plane {
  uint8_t *p;
  int bpe; /* bytes a sample: 2 (HALF) or 4 (FLOAT, UINT) */
  exr_pixel_type_t type;
} plane;

/* Decode one chunk whose top-left pixel is (x0, y0) of the data window. */
static exr_result_t decode_chunk(exr_context_t ctx, const exr_chunk_info_t *ci, exr_decode_pipeline_t *dec,
                                 bool *started, const exr_attr_chlist_t *chl, plane *planes, int width,
                                 int height, int64_t x0, int64_t y0) {
  exr_result_t rv =
      *started ? exr_decoding_update(ctx, 0, ci, dec) : exr_decoding_initialize(ctx, 0, ci, dec);
  if (rv != EXR_ERR_SUCCESS) return rv;
  for (int c = 0; c < dec->channel_count; c++) {
    exr_coding_channel_info_t *ch = &dec->channels[c];
    int idx = 0;
    while (idx < chl->num_channels && strcmp(chl->entries[idx].name.str, ch->channel_name) != 0) idx++;
    if (idx == chl->num_channels) return EXR_ERR_CORRUPT_CHUNK;
    if (x0 < 0 || y0 < 0 || ch->width < 0 || ch->height < 0 || x0 + ch->width > width ||
        y0 + ch->height > height)
      return EXR_ERR_CORRUPT_CHUNK;
    const plane *pl = &planes[idx];
    ch->user_data_type = (uint16_t)pl->type;
    ch->user_bytes_per_element = (int16_t)pl->bpe;
    ch->user_pixel_stride = pl->bpe;
    ch->user_line_stride = pl->bpe * width;
    ch->decode_to_ptr = pl->p + ((size_t)y0 * (size_t)width + (size_t)x0) * (size_t)pl->bpe;
  }
  if (!*started) {
    rv = exr_decoding_choose_default_routines(ctx, 0, dec);
    if (rv != EXR_ERR_SUCCESS) return rv;
    *started = true;
  }
  return exr_decoding_run(ctx, 0, dec);
}

static exr_result_t decode_all(exr_context_t ctx, exr_storage_t storage, const exr_attr_box2i_t *dw,
                               const exr_attr_chlist_t *chl, plane *planes, int width, int height) {
  exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
  bool started = false;
  exr_result_t rv = EXR_ERR_SUCCESS;
  if (storage == EXR_STORAGE_SCANLINE) {
    int32_t lines = 0;
    rv = exr_get_scanlines_per_chunk(ctx, 0, &lines);
    if (rv == EXR_ERR_SUCCESS && lines < 1) rv = EXR_ERR_INVALID_ATTR;
    for (int64_t y = dw->min.y; rv == EXR_ERR_SUCCESS && y <= dw->max.y; y += lines) {
      exr_chunk_info_t ci;
      rv = exr_read_scanline_chunk_info(ctx, 0, (int)y, &ci);
      if (rv == EXR_ERR_SUCCESS)
        rv = decode_chunk(ctx, &ci, &dec, &started, chl, planes, width, height, 0,
                          (int64_t)ci.start_y - dw->min.y);
    }
  } else {
    uint32_t tw = 0, th = 0;
    exr_tile_level_mode_t lm;
    exr_tile_round_mode_t rm;
    rv = exr_get_tile_descriptor(ctx, 0, &tw, &th, &lm, &rm);
    if (rv == EXR_ERR_SUCCESS && (tw == 0 || th == 0)) rv = EXR_ERR_INVALID_ATTR;
    int64_t nx = rv == EXR_ERR_SUCCESS ? ((int64_t)width + tw - 1) / tw : 0;
    int64_t ny = rv == EXR_ERR_SUCCESS ? ((int64_t)height + th - 1) / th : 0;
    /* Level (0, 0) is the full-resolution image in every level mode. */
    for (int64_t ty = 0; rv == EXR_ERR_SUCCESS && ty < ny; ty++)
      for (int64_t tx = 0; rv == EXR_ERR_SUCCESS && tx < nx; tx++) {
        exr_chunk_info_t ci;
        rv = exr_read_tile_chunk_info(ctx, 0, (int)tx, (int)ty, 0, 0, &ci);
        if (rv == EXR_ERR_SUCCESS)
          rv = decode_chunk(ctx, &ci, &dec, &started, chl, planes, width, height, tx * tw, ty * th);
      }
  }
  exr_result_t drv = exr_decoding_destroy(ctx, &dec);
  return rv != EXR_ERR_SUCCESS ? rv : drv;
}

static char *dup_n(const char *s, size_t n) {
  char *d = malloc(n + 1);
  if (d) {
    memcpy(d, s, n);
    d[n] = '\0';
  }
  return d;
}

/* Copy the header's string attributes into img. */
static rsw_status read_meta(exr_context_t ctx, exr_image *img, const char *path, rsw_err *err) {
  int32_t count = 0;
  if (exr_get_attribute_count(ctx, 0, &count) != EXR_ERR_SUCCESS || count <= 0) return RSW_OK;
  img->meta_keys = calloc((size_t)count, sizeof *img->meta_keys);
  img->meta_values = calloc((size_t)count, sizeof *img->meta_values);
  if (!img->meta_keys || !img->meta_values)
    return rsw_fail(err, RSW_ERR_NOMEM, path, "no memory for metadata");
  for (int32_t i = 0; i < count; i++) {
    const exr_attribute_t *a = NULL;
    if (exr_get_attribute_by_index(ctx, 0, EXR_ATTR_LIST_FILE_ORDER, i, &a) != EXR_ERR_SUCCESS || !a ||
        a->type != EXR_ATTR_STRING || !a->string || !a->name)
      continue;
    size_t len = a->string->length > 0 ? (size_t)a->string->length : 0;
    char *k = dup_n(a->name, strlen(a->name));
    char *v = dup_n(a->string->str ? a->string->str : "", a->string->str ? len : 0);
    if (!k || !v) {
      free(k);
      free(v);
      return rsw_fail(err, RSW_ERR_NOMEM, path, "no memory for metadata");
    }
    img->meta_keys[img->n_meta] = k;
    img->meta_values[img->n_meta] = v;
    img->n_meta++;
  }
  return RSW_OK;
}

/* Validate the header and fill img's size and channel names. */
static rsw_status read_header(exr_context_t ctx, const exr_stream *st, exr_storage_t *storage,
                              exr_attr_box2i_t *dw, const exr_attr_chlist_t **chl, exr_image *img,
                              const char *path, rsw_err *err) {
  exr_result_t rv = exr_get_storage(ctx, 0, storage);
  if (rv != EXR_ERR_SUCCESS) return exr_fail(err, RSW_ERR_FILE, path, st, rv, "bad EXR header");
  if (*storage != EXR_STORAGE_SCANLINE && *storage != EXR_STORAGE_TILED)
    return rsw_fail(err, RSW_ERR_UNSUPPORTED, path, "deep EXR images are not supported");
  rv = exr_get_data_window(ctx, 0, dw);
  if (rv == EXR_ERR_SUCCESS) rv = exr_get_channels(ctx, 0, chl);
  if (rv != EXR_ERR_SUCCESS || !*chl) return exr_fail(err, RSW_ERR_FILE, path, st, rv, "bad EXR header");
  int64_t w = (int64_t)dw->max.x - dw->min.x + 1;
  int64_t h = (int64_t)dw->max.y - dw->min.y + 1;
  int nc = (*chl)->num_channels;
  if (w < 1 || h < 1) return rsw_fail(err, RSW_ERR_FILE, path, "empty EXR data window");
  if (nc < 1 || nc > EXR_MAX_CHANNELS)
    return rsw_fail(err, RSW_ERR_UNSUPPORTED, path, "EXR has %d channels (need 1 to %d)", nc,
                    EXR_MAX_CHANNELS);
  if (w > (int64_t)EXR_MAX_SAMPLES || h > (int64_t)EXR_MAX_SAMPLES ||
      (size_t)w * (size_t)h > EXR_MAX_SAMPLES / (size_t)nc)
    return rsw_fail(err, RSW_ERR_LIMIT, path, "EXR image %lld x %lld x %d exceeds %zu samples", (long long)w,
                    (long long)h, nc, EXR_MAX_SAMPLES);
  img->channel_names = calloc((size_t)nc, sizeof *img->channel_names);
  if (!img->channel_names) return rsw_fail(err, RSW_ERR_NOMEM, path, "no memory for channels");
  img->n_channels = nc; /* so exr_image_free frees the names on failure */
  for (int c = 0; c < nc; c++) {
    const exr_attr_chlist_entry_t *e = &(*chl)->entries[c];
    if (e->x_sampling != 1 || e->y_sampling != 1)
      return rsw_fail(err, RSW_ERR_UNSUPPORTED, path, "EXR channel \"%s\" is subsampled (%d x %d)",
                      e->name.str, e->x_sampling, e->y_sampling);
    if (e->pixel_type != EXR_PIXEL_HALF && e->pixel_type != EXR_PIXEL_FLOAT &&
        e->pixel_type != EXR_PIXEL_UINT)
      return rsw_fail(err, RSW_ERR_FILE, path, "EXR channel \"%s\" has unknown pixel type %d", e->name.str,
                      (int)e->pixel_type);
    img->channel_names[c] = dup_n(e->name.str, e->name.length > 0 ? (size_t)e->name.length : 0);
    if (!img->channel_names[c]) return rsw_fail(err, RSW_ERR_NOMEM, path, "no memory for channels");
  }
  img->width = (int)w;
  img->height = (int)h;
  return RSW_OK;
}

/* Decode the pixels of part 0 into img->data (float HWC). */
static rsw_status read_pixels(exr_context_t ctx, const exr_stream *st, exr_storage_t storage,
                              const exr_attr_box2i_t *dw, const exr_attr_chlist_t *chl, exr_image *img,
                              const char *path, rsw_err *err) {
  size_t npix = (size_t)img->width * (size_t)img->height;
  int nc = img->n_channels;
  plane planes[EXR_MAX_CHANNELS];
  size_t native_bytes = 0;
  for (int c = 0; c < nc; c++) {
    planes[c].type = chl->entries[c].pixel_type;
    planes[c].bpe = planes[c].type == EXR_PIXEL_HALF ? 2 : 4;
    native_bytes += npix * (size_t)planes[c].bpe;
  }
  /* calloc: a channel the library leaves unfilled reads as zero rather
   * than uninitialised memory. */
  uint8_t *native = calloc(native_bytes, 1);
  img->data = malloc(npix * (size_t)nc * sizeof *img->data);
  if (!native || !img->data) {
    free(native);
    return rsw_fail(err, RSW_ERR_NOMEM, path, "no memory for a %d x %d x %d image", img->width, img->height,
                    nc);
  }
  size_t off = 0;
  for (int c = 0; c < nc; c++) {
    planes[c].p = native + off;
    off += npix * (size_t)planes[c].bpe;
  }
  exr_result_t rv = decode_all(ctx, storage, dw, chl, planes, img->width, img->height);
  if (rv != EXR_ERR_SUCCESS) {
    free(native);
    return exr_fail(err, RSW_ERR_FILE, path, st, rv, "corrupt or truncated EXR pixel data");
  }
  for (int c = 0; c < nc; c++) {
    const uint8_t *p = planes[c].p;
    float *o = img->data + c;
    for (size_t i = 0; i < npix; i++, o += nc) {
      if (planes[c].type == EXR_PIXEL_HALF) {
        uint16_t h;
        memcpy(&h, p + 2 * i, 2);
        *o = float_from_half(h);
      } else if (planes[c].type == EXR_PIXEL_FLOAT) {
        memcpy(o, p + 4 * i, 4);
      } else {
        uint32_t u;
        memcpy(&u, p + 4 * i, 4);
        *o = (float)u;
      }
    }
  }
  free(native);
  return RSW_OK;
}

/* Read the image of st (a file or borrowed bytes); label names it in errors. */
static rsw_status read_stream(exr_stream *st, const char *label, exr_image *out, rsw_err *err) {
  exr_context_initializer_t init = stream_init(st);
  init.write_fn = NULL;
  /* Fail on a damaged chunk table instead of guessing at the chunks. */
  init.flags |= EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
  exr_context_t ctx = NULL;
  exr_stream *outer = t_stream;
  t_stream = st;
  exr_result_t rv = exr_start_read(&ctx, label, &init);
  if (rv != EXR_ERR_SUCCESS) {
    rsw_status s = exr_fail(err, RSW_ERR_FILE, label, st, rv, "not a readable EXR file");
    if (ctx) exr_finish(&ctx);
    t_stream = outer;
    return s;
  }
  exr_image img = {0};
  exr_storage_t storage;
  exr_attr_box2i_t dw;
  const exr_attr_chlist_t *chl = NULL;
  rsw_status s = read_header(ctx, st, &storage, &dw, &chl, &img, label, err);
  if (s == RSW_OK) s = read_meta(ctx, &img, label, err);
  if (s == RSW_OK) s = read_pixels(ctx, st, storage, &dw, chl, &img, label, err);
  exr_finish(&ctx);
  t_stream = outer;
  if (s != RSW_OK) {
    exr_image_free(&img);
    return s;
  }
  *out = img;
  return RSW_OK;
}

rsw_status exr_read_image(const char *path, exr_image *out, rsw_err *err) {
  if (!path || !path[0]) return rsw_fail(err, RSW_ERR_INVALID, "", "EXR input path is empty");
  exr_stream st = {.fd = -1};
  st.fd = open(path, O_RDONLY | O_CLOEXEC);
  if (st.fd < 0) return rsw_fail(err, RSW_ERR_FILE, path, "cannot open EXR file: %s", strerror(errno));
  rsw_status s = read_stream(&st, path, out, err);
  close(st.fd);
  return s;
}

rsw_status exr_decode_image(const void *bytes, size_t len, const char *label, exr_image *out, rsw_err *err) {
  if (!label || !label[0]) label = "(EXR in memory)";
  if (!bytes || !len) return rsw_fail(err, RSW_ERR_FILE, label, "no EXR bytes");
  exr_stream st = {.fd = -1, .src = bytes, .src_len = len};
  return read_stream(&st, label, out, err);
}

int exr_image_channel(const exr_image *img, const char *name) {
  for (int c = 0; img && name && c < img->n_channels; c++)
    if (strcmp(img->channel_names[c], name) == 0) return c;
  return -1;
}

const char *exr_image_meta(const exr_image *img, const char *key) {
  for (size_t i = 0; img && key && i < img->n_meta; i++)
    if (strcmp(img->meta_keys[i], key) == 0) return img->meta_values[i];
  return NULL;
}

void exr_image_free(exr_image *img) {
  if (!img) return;
  if (img->channel_names)
    for (int c = 0; c < img->n_channels; c++) free(img->channel_names[c]);
  free(img->channel_names);
  for (size_t i = 0; i < img->n_meta; i++) {
    free(img->meta_keys[i]);
    free(img->meta_values[i]);
  }
  free(img->meta_keys);
  free(img->meta_values);
  free(img->data);
  memset(img, 0, sizeof *img);
}
