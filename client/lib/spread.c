/* rsw_spread_run: one job spread over several replicas behind a load
 * balancer that hashes the X-Raysweep-Shard header consistently
 * (docker/haproxy, docker/nginx). No state in the balancer: a shard's
 * routing key alone decides its replica, so the key is all a shard's
 * follow-up requests (events, results, films) need to find their job.
 *
 * Shard k holds contexts k, k+K, k+2K, ... (as `raysweep sweep --shard
 * k/K`); with spectral bundles, the bundle groups dealt out in turn
 * (the g-th group, in the order of their first contexts, to shard g mod
 * K: rsw_bundle_shard_keys), so that every shard forms the bundles the
 * whole job would (client_contexts_bundle_leads;
 * docs/cluster.md#shards-and-spectral-bundles). Its n-th (re)submission is routed by "<prefix>-<k>.r<n>" (n = 0:
 * "<prefix>-<k>"), so a resubmission after a lost replica hashes to a
 * fresh point of the ring and usually lands on another replica, while
 * the balancer's own health checks take the lost one out.
 *
 * The state file is a journal of JSON lines, appended and flushed as the
 * run goes:
 *   {"format": "raysweep-spread/1", "prefix": P, "shards": K,
 *    "contexts": N, "request": FNV-1a 64 of the JobRequest, "scene": ID?}
 *   {"shard": k, "attempt": n, "key": KEY, "job": JOB, "contexts": C}
 *   {"context": ID, "results": [result objects]}   one per delivered context
 * A rerun reads it: delivered contexts are handed back (film NULL,
 * resumed 1) and not rendered again; the last job of each shard is
 * followed again through its key when the replica still has it. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bundle_plan.h"

#include "internal.h"

#define SPREAD_FORMAT "raysweep-spread/1"

static _Thread_local char spread_err[1024];

const char *rsw_spread_last_error(void) {
  return spread_err;
}

typedef struct spread spread;

typedef struct shard {
  spread *sp;
  int k;
  size_t *idx; /* context indices of x in this shard */
  size_t n;
  int attempt;
  char base[64]; /* first key; resubmissions append ".r<n>" */
  char key[96];
  char job[40];        /* the job of this attempt, "" before submission */
  char scene[65];      /* the scene its job runs on, on its replica */
  size_t job_contexts; /* contexts in that job */
  size_t prior;        /* renders delivered by earlier attempts */
  size_t delivered;    /* renders delivered by this attempt */
  size_t cur_done, cur_total;
  rsw_status status;
  struct early *early; /* while its job runs: the contexts handed over early */
} shard;

struct spread {
  const rsw_client_opts *copts;
  const rsw_spread_opts *o;
  const rsw_contexts *x;
  char prefix[32];
  char scene_id[65];
  char doc_id[65]; /* a FILE's document id: every replica's scene of it has it */
  size_t n_ctx;
  const char **sorted_ids; /* ids sorted, for lookups */
  size_t *sorted_idx;      /* index in x of sorted_ids[i] */
  unsigned char *done;     /* per context index of x: delivered */
  size_t *lead;            /* per context index of x: its bundle group's first (itself without bundles) */
  size_t *key;             /* and its shard key: the group's rank, dealt mod shards (rsw_bundle_shard_keys) */
  bool grouped;            /* some lead differs from its context: resubmit groups whole, name them */
  double deadline;
  FILE *journal;
  pthread_mutex_t lock; /* journal, callbacks, counters, done[] */
  atomic_int stop;      /* a shard hit something the run cannot go past */
  rsw_status fatal;
  char err[1024];
  shard *shards;
  int n_shards;
  size_t resumed, films, failed, resubmitted, contexts_resubmitted;
};

static void set_fatal(spread *sp, rsw_status s, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static void set_fatal(spread *sp, rsw_status s, const char *fmt, ...) {
  pthread_mutex_lock(&sp->lock);
  if (!sp->fatal) {
    sp->fatal = s;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(sp->err, sizeof sp->err, fmt, ap);
    va_end(ap);
  }
  atomic_store(&sp->stop, 1);
  pthread_mutex_unlock(&sp->lock);
}

static int cmp_id(const void *a, const void *b) {
  const spread *sp = NULL;
  (void)sp;
  return strcmp(*(const char *const *)a, *(const char *const *)b);
}

/* A context and its bundle group's first, sorted by group, then index. */
typedef struct led {
  size_t lead, index;
} led;

static int cmp_led(const void *pa, const void *pb) {
  const led *a = pa, *b = pb;
  if (a->lead != b->lead) return a->lead < b->lead ? -1 : 1;
  return a->index < b->index ? -1 : a->index > b->index;
}

/* Index in x of context id, or (size_t)-1. */
static size_t lookup(const spread *sp, const char *id) {
  if (!id) return (size_t)-1;
  const char **hit = bsearch(&id, sp->sorted_ids, sp->n_ctx, sizeof *sp->sorted_ids, cmp_id);
  return hit ? sp->sorted_idx[hit - sp->sorted_ids] : (size_t)-1;
}

static uint64_t fnv1a64(const char *s) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (; s && *s; s++) h = (h ^ (unsigned char)*s) * 0x100000001b3ull;
  return h;
}

/* Append one line to the journal (caller holds the lock). Flushed, not
 * synced: the line is there for a rerun after the process dies (Ctrl-C,
 * a crash, a kill), which is what the journal is for; the films it names
 * are not synced either, so syncing it alone would survive a power loss
 * only to name films that did not. One fsync per context was also the
 * client's largest cost per film (about 2.5 ms on this machine's disk,
 * a quarter of the render of a 32x32 film at 16 spp on one thread). */
static void journal_line(spread *sp, cJSON *o) {
  if (!sp->journal) {
    cJSON_Delete(o);
    return;
  }
  char *t = cJSON_PrintUnformatted(o);
  cJSON_Delete(o);
  if (t) {
    fprintf(sp->journal, "%s\n", t);
    fflush(sp->journal);
  }
  free(t);
}

static void shard_key(shard *sh) {
  if (!sh->base[0]) snprintf(sh->base, sizeof sh->base, "%s-%d", sh->sp->prefix, sh->k);
  if (sh->attempt == 0)
    snprintf(sh->key, sizeof sh->key, "%s", sh->base);
  else
    snprintf(sh->key, sizeof sh->key, "%s.r%d", sh->base, sh->attempt);
}

/* The replica a key reaches: GET /v1 through the balancer and read the
 * daemon's "instance" (random per process). "" when the answer has none. */
static rsw_status probe_instance(rsw_client *c, const char *key, char out[64]) {
  out[0] = '\0';
  rsw_status s = rsw_client_set_route(c, key);
  char *text = NULL;
  if (!s) s = rsw_server_info(c, &text);
  if (s) return s;
  cJSON *o = cJSON_Parse(text);
  rsw_free(text);
  const char *id = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "instance"));
  if (id) snprintf(out, 64, "%s", id);
  cJSON_Delete(o);
  return RSW_OK;
}

