/* raysweep sweep and raysweep merge: what their files share. A sweep
 * directory holds one film per (context, sensor), in DIR/<context>/ or,
 * with --layout flat, in DIR itself (sweep_film_file), DIR/index.jsonl
 * (one line per film), DIR/sweep.json (the manifest: what the directory
 * is meant to hold) and, with --format nc, DIR/dataset.nc. With --format
 * dataset the films are in DIR/dataset.nc alone (no file per film).
 *
 *   cmd_sweep.c       the contexts (--contexts, --grid), the job, its films
 *   sweep_spread.c    --spread: the shards at once through a balancer, and
 *                     resuming an interrupted --spread run
 *   sweep_manifest.c  sweep.json, and --force (what an earlier sweep wrote)
 *   sweep_dir.c       index.jsonl, dataset.nc, context ids, file helpers
 *   sweep_pack.c      --format dataset: the films kept until dataset.nc
 *                     is built, and the spool a cut-off --spread resumes
 *   cmd_merge.c       raysweep merge (join shard directories) */
#ifndef RSW_CLI_SWEEP_H
#define RSW_CLI_SWEEP_H

#include <cjson/cJSON.h>
#include <dirent.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "cli.h"

/* DIR/sweep.json, written before the job is submitted and again when the
 * sweep ends:
 *   {"format": "raysweep-sweep/1", "sweep": FINGERPRINT, "scene": ID,
 *    "shard": [I, N], "contexts_total": T,
 *    "id_width": W | "ids": [every context id of the unsharded list],
 *    "job": JOB | null, "finished": BOOL, "incomplete": [context ids],
 *    "bundle_leads": [per context, its bundle group's first] (with --bundle),
 *    "bundle_shards": "rank" (with bundle_leads: group g, in the order of
 *      the groups' first contexts, is shard g mod N; absent, as written
 *      before this rule, a group is shard (its first context) mod N),
 *    "layout": "flat" (with --layout flat; absent: one directory per context),
 *    "output": "dataset" (with --format dataset: the films are in
 *      dataset.nc alone; absent: a file per film)}
 * FINGERPRINT is FNV-1a 64 over everything that defines the unsharded
 * sweep (scene, contexts file or grid, --set, --sensor, --spp, --seed,
 * --format, --quantities, --variance, --bundle but 1) and not over --shard, so every shard of one sweep carries the
 * same value. `merge` uses it to know which contexts a set of shard
 * directories must cover; `sweep --force` to know what an earlier sweep
 * wrote. "incomplete" lists contexts with a render that did not succeed.
 * The layout is not in the fingerprint: the films are the same either way,
 * so shards of one sweep may differ in it and still merge. */
#define MANIFEST_NAME   "sweep.json"
#define DATASET_NAME    "dataset.nc"
/* The journal of a --spread sweep (rsw_spread_opts.state_path): there
 * while the sweep is unfinished, removed when it completes. */
#define SPREAD_STATE    "sweep.spread.jsonl"
/* --format dataset --spread: the films delivered so far (sweep_pack.c),
 * there while the sweep is unfinished. */
#define FILM_SPOOL      "sweep.films"
#define MANIFEST_FORMAT "raysweep-sweep/1"

/* Where a sweep puts its films (--layout). */
typedef enum sweep_layout {
  SWEEP_LAYOUT_DIRS, /* DIR/<context>/<sensor>.<ext> (the default) */
  SWEEP_LAYOUT_FLAT  /* DIR/<context escaped>.<sensor>.<ext> */
} sweep_layout;

/* One context of the list being swept. */
typedef struct sweep_item {
  char id[72];
  bool has_wl;
  double wl;
  cJSON *params;       /* object or NULL, owned */
  cJSON *sensors;      /* array of strings or NULL, owned */
  cJSON *coords;       /* object or NULL, owned: the context's coords */
  long long spp, seed; /* -1: unset */
  long long group;     /* its "bundle_group" (the index of its group's first context), -1: none */
} sweep_item;

/* The contexts one shard sweeps. */
typedef struct sweep_list {
  sweep_item *items;
  size_t n, cap;
  size_t total; /* unsharded count */
  /* --contexts with ids in the file: the id of every context of the
   * unsharded list (NULL: numbered), so sweep.json can name the contexts
   * of the other shards. NULL when every id is numbered. */
  char **all_ids;
  int id_width;
  /* With bundles: per context of the unsharded list, the index of its
   * bundle group's first context, and its shard key (sweep_shard_of:
   * rsw_bundle_shard_keys); NULL without. */
  size_t *leads, *keys;
  long long seed; /* --seed (0 by default): the job seed, in sweep.json */
  bool dataset;   /* --format nc: DIR/dataset.nc besides the (JSON) films */
  bool pack;      /* --format dataset: DIR/dataset.nc alone (sweep_pack.c) */
  sweep_layout layout;
  const char *templates; /* --templates as compact JSON (borrowed), or NULL: part of the fingerprint */
} sweep_list;

