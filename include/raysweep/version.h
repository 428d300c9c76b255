/* raysweep's version, written in this one place. `raysweepd version`,
 * `raysweep --version`, the "version" of GET /v1, libraysweep's User-Agent
 * and raysweep.pc's Version (the Makefile reads the #define below) all take
 * it from here. */
#ifndef RAYSWEEP_VERSION_H
#define RAYSWEEP_VERSION_H

#define RSW_VERSION "0.2.0"

#endif