/* Consistent hashing places K keys on R replicas at random: with K = R = 3
 * all three differ only 2 times in 9. So each shard tries keys
 * "<prefix>-<k>", "<prefix>-<k>.p1", ... (at most 32) and takes the first
 * that reaches a replica no shard uses yet. Failing that, it settles for
 * the least used replica seen after 8 tries, unless a replica may still be
 * unseen: while fewer replicas than shards have answered and the last
 * new one came less than QUIET probes ago (a third replica missed by 8
 * probes that each reach one of two others at random: (2/3)^8 = 4%; by
 * 24 probes in a row: 6e-5). The balancer stays stateless; the keys are
 * kept in the state file. */
static rsw_status choose_keys(spread *sp, rsw_client *c) {
  enum {
    MAX_TRIES = 32,
    MAX_SEEN = 256,
    QUIET = 24
  };
  int since_new = 0; /* probes since a replica was first seen */
  char(*seen)[64] = calloc(MAX_SEEN, 64);
  int *used = calloc(MAX_SEEN, sizeof *used);
  size_t n_seen = 0;
  rsw_status s = seen && used ? RSW_OK : RSW_ERR_NOMEM;
  for (int k = 0; k < sp->n_shards && !s; k++) {
    shard *sh = &sp->shards[k];
    if (sh->base[0]) continue; /* from the state file */
    char key[64], inst[64], best_key[64] = "";
    int best_use = -1;
    size_t best_i = 0;
    for (int t = 0; t < MAX_TRIES && !s; t++) {
      if (t == 0)
        snprintf(key, sizeof key, "%s-%d", sp->prefix, k);
      else
        snprintf(key, sizeof key, "%s-%d.p%d", sp->prefix, k, t);
      if ((s = probe_instance(c, key, inst))) break;
      if (!inst[0]) { /* no instance ids: nothing to choose from */
        snprintf(best_key, sizeof best_key, "%s", key);
        best_use = 0, best_i = (size_t)-1;
        break;
      }
      size_t i = 0;
      while (i < n_seen && strcmp(seen[i], inst) != 0) i++;
      if (i == n_seen && n_seen < MAX_SEEN) {
        snprintf(seen[n_seen++], 64, "%s", inst);
        since_new = 0;
      } else {
        since_new++;
      }
      int use = i < MAX_SEEN ? used[i] : 0;
      if (best_use < 0 || use < best_use) {
        best_use = use, best_i = i;
        snprintf(best_key, sizeof best_key, "%s", key);
      }
      /* Least used of all the replicas seen: good enough once every
       * shard so far has a replica of its own or this one is unused. */
      int min_use = use;
      for (size_t j = 0; j < n_seen; j++) min_use = used[j] < min_use ? used[j] : min_use;
      bool maybe_unseen = n_seen < (size_t)sp->n_shards && since_new < QUIET;
      if (use == 0 || (use == min_use && t >= 8 && !maybe_unseen)) break;
    }
    if (s) break;
    if (best_i < MAX_SEEN) used[best_i]++;
    snprintf(sh->base, sizeof sh->base, "%s", best_key);
  }
  free(seen);
  free(used);
  return s;
}

/* ---- progress over every shard ---- */

static void early_note(struct early *e, size_t total);
static bool early_failed(struct early *e);

static int on_progress(void *user, const char *context, const char *sensor, size_t done, size_t total,
                       int failed) {
  shard *sh = user;
  spread *sp = sh->sp;
  if (atomic_load(&sp->stop) || (sh->early && early_failed(sh->early))) return 1;
  if (!context) return 0; /* the end-of-job call: the results decide */
  if (sh->early) early_note(sh->early, total);
  pthread_mutex_lock(&sp->lock);
  if (done > sh->cur_done) sh->cur_done = done;
  if (total) sh->cur_total = total;
  size_t d = sp->resumed, t = sp->resumed;
  for (int i = 0; i < sp->n_shards; i++) {
    d += sp->shards[i].prior + sp->shards[i].cur_done;
    t += sp->shards[i].prior + sp->shards[i].cur_total;
  }
  int rc = 0;
  if (sp->o->progress)
    rc = sp->o->progress(sp->o->progress_user, context, sensor ? sensor : "", d, t, failed);
  pthread_mutex_unlock(&sp->lock);
  if (rc) atomic_store(&sp->stop, 1);
  return rc;
}

/* ---- what a failure means ---- */

typedef enum {
  F_LOST,
  F_GONE,
  F_STOP,
  F_FATAL
} failure;

/* A request of shard sh failed with s: is its replica lost (resubmit), the
 * balancer gone (stop, resumable), the run stopped, or something else? */
static failure classify(shard *sh, rsw_client *c, rsw_status s) {
  const rsw_error_info *e = rsw_client_last_error(c);
  if (s == RSW_ERR_CANCELLED || s == RSW_ERR_TIMEOUT || atomic_load(&sh->sp->stop)) return F_STOP;
  int h = e->http_status;
  if (h == 404 || h == 429 || h == 502 || h == 503 || h == 504 || s == RSW_ERR_NOT_FOUND) return F_LOST;
  if (h == 0 && s == RSW_ERR_UNAVAILABLE) {
    /* No answer at all. A stream that dropped because its replica died
     * reads the same: ask the balancer itself (any HTTP answer will do). */
    char *text = NULL;
    rsw_status p = rsw_server_ready(c);
    (void)text;
    if (p == RSW_OK || rsw_client_last_error(c)->http_status != 0) return F_LOST;
    return F_GONE;
  }
  return F_FATAL;
}

static void fail_shard(shard *sh, rsw_client *c, rsw_status s, failure f, const char *what) {
  spread *sp = sh->sp;
  const rsw_error_info *e = rsw_client_last_error(c);
  if (f == F_GONE)
    set_fatal(sp, RSW_ERR_UNAVAILABLE, "cannot reach %s (%s): the balancer is gone; %s",
              sp->copts->base_url ? sp->copts->base_url : "the server", e->message,
              sp->o->state_path ? "the same call resumes from the state file"
                                : "no state file: nothing to resume");
  else if (f == F_STOP)
    set_fatal(sp, s, "%s: %s", what, e->message[0] ? e->message : rsw_strerror(s));
  else
    set_fatal(sp, s, "shard %d (%s) %s: %s", sh->k, sh->key, what,
              e->message[0] ? e->message : rsw_strerror(s));
}

/* ---- one shard ---- */

/* One result's film, as the caller asked for it (rsw_spread_opts
 * .film_media_type): decoded, or the daemon's bytes. Neither: the render
 * did not succeed (or the film was delivered by an earlier run). */