/* One film of the index: its line (owned) and, for merge, the source. */
typedef struct index_entry {
  const char *context, *sensor; /* borrowed from line */
  cJSON *line;
  char *src; /* owned, merge only */
  size_t order;
  size_t input; /* merge: which input directory */
} index_entry;

/* DIR/sweep.json as read (manifest_read). */
typedef struct sweep_manifest {
  cJSON *root; /* owned */
  const char *sweep;
  size_t shard_i, shard_n, total;
  int id_width;
  size_t *leads;           /* owned: "bundle_leads", or NULL (every context its own) */
  size_t *keys;            /* owned: their shard keys (rsw_bundle_shard_keys), or NULL */
  const char **ids;        /* owned array of total ids (borrowed strings), or NULL: numbered */
  const char **incomplete; /* owned, sorted (strings borrowed from root) */
  size_t n_incomplete;
  bool finished;
  sweep_layout layout; /* "layout" (absent: dirs) */
  bool pack;           /* "output": "dataset" */
} sweep_manifest;

/* ---- sweep_dir.c -------------------------------------------------------- */

/* dir + "/" + name (malloc'd; NULL when out of memory). */
char *sweep_dir_file(const char *dir, const char *name);
/* Entries of a directory other than "." and "..": count, and the first. */
size_t sweep_dir_entries(DIR *d, char *first, size_t cap);
bool sweep_is_regular(const char *path);
/* v is a number holding an integer >= lo. */
bool sweep_json_is_int(const cJSON *v, double lo);
/* A relative path inside a sweep directory: no leading '/', no "..". */
bool sweep_safe_relative(const char *p);
/* Context ids "c00042": the width for a list of total contexts, and id
 * number index at that width. */
int sweep_id_width(size_t total);
void sweep_make_id(char out[72], int width, size_t index);
/* qsort/bsearch comparators: sweep_item pointers by id, index entries by
 * context, sensor and order, C strings. */
int sweep_cmp_item_id(const void *a, const void *b);
int sweep_cmp_entry(const void *a, const void *b);
int sweep_cmp_str(const void *a, const void *b);
/* DIR/index.jsonl: written sorted (e is sorted in place), read appending
 * to *e (input: which merge input DIR is). */
int sweep_write_index(const cli_ctx *ctx, const char *dir, index_entry *e, size_t n);
int sweep_read_index(const cli_ctx *ctx, const char *dir, size_t input, index_entry **e, size_t *n,
                     size_t *cap);
void sweep_entries_free(index_entry *e, size_t n);
/* The lines and sources of entries [from, to) (the array stays). */
void sweep_entries_free_range(index_entry *e, size_t from, size_t to);
/* The index line of film rel of result r (sorted: the sweep's items by id);
 * rel NULL: a film of the dataset alone ("dataset": "dataset.nc" in place
 * of "file"). */
cJSON *sweep_index_line(const cJSON *r, const char *c, const char *sn, const char *rel, sweep_item **sorted,
                        size_t n, const cJSON *job_params);
/* The films a dataset is built from stay in memory up to this many bytes
 * of pixels, then go to a file without a name in DIR
 * (rsw_dataset_set_store); RAYSWEEP_DATASET_MEMORY overrides it. */
#define SWEEP_DATASET_MEMORY ((unsigned long long)512 << 20)
/* d's film store in dir (SWEEP_DATASET_MEMORY or the environment's);
 * CLI_USAGE for a bad RAYSWEEP_DATASET_MEMORY, CLI_IO if dir takes no
 * file. */
int sweep_dataset_store(const cli_ctx *ctx, rsw_dataset *d, const char *dir);
/* The bytes of that (CLI_USAGE, said, for a bad RAYSWEEP_DATASET_MEMORY). */
int sweep_dataset_memory(const cli_ctx *ctx, unsigned long long *out);
/* DIR/dataset.nc from the films of index entries e (sorted): their files
 * (pack NULL), or the EXRs kept in pack. */
typedef struct film_pack film_pack;
int sweep_write_dataset(const cli_ctx *ctx, const char *dir, const index_entry *e, size_t n, bool has_seed,
                        long long seed, film_pack *pack);

/* ---- sweep_pack.c ------------------------------------------------------- */

/* One film of --format dataset: where the daemon's EXR lies in the pack's
 * store (its bytes are not kept in memory: the live dataset holds the
 * film decoded) and the film's channel order (its result's "channels"). */
typedef struct pack_film {
  char *context, *sensor;
  off_t off; /* the EXR's first byte in the store */
  size_t len;
  cJSON *channels; /* array of strings, or NULL */
  size_t seq;      /* order kept */
} pack_film;
struct film_pack {
  pack_film *f;
  size_t n, cap;
  bool sorted;
  /* The store the films' EXRs are appended to, read back only when the
   * dataset is built again (sweep_write_dataset): with --spread the spool
   * DIR/FILM_SPOOL, which a rerun reads; else a file of DIR without a
   * name (gone with the process). */
  int fd;
  off_t end;        /* the store's length */
  char *spool_path; /* the spool's, or NULL */
  /* The dataset the films go into as they arrive (sweep_pack.c): every
   * context of the sweep (items, borrowed) added first. */
  sweep_item **items;
  size_t n_items;
  rsw_dataset *live;
  bool live_ok; /* every context and film added so far was taken */
  size_t live_films;
};
/* Start a pack for the sweep's contexts (sorted by id, n of them; borrowed
 * until pack_close); spool: its store is DIR/FILM_SPOOL (created anew, or
 * with resume, its films read first), else a nameless file in DIR. */
