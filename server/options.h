/*
 * options.h — kdrayd's command line: the flags, their defaults and limits,
 * and --help. Parsing never allocates per flag and never opens anything;
 * main.c acts on the result.
 */
#ifndef KDR_SRV_OPTIONS_H
#define KDR_SRV_OPTIONS_H

#include <stddef.h>

typedef struct kdr_options {
    const char *listen;
    unsigned threads, http_threads;
    size_t max_body_mb, max_rays, max_inflight_mb, max_queue;
    unsigned max_connections;
    unsigned connection_timeout_s; /* an idle connection is closed after this */
    double deadline_ms;     /* 0: none */
    double grace_s;         /* shutdown: seconds for requests in flight */
    int worker_nice;        /* added to the workers' nice value */
    const char *access_log; /* NULL: off; "-": stdout */
    int log_level;          /* kdr_log_level */
    const char *cache_dir;  /* NULL: build every tree at every start */
    char **scene_args;      /* NAME=PATH, pointing into argv */
    size_t nscenes;
} kdr_options;

/* Returns -1 to go on, or an exit status: 0 after --help/--version, 2 after
 * a one-line error on stderr, 1 out of memory. */
int kdr_options_parse(kdr_options *o, int argc, char **argv);
void kdr_options_free(kdr_options *o);

#endif