typedef struct fetched {
  rsw_film *film;
  const void *bytes; /* encoded: owned, or borrowed from a batch's answer (hand_results) */
  void *owned;       /* bytes when owned (free()), else NULL */
  size_t len;
} fetched;

/* The caller's callback for one result (caller holds the lock). */
static int hand_over(spread *sp, const char *id, const char *sensor, const char *result_json,
                     const fetched *f, int resumed) {
  const rsw_spread_opts *o = sp->o;
  if (o->film_media_type)
    return o->on_film_encoded(o->film_user, id, sensor, result_json, f ? f->bytes : NULL, f ? f->len : 0,
                              resumed);
  return o->on_film(o->film_user, id, sensor, result_json, f ? f->film : NULL, resumed);
}

/* Hand every result of one context to the caller and journal it: rs, the
 * job's nr results of context `id`, in the job's order; pre (or NULL: each
 * fetched here) their films fetched already (fetch_ahead), moved out of pre. */
static int deliver_context(shard *sh, rsw_client *c, const cJSON *const *rs, size_t nr, const char *id,
                           size_t cidx, fetched *pre, rsw_status *st_out) {
  spread *sp = sh->sp;
  cJSON *mine = cJSON_CreateArray();
  fetched *films = NULL;
  size_t nf = 0, cap = 0;
  const cJSON *r;
  *st_out = RSW_OK;
  /* Fetch first, then deliver under the lock: a lost replica half-way
   * leaves the context undelivered. */
  for (size_t ri = 0; ri < nr; ri++) {
    r = rs[ri];
    const char *sensor = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "sensor"));
    const char *state = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "state"));
    if (nf == cap) {
      cap = cap ? 2 * cap : 4;
      fetched *nfm = realloc(films, cap * sizeof *nfm);
      if (!nfm) {
        *st_out = RSW_ERR_NOMEM;
        break;
      }
      films = nfm;
    }
    fetched *f = &films[nf++];
    memset(f, 0, sizeof *f);
    if (pre && pre[ri].bytes && state && sensor && strcmp(state, "succeeded") == 0) {
      *f = pre[ri]; /* fetched with others (fetch_ahead), borrowed from their answer */
      memset(&pre[ri], 0, sizeof pre[ri]);
    } else if (state && sensor && strcmp(state, "succeeded") == 0) {
      rsw_status s =
          sp->o->film_media_type
              ? rsw_job_fetch_encoded(c, sh->job, id, sensor, sp->o->film_media_type, &f->owned, &f->len)
              : rsw_job_fetch(c, sh->job, id, sensor, &f->film);
      f->bytes = f->owned;
      if (s) {
        *st_out = s;
        break;
      }
    }
    cJSON_AddItemToArray(mine, cJSON_Duplicate(r, 1));
  }
  int stop = 0;
  if (!*st_out) {
    pthread_mutex_lock(&sp->lock);
    size_t i = 0;
    cJSON_ArrayForEach(r, mine) {
      const char *sensor = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "sensor"));
      char *t = cJSON_PrintUnformatted(r);
      if (!stop && hand_over(sp, id, sensor ? sensor : "", t ? t : "{}", &films[i], 0)) stop = 1;
      free(t);
      if (films[i].film || films[i].bytes)
        sp->films++;
      else
        sp->failed++;
      i++;
    }
    sh->delivered += i;
    sp->done[cidx] = 1;
    cJSON *line = cJSON_CreateObject();
    cJSON_AddStringToObject(line, "context", id);
    cJSON_AddItemToObject(line, "results", mine);
    mine = NULL;
    journal_line(sp, line);
    pthread_mutex_unlock(&sp->lock);
  }
  for (size_t i = 0; i < nf; i++) {
    rsw_film_free(films[i].film);
    free(films[i].owned);
  }
  free(films);
  cJSON_Delete(mine);
  return stop;
}

/* Submit the undelivered contexts of sh under its current key. Returns
 * RSW_OK with sh->job set, or the failure (nothing left: job ""). */
static rsw_status submit(shard *sh, rsw_client *c, size_t *n_out) {
  spread *sp = sh->sp;
  size_t *pending = malloc((sh->n ? sh->n : 1) * sizeof *pending), np = 0;
  if (!pending) return RSW_ERR_NOMEM;
  pthread_mutex_lock(&sp->lock);
  /* A bundle group goes whole, delivered mates too (hand_results skips
   * them), so that its bundles are the whole job's: idx lists a group's
   * contexts from its first, in order. */
  for (size_t a = 0, b; a < sh->n; a = b) {
    bool left = false;
    for (b = a; b < sh->n && sp->lead[sh->idx[b]] == sp->lead[sh->idx[a]]; b++)
      left = left || !sp->done[sh->idx[b]];
    for (size_t i = a; i < b; i++)
      if (left && (sp->grouped || !sp->done[sh->idx[i]])) pending[np++] = sh->idx[i];
  }
  pthread_mutex_unlock(&sp->lock);
  *n_out = np;
  sh->job[0] = '\0';
  if (!np) {
    free(pending);
    return RSW_OK;
  }
  rsw_status s = rsw_client_set_route(c, sh->key);
  snprintf(sh->scene, sizeof sh->scene, "%s", sp->scene_id);
  if (!s && sp->o->scene_file) {
    /* The replica's scene in the file's state: its id is the document's
     * unless that replica's twin has been changed (then a scene of its
     * own); the document must be the same everywhere. */
    char doc[65];
    s = client_scene_push_file(c, sp->o->scene_file, sp->o->variant, sh->scene, doc, NULL);
    if (!s && strcmp(doc, sp->doc_id) != 0) {
      free(pending);
      set_fatal(sp, RSW_ERR_CONFLICT, "shard %d: %s is document %s on this replica but %s on another", sh->k,
                sp->o->scene_file, doc, sp->doc_id);
      return RSW_ERR_CONFLICT;
    }
  }
  rsw_contexts *y = NULL;
  if (!s) s = client_contexts_subset(sp->x, pending, np, &y);
  for (size_t i = 0; !s && sp->grouped && i < np; i++) /* the groups, for the daemon to keep */
    if (!cJSON_GetObjectItemCaseSensitive(client_contexts_item(y, i), "bundle_group"))
      s = rsw_contexts_set_bundle_group(y, i, (long long)sp->lead[pending[i]]);
  free(pending);
  if (!s) s = rsw_job_submit(c, sh->scene, y, sh->key, sh->job);
  rsw_contexts_free(y);
  if (s) return s;
  sh->job_contexts = np;
  pthread_mutex_lock(&sp->lock);
  sh->prior += sh->delivered;
  sh->delivered = 0;
  sh->cur_done = sh->cur_total = 0;
  cJSON *line = cJSON_CreateObject();
  cJSON_AddNumberToObject(line, "shard", sh->k);
  cJSON_AddNumberToObject(line, "attempt", sh->attempt);
  cJSON_AddStringToObject(line, "base", sh->base);
  cJSON_AddStringToObject(line, "key", sh->key);
  cJSON_AddStringToObject(line, "job", sh->job);
  cJSON_AddNumberToObject(line, "contexts", (double)np);
  journal_line(sp, line);
  pthread_mutex_unlock(&sp->lock);
  return RSW_OK;
}

