/* Error detail carried next to an rsw_status: what went wrong and where
 * (JSON pointer, XML file:line, parameter key, command-line flag). */
#ifndef RSW_CORE_ERROR_H
#define RSW_CORE_ERROR_H

#include "raysweep/status.h"
#include <stdarg.h>

typedef struct rsw_err {
  rsw_status code;
  char where[256]; /* "/shapes/0/bsdf" or "scene.xml:12" or "" */
  char msg[768];
} rsw_err;

/* Record an error and return its code, so callers can "report and return"
 * in one statement:  return rsw_fail(err, RSW_ERR_TYPE, loc, "...", ...);
 * err may be NULL (then only the code is returned). The first error
 * recorded wins: later calls do not overwrite a set error. */
rsw_status rsw_fail(rsw_err *err, rsw_status code, const char *where, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));

/* Clear an error record. */
void rsw_err_clear(rsw_err *err);

/* Format "where: message" (or just the message) into buf. */
const char *rsw_err_format(const rsw_err *err, char *buf, unsigned long len);

#endif
