#include "rsw_error.h"

#include <stdio.h>
#include <string.h>

static const char *const status_msgs[] = {
#define RSW_MSG_(name, msg, http) msg,
    RSW_STATUS_LIST(RSW_MSG_)
#undef RSW_MSG_
};

static const char *const status_names[] = {
#define RSW_NAME_(name, msg, http) #name,
    RSW_STATUS_LIST(RSW_NAME_)
#undef RSW_NAME_
};

static const int status_http[] = {
#define RSW_HTTP_(name, msg, http) http,
    RSW_STATUS_LIST(RSW_HTTP_)
#undef RSW_HTTP_
};

const char *rsw_strerror(rsw_status s) {
  if ((unsigned)s >= RSW_STATUS_COUNT_) return "unknown status";
  return status_msgs[s];
}

const char *rsw_status_name(rsw_status s) {
  if ((unsigned)s >= RSW_STATUS_COUNT_) return "RSW_UNKNOWN";
  return status_names[s];
}

int rsw_status_http(rsw_status s) {
  if ((unsigned)s >= RSW_STATUS_COUNT_) return 500;
  return status_http[s];
}

rsw_status rsw_fail(rsw_err *err, rsw_status code, const char *where, const char *fmt, ...) {
  if (!err || err->code != RSW_OK) return code;
  err->code = code;
  snprintf(err->where, sizeof err->where, "%s", where ? where : "");
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(err->msg, sizeof err->msg, fmt, ap);
  va_end(ap);
  return code;
}

void rsw_err_clear(rsw_err *err) {
  if (!err) return;
  err->code = RSW_OK;
  err->where[0] = '\0';
  err->msg[0] = '\0';
}

const char *rsw_err_format(const rsw_err *err, char *buf, unsigned long len) {
  /* A message that already names its place, quoted ('KEY': a parameter
   * key), is not prefixed with it again. */
  char quoted[sizeof err->where + 2];
  snprintf(quoted, sizeof quoted, "'%s'", err->where);
  if (err->where[0] && !strstr(err->msg, quoted))
    snprintf(buf, len, "%s: %s", err->where, err->msg);
  else
    snprintf(buf, len, "%s", err->msg);
  return buf;
}