/* One result of a job and the index in x of its context. */
typedef struct ctx_result {
  size_t ci, order;
  const cJSON *r;
} ctx_result;

static int cmp_ctx_result(const void *a, const void *b) {
  const ctx_result *x = a, *y = b;
  if (x->ci != y->ci) return x->ci < y->ci ? -1 : 1;
  return x->order < y->order ? -1 : x->order > y->order;
}

/* Does the context of results by[a..b) get handed over in this pass: not
 * delivered yet and, early or cancelled, every render of it succeeded?
 * (caller holds sp->lock) */
static bool to_deliver(const spread *sp, const ctx_result *by, size_t a, size_t b, bool early,
                       bool cancelled) {
  if (sp->done[by[a].ci]) return false;
  if (!early && !cancelled) return true;
  for (size_t i = a; i < b; i++) {
    const char *state = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(by[i].r, "state"));
    if (!state || strcmp(state, "succeeded") != 0) return false;
  }
  return true;
}

/* Fetch in one request (POST .../results:fetch) the films of the contexts
 * handed over next, from by[a] on: as many whole contexts as hold at most
 * CLIENT_FETCH_MAX films and about CLIENT_FETCH_BYTES. pre[i] gets result
 * by[i]'s film, borrowed from *answer (the whole answer, owned: the films
 * are not copied out of it); returns the end of the results looked at
 * (by index), a when nothing was fetched (not EXR or NPY, a daemon without
 * the route, any failure: deliver_context then fetches them one by one,
 * and says what failed). */
static size_t fetch_ahead(shard *sh, rsw_client *c, const ctx_result *by, size_t nres, size_t a, bool early,
                          bool cancelled, fetched *pre, char **answer) {
  spread *sp = sh->sp;
  const char *mt = sp->o->film_media_type;
  if (!mt || (strcmp(mt, "image/x-exr") != 0 && strcmp(mt, "application/x-npy") != 0)) return a;
  const char *ctx[CLIENT_FETCH_MAX], *sen[CLIENT_FETCH_MAX];
  size_t at[CLIENT_FETCH_MAX], n = 0, end = a;
  double est = 0; /* the answer's size, about: 4 bytes a sample, 24 a pixel's angles */
  pthread_mutex_lock(&sp->lock);
  for (size_t lo = a, hi; lo < nres; lo = hi) {
    for (hi = lo; hi < nres && by[hi].ci == by[lo].ci; hi++) {}
    size_t m = n;
    double est_m = est;
    bool fits = true;
    if (to_deliver(sp, by, lo, hi, early, cancelled))
      for (size_t i = lo; i < hi && fits; i++) {
        const cJSON *r = by[i].r;
        const char *sensor = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "sensor"));
        const char *state = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "state"));
        if (!sensor || !state || strcmp(state, "succeeded") != 0) continue;
        est_m += cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(r, "width")) *
                 cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(r, "height")) *
                 (4.0 * cJSON_GetArraySize(cJSON_GetObjectItemCaseSensitive(r, "channels")) + 24.0);
        fits = m < CLIENT_FETCH_MAX && est_m <= CLIENT_FETCH_BYTES; /* (a size not given: NaN, no) */
        if (!fits) break;
        ctx[m] = client_contexts_id(sp->x, by[i].ci), sen[m] = sensor, at[m] = i;
        m++;
      }
    if (!fits) break; /* this context's films do not fit: the next batch */
    n = m, end = hi, est = est_m;
    if (n == CLIENT_FETCH_MAX) break;
  }
  pthread_mutex_unlock(&sp->lock);
  if (n < 2) return a; /* one film: its GET is as cheap */
  const void *bytes[CLIENT_FETCH_MAX];
  size_t len[CLIENT_FETCH_MAX];
  if (client_job_fetch_encoded_many(c, sh->job, n, ctx, sen, mt, answer, bytes, len)) return a;
  for (size_t k = 0; k < n; k++) pre[at[k]].bytes = bytes[k], pre[at[k]].len = len[k];
  return end;
}

/* Hand over the contexts of one answer of GET results (text, freed here)
 * that are not delivered yet. early (the job still runs): those whose
 * every render succeeded; otherwise (the job is over) every context,
 * but for a job cancelled by its replica only those whose every render
 * succeeded (the rest is rendered again elsewhere). RSW_OK, or the
 * failure: *lost set when the replica is lost, else recorded (set_fatal). */
static rsw_status hand_results(shard *sh, rsw_client *c, char *text, bool early, bool cancelled, bool *lost) {
  spread *sp = sh->sp;
  cJSON *res = cJSON_Parse(text);
  rsw_free(text);
  const cJSON *list = cJSON_GetObjectItemCaseSensitive(res, "results");
  /* Ours: every result names a context of this shard that is pending. */
  const cJSON *r;
  bool ours = cJSON_IsArray(list);
  cJSON_ArrayForEach(r, list) {
    size_t ci = lookup(sp, cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "context")));
    if (ci == (size_t)-1 || sp->key[ci] % (size_t)sp->n_shards != (size_t)sh->k) ours = false;
  }
  if (!ours) {
    cJSON_Delete(res);
    *lost = true;
    return RSW_ERR_NOT_FOUND;
  }
  /* The results by context (each context's in the job's order), so that
   * handing them over costs one pass, not one per context. */
  size_t nres = (size_t)cJSON_GetArraySize(list), k = 0;
  ctx_result *by = malloc((nres ? nres : 1) * sizeof *by);
  const cJSON **run = malloc((nres ? nres : 1) * sizeof *run);
  if (!by || !run) {
    free(by);
    free(run);
    cJSON_Delete(res);
    set_fatal(sp, RSW_ERR_NOMEM, "out of memory");
    return RSW_ERR_NOMEM;
  }
  cJSON_ArrayForEach(r, list) {
    by[k] =
        (ctx_result){lookup(sp, cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "context"))), k, r};
    k++;
  }
  qsort(by, nres, sizeof *by, cmp_ctx_result);
  /* Films fetched ahead, several contexts' in one request (fetch_ahead),
   * by index in by, borrowed from answer (the request's, for the results
   * from ans_from on); pre_end: the results looked at so far. */
  fetched *pre = calloc(nres ? nres : 1, sizeof *pre);
  size_t pre_end = 0, ans_from = 0;
  char *answer = NULL;
  bool batches = pre != NULL;
  rsw_status s = RSW_OK;
  for (size_t a = 0, b; a < nres && !s; a = b) {
    size_t ci = by[a].ci;
    for (b = a; b < nres && by[b].ci == ci; b++) run[b - a] = by[b].r;
    pthread_mutex_lock(&sp->lock);
    bool go = to_deliver(sp, by, a, b, early, cancelled);
    pthread_mutex_unlock(&sp->lock);
    if (!go) continue;
    const char *id = client_contexts_id(sp->x, ci);
    if (batches && a >= pre_end) {
      /* The answer before: its films delivered (or passed over) by now. */
      for (size_t i = ans_from; i < pre_end; i++) pre[i].bytes = NULL, pre[i].len = 0;
      free(answer);
      answer = NULL;
      ans_from = a;
      pre_end = fetch_ahead(sh, c, by, nres, a, early, cancelled, pre, &answer);
      batches = pre_end > a; /* a failure: one by one from here on */
    }
    rsw_status fs;
    if (deliver_context(sh, c, run, b - a, id, ci, a < pre_end ? &pre[a] : NULL, &fs)) {
      set_fatal(sp, RSW_ERR_CANCELLED, "stopped by the film callback");
      s = RSW_ERR_CANCELLED;
      break;
    }
    if (fs) {
      failure f = classify(sh, c, fs);
      if (f == F_LOST)
        *lost = true;
      else
        fail_shard(sh, c, fs, f, "fetching films");
      s = fs;
    }
  }
  free(answer);
  free(pre);
  free(by);
  free(run);
  cJSON_Delete(res);
  return s;
}

