#include "jsonscan.h"

#include <stdbool.h>
#include <string.h>

static void copy_name(char *name, size_t name_size, const char *s, size_t n) {
  if (!name || !name_size) return;
  if (n > name_size - 1) n = name_size - 1;
  memcpy(name, s, n);
  name[n] = '\0';
}

long json_find_nul_escape(const char *text, size_t len, char *name, size_t name_size) {
  const char *key = NULL; /* raw text of the last object key */
  size_t key_len = 0;
  if (name && name_size) name[0] = '\0';
  size_t i = 0;
  while (i < len) {
    if (text[i] != '"') {
      i++;
      continue;
    }
    /* A string from text[i] to its closing quote. */
    size_t start = i + 1, j = start;
    long nul_at = -1;
    while (j < len && text[j] != '"') {
      if (text[j] == '\\' && j + 1 < len) {
        if (text[j + 1] == 'u' && j + 5 < len && nul_at < 0 && text[j + 2] == '0' && text[j + 3] == '0' &&
            text[j + 4] == '0' && text[j + 5] == '0')
          nul_at = (long)j;
        j += 2;
      } else {
        if (text[j] == '\0' && nul_at < 0) nul_at = (long)j; /* a raw NUL byte cuts it too */
        j++;
      }
    }
    size_t end = j; /* the closing quote (or len) */
    size_t k = end + 1;
    while (k < len && (text[k] == ' ' || text[k] == '\t' || text[k] == '\n' || text[k] == '\r')) k++;
    bool is_key = k < len && text[k] == ':';
    if (nul_at >= 0) {
      if (is_key)
        copy_name(name, name_size, text + start, end - start);
      else if (key)
        copy_name(name, name_size, key, key_len);
      return nul_at;
    }
    if (is_key) {
      key = text + start;
      key_len = end - start;
    }
    i = end + 1;
  }
  return -1;
}

long json_value_end(const char *text, size_t len) {
  size_t i = 0;
  while (i < len && (text[i] == ' ' || text[i] == '\t' || text[i] == '\n' || text[i] == '\r')) i++;
  if (i >= len || (text[i] != '{' && text[i] != '[')) return -1;
  size_t depth = 0;
  for (; i < len; i++) {
    char c = text[i];
    if (c == '"') {
      for (i++; i < len && text[i] != '"'; i++)
        if (text[i] == '\\') i++;
      if (i >= len) return -1;
    } else if (c == '{' || c == '[') {
      depth++;
    } else if (c == '}' || c == ']') {
      if (--depth == 0) return (long)(i + 1);
    }
  }
  return -1;
}
