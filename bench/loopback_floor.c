/*
 * loopback_floor.c — the floor under kdrayd's transport on this machine: how
 * long N bytes take over a TCP loopback connection between two threads of
 * one process, with nothing else done to them (issue 16, round arrive). Not
 * a test; kdrayd's Server-Timing "body" step and the answer's transfer are
 * compared against what it prints (docs/BENCHMARKS.md).
 *
 *   kdray-loopback-floor [--bytes N] [--reps R]
 *
 * A sender thread writes N bytes (default 24 MiB, a 1M-ray CBOR bundle with
 * an origin a ray) in one send() call, as kdray_bench_e2e's client does; the
 * receiver reads them in each of these ways, R times each (default 7),
 * interleaved so that the machine's load falls on all of them alike:
 *   mhd16k   poll() before every read, 16 KiB reads into a scratch buffer,
 *            each copied into the final buffer: what libmicrohttpd 0.9.75
 *            with kdrayd's 32 KiB connection pool and kdr_http_append do
 *            (its read buffer is half the pool);
 *   mhd64k, mhd128k  the same with 64 and 128 KiB reads (pools of 128
 *            and 256 KiB);
 *   r16k, r128k  16 or 128 KiB reads straight into the final buffer, no
 *            poll, no copy;
 *   whole    one read call asking for everything that is left.
 * It prints, per way, the median and best wall time from the first byte
 * read to the last, the receiver thread's CPU time (CLOCK_THREAD_CPUTIME_ID)
 * and the number of read calls. The final buffer is touched before the
 * first pass so that page faults are not counted.
 */
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

enum { WAYS = 6, MAX_REPS = 64, MHD_LIKE_MAX = 128 * 1024 };
/* How each way reads: piece size (0: all that is left), and whether it
 * polls before every read and copies from a scratch buffer as
 * libmicrohttpd and kdr_http_append do. */
static const struct {
    const char *name;
    size_t piece;
    int mhd_like;
} WAY[WAYS] = {{"mhd16k", 16 * 1024, 1}, {"mhd64k", 64 * 1024, 1},
               {"mhd128k", 128 * 1024, 1}, {"r16k", 16 * 1024, 0},
               {"r128k", 128 * 1024, 0}, {"whole", 0, 0}};

typedef struct pipe_link {
    int port;
    size_t bytes;
    int passes;
} pipe_link;