/* ---- handing films over while the job runs ---- */

/* A shard's job streams its events on the shard's connection; a second
 * connection and thread hand over the finished contexts meanwhile: after
 * every batch of renders, GET results and deliver the contexts whose
 * renders all succeeded. So films are fetched and written while the
 * daemon renders the next ones (the daemon's core is busy rendering, the
 * client's fetches and file writes wait on the network and the disk), and
 * a run that is cut off keeps the films delivered so far (the journal
 * names them). What is left when the job ends goes in follow()'s last
 * pass, after the renders: the fixed cost at a sweep's end.
 *
 * A pass costs about the same whatever it delivers (one GET results of
 * the whole job, which the daemon prints and the client parses, and one
 * POST results:fetch), so passes are few while many renders are left:
 * one per an eighth of the job's renders; then, as the end nears, one per
 * half of what is left (client_early_batch), so that the last pass
 * finds few films to fetch. (One per sixteenth throughout cost the sweep
 * bench's client ~13% more CPU; one per eighth throughout left ~12 films
 * to the last pass, ~4 ms more at the end.) */
typedef struct early {
  shard *sh;
  rsw_client *c; /* its own connection, on the shard's key */
  pthread_t th;
  pthread_mutex_t mu;
  pthread_cond_t cv;
  size_t pending;     /* renders reported since the last pass */
  size_t seen, total; /* renders reported, and the job's (0: not known yet) */
  size_t max_batch;   /* renders per pass while many are left */
  bool finish;        /* the wait is over: stop */
  rsw_status status;  /* a pass that failed, and whether the replica is lost */
  bool lost;
  atomic_int failed;
} early;

/* Jobs of fewer contexts are handed over at their end only. */
#define EARLY_MIN_CONTEXTS 8

size_t client_early_batch(size_t max_batch, size_t total, size_t seen, size_t pending) {
  size_t before = seen - pending, left = total > before ? total - before : 0, b = max_batch;
  if (total && left / 2 < b) b = left / 2;
  return b > CLIENT_EARLY_MIN_BATCH ? b : CLIENT_EARLY_MIN_BATCH;
}

/* (caller holds e->mu) */
static size_t early_batch(const early *e) {
  return client_early_batch(e->max_batch, e->total, e->seen, e->pending);
}

/* A render reported (done of total: the job's renders, 0 not known). */
static void early_note(early *e, size_t total) {
  pthread_mutex_lock(&e->mu);
  e->seen++;
  if (total) e->total = total;
  if (++e->pending >= early_batch(e)) pthread_cond_signal(&e->cv);
  pthread_mutex_unlock(&e->mu);
}

static bool early_failed(early *e) {
  return atomic_load(&e->failed) != 0;
}

static void *early_main(void *arg) {
  early *e = arg;
  shard *sh = e->sh;
  for (;;) {
    pthread_mutex_lock(&e->mu);
    while (!e->finish && e->pending < early_batch(e)) pthread_cond_wait(&e->cv, &e->mu);
    bool finish = e->finish;
    e->pending = 0;
    pthread_mutex_unlock(&e->mu);
    if (finish || atomic_load(&sh->sp->stop)) break;
    char *text = NULL;
    bool lost = false;
    rsw_status s = rsw_job_results(e->c, sh->job, &text);
    if (s) {
      failure f = classify(sh, e->c, s);
      if (f == F_LOST)
        lost = true;
      else
        fail_shard(sh, e->c, s, f, "fetching results while its job runs");
    } else {
      s = hand_results(sh, e->c, text, true, false, &lost);
    }
    if (s) {
      e->status = s, e->lost = lost;
      atomic_store(&e->failed, 1);
      break;
    }
  }
  return NULL;
}

/* Start handing sh's contexts over early (false: not for this job, or no
 * connection or thread for it; the last pass then does it all). */
static bool early_start(shard *sh, early *e) {
  memset(e, 0, sizeof *e);
  if (sh->job_contexts < EARLY_MIN_CONTEXTS) return false;
  e->sh = sh;
  e->max_batch = sh->job_contexts / 8;
  rsw_client_opts co = *sh->sp->copts;
  co.size = sizeof co;
  co.route_key = sh->key;
  if (rsw_client_new(&co, &e->c)) return false;
  pthread_mutex_init(&e->mu, NULL);
  pthread_cond_init(&e->cv, NULL);
  if (pthread_create(&e->th, NULL, early_main, e) != 0) {
    pthread_mutex_destroy(&e->mu);
    pthread_cond_destroy(&e->cv);
    rsw_client_free(e->c);
    return false;
  }
  sh->early = e;
  return true;
}

static void early_stop(shard *sh, early *e) {
  pthread_mutex_lock(&e->mu);
  e->finish = true;
  pthread_cond_signal(&e->cv);
  pthread_mutex_unlock(&e->mu);
  pthread_join(e->th, NULL);
  sh->early = NULL;
  pthread_mutex_destroy(&e->mu);
  pthread_cond_destroy(&e->cv);
  rsw_client_free(e->c);
}

