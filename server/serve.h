/* `raysweepd serve` (the HTTP daemon) and `raysweepd routes` (its routes
 * table), for main.c's command table. Both take argv with argv[0] the
 * command name and return the process exit status. */
#ifndef RSW_SERVE_H
#define RSW_SERVE_H

int cmd_serve(int argc, char **argv);
int cmd_routes(int argc, char **argv);

#define RSW_SERVE_USAGE                                                                                      \
  "serve [--listen HOST:PORT] [--threads N] [--scene FILE]... [--data-root DIR] [--blob-dir DIR] "           \
  "[--token-file F] [--max-body BYTES] [--max-queue N] [--result-ttl S] [--port-file F] "                    \
  "[--plugin-dir DIR] [--state-dir DIR] [--max-scene-bytes BYTES] [--max-result-bytes BYTES] "               \
  "[--max-connections N] [--header-timeout S] [--max-film-bytes BYTES] [--isa "                              \
  "auto|avx512|avx2|sse2|generic]"

#endif
