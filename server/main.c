/* raysweepd: the radiometric computation daemon (placeholder entry until
 * the render subcommand lands). */
#include <stdio.h>

int main(int argc, char **argv) {
  (void)argc;
  (void)argv;
  fprintf(stderr, "raysweepd: no subcommand implemented yet\n");
  return 2;
}