/* Wait for sh's job and deliver its results. RSW_OK: every context of the
 * job delivered; F_LOST-type failures come back as their status with
 * *lost set. */
static rsw_status follow(shard *sh, rsw_client *c, bool *lost) {
  spread *sp = sh->sp;
  *lost = false;
  double left = 0;
  if (sp->deadline > 0) {
    left = sp->deadline - client_now_s();
    if (left <= 0) {
      set_fatal(sp, RSW_ERR_TIMEOUT, "the spread sweep did not end within %.3g s", sp->o->timeout_s);
      return RSW_ERR_TIMEOUT;
    }
  }
  rsw_job_status st;
  early e;
  bool piped = early_start(sh, &e);
  rsw_status s = rsw_job_wait(c, sh->job, on_progress, sh, left, &st);
  if (piped) {
    early_stop(sh, &e);
    if (e.status) { /* a pass failed (and stopped the wait) */
      *lost = e.lost;
      return e.status;
    }
  }
  /* A replica that restarted (or another behind the same key) may have a
   * job of the same id: check it is ours by its size. */
  if (!s && st.contexts_total != sh->job_contexts) {
    *lost = true;
    return RSW_ERR_NOT_FOUND;
  }
  char *text = NULL;
  if (!s) s = rsw_job_results(c, sh->job, &text);
  if (s) {
    failure f = classify(sh, c, s);
    if (f == F_LOST) {
      *lost = true;
      return s;
    }
    fail_shard(sh, c, s, f, "waiting for its job");
    return s;
  }
  bool cancelled = st.state == RSW_JOB_CANCELLED;
  s = hand_results(sh, c, text, false, cancelled, lost);
  if (!s && cancelled) {
    pthread_mutex_lock(&sp->lock);
    bool left_over = false;
    for (size_t i = 0; i < sh->n; i++) left_over = left_over || !sp->done[sh->idx[i]];
    pthread_mutex_unlock(&sp->lock);
    if (left_over) {
      *lost = true;
      return RSW_ERR_CANCELLED;
    }
  }
  return s;
}

static void *shard_main(void *arg) {
  shard *sh = arg;
  spread *sp = sh->sp;
  rsw_client_opts co = *sp->copts;
  co.size = sizeof co;
  co.route_key = NULL;
  rsw_client *c = NULL;
  rsw_status s = rsw_client_new(&co, &c);
  if (s) {
    set_fatal(sp, s, "shard %d: cannot create a client: %s", sh->k, rsw_strerror(s));
    sh->status = s;
    return NULL;
  }
  int max = sp->o->max_resubmits > 0 ? sp->o->max_resubmits : 8;
  while (!atomic_load(&sp->stop)) {
    bool lost = false;
    if (sh->job[0]) { /* resumed: is the job still there, behind its key? */
      rsw_client_set_route(c, sh->key);
      rsw_job_status st;
      s = rsw_job_get(c, sh->job, &st);
      if (s) {
        failure f = classify(sh, c, s);
        if (f != F_LOST) {
          fail_shard(sh, c, s, f, "following its job");
          break;
        }
        lost = true;
      }
    } else {
      size_t np = 0;
      shard_key(sh);
      s = submit(sh, c, &np);
      if (s && !sp->o->scene_file && rsw_client_last_error(c)->http_status == 404) {
        set_fatal(sp, s,
                  "scene %s is not resident on the replica behind key %s: give the scene FILE instead of its "
                  "id, so that every replica gets it",
                  sp->scene_id, sh->key);
        break;
      }
      if (s) {
        failure f = classify(sh, c, s);
        if (f != F_LOST) {
          fail_shard(sh, c, s, f, "submitting its job");
          break;
        }
        lost = true;
      } else if (!np) {
        break; /* everything delivered */
      }
    }
    if (!lost) {
      s = follow(sh, c, &lost);
      if (!s) break;
      if (!lost) break; /* follow() recorded the failure */
    }
    /* The replica behind this key is lost (or full): next key. */
    if (sh->attempt >= max) {
      set_fatal(sp, RSW_ERR_UNAVAILABLE, "shard %d: resubmitted %d times without finishing (last key %s)",
                sh->k, sh->attempt, sh->key);
      break;
    }
    pthread_mutex_lock(&sp->lock);
    size_t left = 0;
    for (size_t i = 0; i < sh->n; i++) left += !sp->done[sh->idx[i]];
    sp->resubmitted++;
    sp->contexts_resubmitted += left;
    pthread_mutex_unlock(&sp->lock);
    sh->attempt++;
    sh->job[0] = '\0';
    client_sleep_s(c, 0.2 * sh->attempt);
  }
  rsw_client_free(c);
  return NULL;
}

/* ---- the state file ---- */