int pack_open(const cli_ctx *ctx, film_pack *p, const char *dir, bool spool, bool resume, sweep_item **sorted,
              size_t n);
/* Add film f of p to d (its EXR read back from p's store;
 * rsw_dataset_add_film_exr, its channels in order). */
int pack_film_add_to(const film_pack *p, rsw_dataset *d, const pack_film *f);
/* The live dataset when it holds exactly the films of index entries e
 * (sorted) with their contexts' wavelengths, ready to write; else NULL
 * (build it again from the films). */
rsw_dataset *pack_live(film_pack *p, const index_entry *e, size_t n);
int pack_add(const cli_ctx *ctx, film_pack *p, const char *c, const char *sn, const cJSON *channels,
             const void *bytes, size_t len);
/* The film of (c, sn) (the last kept), or NULL. */
const pack_film *pack_find(film_pack *p, const char *c, const char *sn);
/* Free it; remove_spool: the sweep is done, the spool goes. */
void pack_close(film_pack *p, bool remove_spool);

/* --layout's value: dirs or flat; false for anything else. */
bool sweep_layout_from_name(const char *name, sweep_layout *out);
const char *sweep_layout_name(sweep_layout l);
/* The file of film (c, sn) in format fmt: rel (inside dir, as index.jsonl
 * names it) and path (dir/rel). dirs: c/sn.ext; flat: c with every '%' and
 * '.' written %25 and %2E, then '.', sn, '.', ext, so the first '.' ends
 * the context and no two (context, sensor) pairs share a name, nor does a
 * film share one with the directory's own files (index.jsonl, sweep.json,
 * dataset.nc, sweep.spread.jsonl: one dot, or not a film extension).
 * mkdir: create DIR/<c> (dirs). 0, or a CLI exit code after printing (a
 * name no file can have, a directory that cannot be made). */
int sweep_film_file(const cli_ctx *ctx, const char *dir, sweep_layout layout, const char *c, const char *sn,
                    cli_format fmt, bool mkdir, char *rel, size_t rel_cap, char *path, size_t path_cap);
/* The context whose flat film (or its temp file) name is: false when name
 * is no flat film's name. out: at least strlen(name) + 1 bytes. */
bool sweep_flat_context(const char *name, char *out);

/* ---- sweep_manifest.c --------------------------------------------------- */

/* The sweep's identity for merge and resume: the scene, the options that
 * shape its films, a --contexts file's bytes and --templates' JSON
 * (templates: compact JSON, or NULL). */
void sweep_fingerprint(const cmdline_args *a, const char *scene, const char *templates, char out[17]);
/* 0, or -1 when DIR has no sweep.json (errno ENOENT), or a CLI exit code
 * after printing. */
int manifest_read(const cli_ctx *ctx, const char *dir, sweep_manifest *m);
int manifest_write(const cli_ctx *ctx, const char *dir, const char *fingerprint, const char *scene,
                   size_t shard_i, size_t shard_n, const sweep_list *l, const char *job, bool finished,
                   const cJSON *incomplete);
void manifest_free(sweep_manifest *m);
/* The shard of the unsharded list's context k: its bundle group's rank
 * (keys[k], rsw_bundle_shard_keys; k itself without bundles) mod n, so
 * that a bundle group stays whole and the groups are dealt out in turn
 * (docs/cluster.md#shards-and-spectral-bundles). */
static inline size_t sweep_shard_of(const size_t *keys, size_t k, size_t n) {
  return (keys ? keys[k] : k) % n;
}
/* The id of context k of the unsharded list; whether it is incomplete. */
const char *manifest_id(const sweep_manifest *m, size_t k, char buf[72]);
bool manifest_incomplete(const sweep_manifest *m, const char *id);
/* Make -o DIR ready (created, empty, or with --force an earlier sweep
 * removed). */
int sweep_prepare_output(const cli_ctx *ctx, const char *dir, bool force);

/* ---- sweep_spread.c ----------------------------------------------------- */

/* DIR holds an unfinished --spread run of this sweep (rerun: resume);
 * *layout: the layout that run writes. */
bool sweep_spread_resumable(const char *dir, const char *fingerprint, sweep_layout *layout);
int sweep_run_spread(cli_ctx *ctx, const cmdline_args *a, int k_shards, bool resume, cli_format fmt,
                     double timeout, const sweep_list *l, sweep_item **sorted, const cJSON *job_params,
                     const rsw_contexts *x, const char *fingerprint, size_t shard_i, size_t shard_n);

#endif