static double clock_ms(clockid_t id) {
    struct timespec ts;
    clock_gettime(id, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static void die(const char *what) {
    perror(what);
    exit(1);
}

/* Sends the bytes once per pass, then waits for the receiver's one-byte
 * go-ahead, so that passes never overlap. */
static void *sender(void *arg) {
    const pipe_link *l = arg;
    const int fd = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in a = {.sin_family = AF_INET,
                            .sin_port = htons((uint16_t)l->port),
                            .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
    if (fd < 0 || connect(fd, (struct sockaddr *)&a, sizeof a) != 0) die("connect");
    const int one = 1;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    char *data = malloc(l->bytes);
    if (!data) die("malloc");
    memset(data, 0x5a, l->bytes);
    for (int p = 0; p < l->passes; p++) {
        for (size_t off = 0; off < l->bytes;) {
            const ssize_t k = send(fd, data + off, l->bytes - off, MSG_NOSIGNAL);
            if (k < 0 && errno == EINTR) continue;
            if (k <= 0) die("send");
            off += (size_t)k;
        }
        char go;
        if (recv(fd, &go, 1, 0) != 1) die("recv go-ahead");
    }
    free(data);
    close(fd);
    return NULL;
}

/* One pass: reads l->bytes the way `way` says; wall and CPU ms, read calls. */
static void receive(int fd, int way, char *dst, char *scratch, size_t bytes, double *wall,
                    double *cpu, long *calls) {
    const size_t piece = WAY[way].piece ? WAY[way].piece : bytes;
    const int mhd_like = WAY[way].mhd_like;
    const double w0 = clock_ms(CLOCK_MONOTONIC), c0 = clock_ms(CLOCK_THREAD_CPUTIME_ID);
    size_t got = 0;
    long n = 0;
    while (got < bytes) {
        if (mhd_like) {
            struct pollfd p = {.fd = fd, .events = POLLIN};
            if (poll(&p, 1, -1) < 0 && errno != EINTR) die("poll");
        }
        const size_t want = piece < bytes - got ? piece : bytes - got;
        char *into = mhd_like ? scratch : dst + got;
        const ssize_t k = recv(fd, into, want, 0);
        if (k < 0 && errno == EINTR) continue;
        if (k <= 0) die("recv");
        if (mhd_like) memcpy(dst + got, scratch, (size_t)k);
        got += (size_t)k;
        n++;
    }
    *wall = clock_ms(CLOCK_MONOTONIC) - w0;
    *cpu = clock_ms(CLOCK_THREAD_CPUTIME_ID) - c0;
    *calls = n;
}

static int cmp_double(const void *a, const void *b) {
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median(double *v, int n) {
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

int main(int argc, char **argv) {
    size_t bytes = 24u << 20;
    int reps = 7;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--bytes") && i + 1 < argc) {
            bytes = strtoull(argv[++i], NULL, 10);
        } else if (!strcmp(argv[i], "--reps") && i + 1 < argc) {
            reps = atoi(argv[++i]);
        } else {
            fprintf(stderr, "usage: %s [--bytes N] [--reps R (1-%d)]\n", argv[0], MAX_REPS);
            return 2;
        }
    }
    if (bytes == 0 || reps < 1 || reps > MAX_REPS) {
        fprintf(stderr, "%s: --bytes must be > 0 and --reps 1-%d\n", argv[0], MAX_REPS);
        return 2;
    }
    const int lfd = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
    socklen_t alen = sizeof a;
    if (lfd < 0 || bind(lfd, (struct sockaddr *)&a, sizeof a) != 0 || listen(lfd, 1) != 0 ||
        getsockname(lfd, (struct sockaddr *)&a, &alen) != 0)
        die("listen");
    pipe_link l = {.port = ntohs(a.sin_port), .bytes = bytes, .passes = reps * WAYS};
    pthread_t th;
    if (pthread_create(&th, NULL, sender, &l) != 0) die("pthread_create");
    const int fd = accept(lfd, NULL, NULL);
    if (fd < 0) die("accept");
    char *dst = malloc(bytes), *scratch = malloc(MHD_LIKE_MAX);
    if (!dst || !scratch) die("malloc");
    memset(dst, 0, bytes);
    static double wall[WAYS][MAX_REPS], cpu[WAYS][MAX_REPS];
    long calls[WAYS] = {0};
    for (int r = 0; r < reps; r++)
        for (int w = 0; w < WAYS; w++) {
            receive(fd, w, dst, scratch, bytes, &wall[w][r], &cpu[w][r], &calls[w]);
            if (send(fd, "g", 1, MSG_NOSIGNAL) != 1) die("send go-ahead");
        }
    pthread_join(th, NULL);
    printf("%zu bytes over TCP loopback, one send() call; %d passes each, interleaved\n",
           bytes, reps);
    printf("%-8s %9s %9s %9s %9s %7s\n", "read", "wall med", "wall best", "GB/s med",
           "cpu med", "reads");
    for (int w = 0; w < WAYS; w++) {
        double best = wall[w][0];
        for (int r = 1; r < reps; r++)
            best = wall[w][r] < best ? wall[w][r] : best;
        const double wm = median(wall[w], reps), cm = median(cpu[w], reps);
        printf("%-8s %9.2f %9.2f %9.2f %9.2f %7ld\n", WAY[w].name, wm, best,
               (double)bytes / (wm * 1e6), cm, calls[w]);
    }
    printf("(ms; reads: of the last pass; cpu: the receiving thread's)\n");
    free(dst);
    free(scratch);
    close(fd);
    close(lfd);
    return 0;
}