static rsw_status journal_open(spread *sp, uint64_t request) {
  const char *path = sp->o->state_path;
  FILE *f = fopen(path, "r");
  if (f) {
    char *line = NULL;
    size_t cap = 0;
    ssize_t len;
    size_t lineno = 0;
    rsw_status s = RSW_OK;
    while ((len = getline(&line, &cap, f)) > 0 && !s) {
      lineno++;
      cJSON *o = cJSON_Parse(line);
      if (!o) {
        if (line[len - 1] != '\n') break; /* a torn last line: the run died writing it */
        snprintf(sp->err, sizeof sp->err, "%s:%zu: not JSON", path, lineno);
        s = RSW_ERR_PARSE;
        break;
      }
      const cJSON *fmt = cJSON_GetObjectItemCaseSensitive(o, "format");
      const cJSON *sh = cJSON_GetObjectItemCaseSensitive(o, "shard");
      const cJSON *ctx = cJSON_GetObjectItemCaseSensitive(o, "context");
      if (lineno == 1) {
        const char *pre = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "prefix"));
        const char *req = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "request"));
        const cJSON *k = cJSON_GetObjectItemCaseSensitive(o, "shards");
        char want[17];
        snprintf(want, sizeof want, "%016llx", (unsigned long long)request);
        if (!cJSON_IsString(fmt) || strcmp(fmt->valuestring, SPREAD_FORMAT) != 0 || !pre ||
            strlen(pre) >= sizeof sp->prefix || !cJSON_IsNumber(k)) {
          snprintf(sp->err, sizeof sp->err, "%s: not a %s state file", path, SPREAD_FORMAT);
          s = RSW_ERR_PARSE;
        } else if (!req || strcmp(req, want) != 0 || (int)k->valuedouble != sp->n_shards) {
          snprintf(sp->err, sizeof sp->err,
                   "%s: the state of another sweep (different contexts, settings or shard count); "
                   "nothing was resumed",
                   path);
          s = RSW_ERR_PRECONDITION;
        } else {
          snprintf(sp->prefix, sizeof sp->prefix, "%s", pre);
        }
      } else if (cJSON_IsNumber(sh)) {
        int k = (int)sh->valuedouble;
        const char *key = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "key"));
        const char *base = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "base"));
        const char *job = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "job"));
        const cJSON *at = cJSON_GetObjectItemCaseSensitive(o, "attempt");
        const cJSON *nc = cJSON_GetObjectItemCaseSensitive(o, "contexts");
        if (k >= 0 && k < sp->n_shards && key && job && strlen(job) < 40 && cJSON_IsNumber(at) &&
            cJSON_IsNumber(nc)) {
          shard *x = &sp->shards[k];
          snprintf(x->key, sizeof x->key, "%s", key);
          snprintf(x->base, sizeof x->base, "%s", base ? base : key);
          snprintf(x->job, sizeof x->job, "%s", job);
          x->attempt = (int)at->valuedouble;
          x->job_contexts = (size_t)nc->valuedouble;
        }
      } else if (cJSON_IsString(ctx)) {
        size_t ci = lookup(sp, ctx->valuestring);
        const cJSON *res = cJSON_GetObjectItemCaseSensitive(o, "results");
        if (ci != (size_t)-1 && !sp->done[ci] && cJSON_IsArray(res)) {
          const cJSON *r;
          cJSON_ArrayForEach(r, res) {
            const char *sensor = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "sensor"));
            char *t = cJSON_PrintUnformatted(r);
            hand_over(sp, ctx->valuestring, sensor ? sensor : "", t ? t : "{}", NULL, 1);
            free(t);
            sp->resumed++;
          }
          sp->done[ci] = 1;
        }
      }
      cJSON_Delete(o);
    }
    free(line);
    fclose(f);
    if (s) return s;
    if (lineno == 0) goto fresh;
    sp->journal = fopen(path, "a");
    if (!sp->journal) {
      snprintf(sp->err, sizeof sp->err, "%s: %s", path, strerror(errno));
      return RSW_ERR_IO;
    }
    return RSW_OK;
  }
  if (errno != ENOENT) {
    snprintf(sp->err, sizeof sp->err, "%s: %s", path, strerror(errno));
    return RSW_ERR_IO;
  }
fresh:
  sp->journal = fopen(path, "w");
  if (!sp->journal) {
    snprintf(sp->err, sizeof sp->err, "%s: %s", path, strerror(errno));
    return RSW_ERR_IO;
  }
  cJSON *h = cJSON_CreateObject();
  char req[17];
  snprintf(req, sizeof req, "%016llx", (unsigned long long)request);
  cJSON_AddStringToObject(h, "format", SPREAD_FORMAT);
  cJSON_AddStringToObject(h, "prefix", sp->prefix);
  cJSON_AddNumberToObject(h, "shards", sp->n_shards);
  cJSON_AddNumberToObject(h, "contexts", (double)sp->n_ctx);
  cJSON_AddStringToObject(h, "request", req);
  journal_line(sp, h);
  return RSW_OK;
}

static void random_prefix(char out[32]) {
  unsigned char b[6] = {0};
  int fd = open("/dev/urandom", O_RDONLY | O_CLOEXEC);
  if (fd < 0 || read(fd, b, sizeof b) != (ssize_t)sizeof b) {
    uint64_t t = (uint64_t)(client_now_s() * 1e9) ^ (uint64_t)getpid();
    memcpy(b, &t, sizeof b);
  }
  if (fd >= 0) close(fd);
  snprintf(out, 32, "rs%02x%02x%02x%02x%02x%02x", b[0], b[1], b[2], b[3], b[4], b[5]);
}

