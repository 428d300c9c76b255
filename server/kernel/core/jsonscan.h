/* A check that cJSON cannot make: a "\u0000" escape in a JSON string.
 * cJSON decodes it to a NUL byte and every C string it hands out ends
 * there, so "a\u0000b.obj" would silently read as "a" (a file name, a
 * parameter key, a sensor id). Readers of JSON documents and request
 * bodies refuse such text instead, naming the member. */
#ifndef RSW_CORE_JSONSCAN_H
#define RSW_CORE_JSONSCAN_H

#include <stddef.h>

/* Byte offset of the first \u0000 escape (or raw NUL byte) inside a string
 * of the JSON text,
 * or -1 when there is none (text that is not JSON is scanned as far as it
 * reads like JSON). name (name_size bytes, may be NULL) receives the
 * member it belongs to: the string itself when it is an object key, else
 * the key of the closest member before it ("" at the top level); raw
 * text, at most name_size - 1 bytes, escapes as written. */
long json_find_nul_escape(const char *text, size_t len, char *name, size_t name_size);

/* Offset just past the first value of the text when it is an object or
 * an array (brackets matched outside strings), or -1 when the text does
 * not start (after blanks) with one or the value does not close. */
long json_value_end(const char *text, size_t len);

#endif