rsw_status rsw_spread_run(const rsw_client_opts *copts, const char *scene_id, const rsw_contexts *x,
                          const rsw_spread_opts *opts, rsw_spread_result *out) {
  spread_err[0] = '\0';
  rsw_spread_opts o = {0};
  if (opts) {
    size_t n = opts->size ? opts->size : sizeof o;
    memcpy(&o, opts, n < sizeof o ? n : sizeof o);
  }
  rsw_client_opts co = {0};
  if (copts) {
    size_t n = copts->size ? copts->size : sizeof co;
    memcpy(&co, copts, n < sizeof co ? n : sizeof co);
  }
  co.size = sizeof co;
  if (out) memset(out, 0, sizeof *out);
  bool has_callback = o.film_media_type ? o.on_film_encoded && client_film_media_type_known(o.film_media_type)
                                        : o.on_film != NULL;
  if (!x || !has_callback || o.shards < 1 || o.shards > 4096 || (!scene_id && !o.scene_file) ||
      (o.route_prefix && (!client_valid_route(o.route_prefix) || strlen(o.route_prefix) > 24))) {
    snprintf(spread_err, sizeof spread_err,
             "rsw_spread_run: needs contexts, on_film (or on_film_encoded and a film_media_type of "
             "rsw_job_fetch_encoded), 1 <= shards <= 4096, a scene id or file, and a route "
             "prefix of [A-Za-z0-9._-]{1,24}");
    return RSW_ERR_INVALID;
  }
  spread sp = {.copts = &co, .o = &o, .x = x, .n_shards = o.shards};
  sp.n_ctx = rsw_contexts_count(x);
  if (!sp.n_ctx) {
    snprintf(spread_err, sizeof spread_err, "rsw_spread_run: no contexts");
    return RSW_ERR_INVALID;
  }
  pthread_mutex_init(&sp.lock, NULL);
  rsw_status s = RSW_OK;
  sp.sorted_ids = malloc(sp.n_ctx * sizeof *sp.sorted_ids);
  sp.sorted_idx = malloc(sp.n_ctx * sizeof *sp.sorted_idx);
  sp.done = calloc(sp.n_ctx, 1);
  sp.shards = calloc((size_t)o.shards, sizeof *sp.shards);
  pthread_t *th = calloc((size_t)o.shards, sizeof *th);
  if (!sp.sorted_ids || !sp.sorted_idx || !sp.done || !sp.shards || !th) {
    s = RSW_ERR_NOMEM;
    snprintf(sp.err, sizeof sp.err, "out of memory");
    goto done;
  }
  for (size_t i = 0; i < sp.n_ctx; i++) sp.sorted_ids[i] = client_contexts_id(x, i);
  qsort(sp.sorted_ids, sp.n_ctx, sizeof *sp.sorted_ids, cmp_id);
  for (size_t i = 0; i < sp.n_ctx; i++) {
    if (i && strcmp(sp.sorted_ids[i], sp.sorted_ids[i - 1]) == 0) {
      s = RSW_ERR_INVALID;
      snprintf(sp.err, sizeof sp.err, "context id '%s' appears twice", sp.sorted_ids[i]);
      goto done;
    }
  }
  for (size_t i = 0; i < sp.n_ctx; i++) {
    const char *id = client_contexts_id(x, i);
    const char **hit = bsearch(&id, sp.sorted_ids, sp.n_ctx, sizeof *sp.sorted_ids, cmp_id);
    sp.sorted_idx[hit - sp.sorted_ids] = i;
  }
  /* Shard k: the contexts whose bundle group's rank is k mod shards
   * (rsw_bundle_shard_keys; every context its own group without
   * bundles), by group. */
  sp.lead = malloc(sp.n_ctx * sizeof *sp.lead);
  sp.key = malloc((sp.n_ctx ? sp.n_ctx : 1) * sizeof *sp.key);
  if (!sp.lead || !sp.key || (s = client_contexts_bundle_leads(x, sp.lead))) {
    s = RSW_ERR_NOMEM;
    snprintf(sp.err, sizeof sp.err, "out of memory");
    goto done;
  }
  for (size_t i = 0; i < sp.n_ctx; i++) sp.grouped = sp.grouped || sp.lead[i] != i;
  rsw_bundle_shard_keys(sp.n_ctx, sp.lead, sp.key);
  for (size_t i = 0; i < sp.n_ctx; i++) sp.shards[sp.key[i] % (size_t)o.shards].n++;
  for (int k = 0; k < o.shards; k++) {
    shard *sh = &sp.shards[k];
    sh->sp = &sp, sh->k = k;
    sh->idx = malloc((sh->n ? sh->n : 1) * sizeof *sh->idx);
    sh->n = 0;
    if (!sh->idx) {
      s = RSW_ERR_NOMEM;
      snprintf(sp.err, sizeof sp.err, "out of memory");
      goto done;
    }
  }
  if (sp.grouped) { /* by group, then index */
    led *order = malloc(sp.n_ctx * sizeof *order);
    if (!order) {
      s = RSW_ERR_NOMEM;
      snprintf(sp.err, sizeof sp.err, "out of memory");
      goto done;
    }
    for (size_t i = 0; i < sp.n_ctx; i++) order[i] = (led){sp.lead[i], i};
    qsort(order, sp.n_ctx, sizeof *order, cmp_led);
    for (size_t i = 0; i < sp.n_ctx; i++) {
      shard *sh = &sp.shards[sp.key[order[i].index] % (size_t)o.shards];
      sh->idx[sh->n++] = order[i].index;
    }
    free(order);
  } else {
    for (size_t i = 0; i < sp.n_ctx; i++) {
      shard *sh = &sp.shards[i % (size_t)o.shards];
      sh->idx[sh->n++] = i;
    }
  }
  if (o.route_prefix)
    snprintf(sp.prefix, sizeof sp.prefix, "%s", o.route_prefix);
  else
    random_prefix(sp.prefix);
  /* The request's fingerprint and the scene: the state file must belong
   * to this very sweep. */
  char *req = client_contexts_print(x);
  uint64_t request = fnv1a64(req) ^ fnv1a64(scene_id ? scene_id : o.scene_file);
  free(req);
  if (o.state_path && (s = journal_open(&sp, request))) goto done;
  {
    /* Keys first (GET /v1 through each candidate), then the scene's id,
     * once, through shard 0's key (every replica computes the same content
     * address; each shard pushes again through its own key). */
    rsw_client *c = NULL;
    co.route_key = NULL;
    s = rsw_client_new(&co, &c);
    const char *what = "choosing routing keys";
    if (!s) s = choose_keys(&sp, c);
    if (!s && scene_id) {
      snprintf(sp.scene_id, sizeof sp.scene_id, "%s", scene_id);
    } else if (!s) {
      what = "pushing the scene";
      shard_key(&sp.shards[0]);
      s = rsw_client_set_route(c, sp.shards[0].base);
      if (!s) s = client_scene_push_file(c, o.scene_file, o.variant, sp.scene_id, sp.doc_id, NULL);
    }
    if (!s && o.on_warnings) { /* the whole sweep's dry run, where shard 0 runs */
      what = "checking the sweep";
      shard_key(&sp.shards[0]);
      char *w = NULL;
      s = rsw_client_set_route(c, sp.shards[0].base);
      if (!s) s = rsw_job_check(c, sp.scene_id, x, NULL, &w);
      if (s == RSW_ERR_UNSUPPORTED) s = RSW_OK;
      if (!s && w) o.on_warnings(o.warnings_user, w);
      rsw_free(w);
    }
    if (s) {
      const rsw_error_info *e = rsw_client_last_error(c);
      if (c && e->http_status == 0 && s == RSW_ERR_UNAVAILABLE)
        snprintf(sp.err, sizeof sp.err, "cannot reach %s (%s): the balancer is gone%s",
                 co.base_url ? co.base_url : "the server", e->message,
                 o.state_path ? "; the same call resumes from the state file" : "");
      else
        snprintf(sp.err, sizeof sp.err, "%s%s%s: %s", what, o.scene_file ? " " : "",
                 o.scene_file ? o.scene_file : "", c && e->message[0] ? e->message : rsw_strerror(s));
      rsw_client_free(c);
      goto done;
    }
    rsw_client_free(c);
  }
  sp.deadline = o.timeout_s > 0 ? client_now_s() + o.timeout_s : 0;
  int started = 0;
  for (int k = 0; k < o.shards; k++) {
    if (pthread_create(&th[k], NULL, shard_main, &sp.shards[k]) != 0) {
      set_fatal(&sp, RSW_ERR_NOMEM, "cannot start a thread for shard %d", k);
      break;
    }
    started++;
  }
  for (int k = 0; k < started; k++) pthread_join(th[k], NULL);
  s = sp.fatal;
  if (!s)
    for (size_t i = 0; i < sp.n_ctx; i++)
      if (!sp.done[i]) {
        s = RSW_ERR_MISSING;
        snprintf(sp.err, sizeof sp.err, "context %s was never delivered", client_contexts_id(x, i));
        break;
      }
done:
  if (sp.journal) fclose(sp.journal);
  if (out) {
    out->films = sp.films, out->failed = sp.failed, out->resumed = sp.resumed;
    out->resubmitted = sp.resubmitted, out->contexts_resubmitted = sp.contexts_resubmitted;
    snprintf(out->scene_id, sizeof out->scene_id, "%s", sp.scene_id);
    snprintf(out->route_prefix, sizeof out->route_prefix, "%s", sp.prefix);
  }
  if (sp.shards)
    for (int k = 0; k < o.shards; k++) free(sp.shards[k].idx);
  free(sp.shards);
  free(th);
  free(sp.sorted_ids);
  free(sp.sorted_idx);
  free(sp.done);
  free(sp.lead);
  free(sp.key);
  snprintf(spread_err, sizeof spread_err, "%s", sp.err);
  pthread_mutex_destroy(&sp.lock);
  return s;
}
