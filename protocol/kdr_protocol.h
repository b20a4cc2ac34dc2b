/*
 * kdr_protocol.h — the HTTP/JSON contract (shared/API.md) as C: request
 * bodies in, typed queries for the core out; core results in, response
 * bodies out. No sockets, no scene loading: server/ moves the bytes,
 * protocol/ gives them meaning. Bodies are JSON or CBOR (kdr_media).
 *
 * Conventions:
 *  - Parsers take the body as bytes + length (not NUL-terminated). They
 *    return 0 on success, otherwise the HTTP status (400, 413, 500) which is
 *    also stored in err->status together with a detail naming the field and
 *    element at fault ("directions[17]: not a finite number"). On failure the
 *    request struct holds nothing to free (freeing it is still harmless).
 *  - err and out must not be NULL. Flat JSON number arrays (and CBOR arrays
 *    of numbers) are converted while the body is walked, so up to about
 *    twice (CBOR: four times, one-byte integers) the body size in floats
 *    may be allocated before a 413 is known (bodies are limited by the
 *    server); base64 arrays are decoded, and CBOR typed arrays copied, only
 *    after the limit check.
 *  - Parsed requests own their arrays; the embedded core structs
 *    (kdr_ray_batch, kdr_shadow_query) point into them. Do not copy a request
 *    struct by value and free both copies; free exactly once.
 *  - Encoders append to a kdr_buf and return 0, or KDR_ENOMEM. The buffer's
 *    data is malloc'd: it may be handed to libmicrohttpd with free() as the
 *    free callback (then forget it: set the kdr_buf to {0}).
 *  - Thread safety: every function is reentrant (no global state; the cJSON
 *    error pointer is not used). The one per-thread state is the parse
 *    meter (kdr_proto_meter_set); cJSON's allocation hooks are installed
 *    once, before main, so that cJSON's blocks are counted too.
 *  - Out of memory while parsing (cJSON's nodes included) is a 500 whose
 *    detail says "out of memory", never a 400.
 *
 * Limits (documented in the contract's terms):
 *  - bundle: N rays count as N; frustum: width*height; cone-shadow:
 *    N * L * samples (the worst-case number of shadow rays). Over max_rays
 *    -> 413 "batch of X rays exceeds the limit of M".
 *  - cone-shadow: 1..KDR_PROTO_MAX_LIGHTS lights, samples default
 *    KDR_PROTO_DEFAULT_SAMPLES.
 *  - Numbers given as JSON must fit float32 where the field is a float
 *    (|x| > FLT_MAX is "out of float32 range"), except tmin/tmax, which
 *    saturate to +-infinity (so "tmax": 1e300 means "no limit").
 *  - JSON output never contains nan/inf: a non-finite float (which the core
 *    never produces) is written as null.
 */
#ifndef KDR_PROTOCOL_H
#define KDR_PROTOCOL_H

#include <stddef.h>
#include <stdint.h>

#include "kdray.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- tuning / limits (one place) --------------------------------------- */

#define KDR_PROTO_DEFAULT_MAX_RAYS ((size_t)4194304) /* used when max_rays == 0 */
#define KDR_PROTO_MAX_LIGHTS 64
#define KDR_PROTO_DEFAULT_SAMPLES 64
#define KDR_PROTO_MAX_SAMPLES 4096
#define KDR_PROTO_DEFAULT_SEED 1
/* bundle "query": "all": "max_hits" default and limit (the core's) */
#define KDR_PROTO_DEFAULT_MAX_HITS 16u
#define KDR_PROTO_DEFAULT_TILE 8
#define KDR_PROTO_MIN_TILE 4
#define KDR_PROTO_MAX_TILE 64
#define KDR_PROTO_MAX_IMAGE_SIDE 16384
/* "deadline_ms" (every query kind): 0 < ms <= this (one day). */
#define KDR_PROTO_MAX_DEADLINE_MS 86400000.0

/* ---- parse memory ---------------------------------------------------------- */

/* What a parse may allocate. Every block the parsers allocate on a thread,
 * cJSON's nodes and strings included (through its allocation hooks), is
 * counted at its heap footprint on that thread's meter, and checked BEFORE
 * it is allocated: a block that would take `used` past `limit` first calls
 * grow(ctx, m, more), which may raise m->limit by at least `more` and
 * return 0; otherwise the block fails like malloc, `refused` is set and
 * stays set, and the parse ends with a 500 "out of memory". Frees are
 * counted back, so `used` follows the live bytes and `limit` bounds their
 * peak. What parses take is measured by tests/test_protocol_meter.c. */
typedef struct kdr_proto_meter {
    size_t limit;
    size_t used;
    int (*grow)(void *ctx, struct kdr_proto_meter *m, size_t need); /* may be NULL */
    void *ctx;
    int refused;
} kdr_proto_meter;

/* Makes m the calling thread's meter (NULL: none, nothing is limited) and
 * returns the previous one. */
kdr_proto_meter *kdr_proto_meter_set(kdr_proto_meter *m);

/* ---- output buffer ------------------------------------------------------ */

typedef struct kdr_buf {
    char *data; /* malloc'd, NOT NUL-terminated unless kdr_buf_cstr is called */
    size_t len, cap;
} kdr_buf;

/* A block for a large body or answer, freed with free() (and resizable
 * with realloc): from KDR_BLOCK_HUGE_MIN to KDR_BLOCK_HUGE_MAX bytes it is
 * 2 MiB-aligned, rounded up to whole 2 MiB pages (*usable, when not NULL,
 * gets the rounded size) and advised for transparent huge pages before
 * anything touches it, so that its first touch faults 2 MiB at a time;
 * outside that range, plain malloc (kdr_buf.c says why not above). NULL
 * when out of memory. kdr_buf's growth uses it. */
#define KDR_BLOCK_HUGE_MIN ((size_t)2 << 20)
#define KDR_BLOCK_HUGE_MAX ((size_t)28 << 20)
void *kdr_block_alloc(size_t bytes, size_t *usable);
/* The bytes kdr_block_alloc(bytes) really allocates (its *usable): what a
 * caller that budgets memory charges for the block (bytes up to 2 MiB - 1
 * more than asked inside the huge-page range, else bytes). */
size_t kdr_block_size(size_t bytes);

void kdr_buf_init(kdr_buf *b);
void kdr_buf_free(kdr_buf *b); /* frees data, leaves an empty buffer */
/* Makes room for extra more bytes; 0 or KDR_ENOMEM. */
int kdr_buf_reserve(kdr_buf *b, size_t extra);
int kdr_buf_append(kdr_buf *b, const void *bytes, size_t n);
/* Appends a NUL after the data (not counted in len) and returns data. */
const char *kdr_buf_cstr(kdr_buf *b);

/* ---- errors ---------------------------------------------------------------- */

typedef struct kdr_proto_error {
    int status;        /* HTTP status: 400, 404, 405, 413, 415, 500, 503 */
    char detail[256];  /* "field[index]: what is wrong" */
} kdr_proto_error;

/* Sets status and a printf-formatted detail; returns status. */
int kdr_proto_error_set(kdr_proto_error *err, int status, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
/* "Bad Request", "Not Found", ...; "Error" for statuses not in the list. */
const char *kdr_proto_status_title(int status);
/* The RFC 7807 body: {"type":"about:blank","title":...,"status":...,
 * "detail":...} (Content-Type application/problem+json). */
int kdr_proto_encode_error(const kdr_proto_error *err, kdr_buf *out);

/* ---- requests ---------------------------------------------------------------- */

/* How an answer is written. A request's "encoding" member picks JSON or
 * BASE64; the executor (exec/) writes CBOR instead when content
 * negotiation chose application/cbor (kdr_proto_answer_media). */
typedef enum kdr_encoding {
    KDR_ENCODING_JSON = 0,   /* arrays of numbers */
    KDR_ENCODING_BASE64 = 1, /* {"f32": ...} / {"i32": ...} */
    KDR_ENCODING_CBOR = 2,   /* application/cbor, RFC 8746 typed arrays */
} kdr_encoding;

/* ---- media types (Content-Type, Accept) ------------------------------------ */

typedef enum kdr_media {
    KDR_MEDIA_OTHER = -1, /* not one we read: 415 */
    KDR_MEDIA_JSON = 0,   /* application/json (charset, if given, UTF-8) */
    KDR_MEDIA_CBOR = 1,   /* application/cbor (RFC 8949) */
    /* application/cbor-seq (RFC 8742): an answer only, streamed as a
     * sequence of CBOR items (docs/API.md, "Streamed answers"); chosen only
     * when Accept names it exactly, never through a wildcard */
    KDR_MEDIA_CBOR_SEQ = 2,
} kdr_media;

/* The media type of a request body from its Content-Type (NULL: OTHER). */
kdr_media kdr_proto_media_of(const char *content_type);
/* The media type of a query's answer: the one the Accept header ranks
 * highest (q-values; application/json, application/cbor and the wildcards
 * application/STAR and STAR/STAR, STAR being '*'); on a tie, or with no Accept header, or when Accept names
 * neither (an answer is then still sent, as RFC 9110 allows, rather than a
 * 406), the request's own media type. Errors are always problem+json. */
kdr_media kdr_proto_answer_media(const char *accept, kdr_media request);
/* "application/json" / "application/cbor" / "application/cbor-seq". */
const char *kdr_proto_media_name(kdr_media m);
/* The Content-Type of an answer written with enc. */
const char *kdr_proto_encoding_media(kdr_encoding enc);

/* ---- answer fields ("fields": [...]) ----------------------------------------- */

/* What a bundle or frustum answer holds, as a bit set. Defaults: closest ->
 * t, prim, u, v; any -> hit; all (bundle) -> t, prim, u, v of every hit
 * ("hit" not allowed); count (bundle) -> no fields (0: "fields" refused). "hit" (0/1) may also be asked of a closest
 * query (1 where prim >= 0); t, prim, u, v only of closest queries. New
 * per-ray attributes get the next bits and a row in kdr_fields.c. */
#define KDR_FIELD_T (1u << 0)
#define KDR_FIELD_PRIM (1u << 1)
#define KDR_FIELD_U (1u << 2)
#define KDR_FIELD_V (1u << 3)
#define KDR_FIELD_HIT (1u << 4)
/* per hit, three values each (issue 15): the triangle's unit geometric
 * normal (p1-p0) x (p2-p0), and the glTF node, mesh and primitive it came
 * from; closest and all queries only, never defaults. A miss: 0,0,0 and
 * -1,-1,-1. Encoded only with kdr_hit_attrs (kdr_proto_encode_hits_attrs,
 * kdr_all_answer). */
#define KDR_FIELD_NORMAL (1u << 5)
#define KDR_FIELD_MESH (1u << 6)
#define KDR_FIELDS_ATTRS (KDR_FIELD_NORMAL | KDR_FIELD_MESH)
#define KDR_FIELDS_CLOSEST (KDR_FIELD_T | KDR_FIELD_PRIM | KDR_FIELD_U | KDR_FIELD_V)
#define KDR_FIELDS_ANY KDR_FIELD_HIT

/* POST /v1/scenes/{name}/bundle */
typedef struct kdr_bundle_request {
    kdr_ray_batch batch; /* ready for kdr_trace_batch / kdr_all_batch */
    kdr_query query;     /* closest, any, all or count */
    uint32_t max_hits;   /* all: 1..KDR_MAX_HITS_LIMIT (default 16); else 0 */
    kdr_encoding encoding;
    unsigned fields;     /* KDR_FIELD_* bits, never 0 */
    double deadline_ms;  /* "deadline_ms": 0 when absent */
    float *owned[4];     /* org, dir, tmin, tmax storage (internal) */
} kdr_bundle_request;

/* The parsers read a JSON body (kdr_proto_parse_*) or a body of either
 * media type (kdr_proto_parse_*_as). A CBOR request's float32 typed arrays
 * at 4-byte aligned addresses are used in place: its arrays may point INTO
 * the body, which must then outlive the request. */
int kdr_proto_parse_bundle(const char *body, size_t len, size_t max_rays,
                           kdr_bundle_request *out, kdr_proto_error *err);
int kdr_proto_parse_bundle_as(kdr_media media, const char *body, size_t len,
                              size_t max_rays, kdr_bundle_request *out,
                              kdr_proto_error *err);
void kdr_bundle_request_free(kdr_bundle_request *req);

/* POST /v1/scenes/{name}/cone-shadow */
typedef struct kdr_shadow_request {
    kdr_shadow_query query; /* ready for kdr_shadow_trace */
    int want_stats;         /* "stats": true */
    kdr_encoding encoding;
    double deadline_ms;     /* "deadline_ms": 0 when absent */
    float *owned_points, *owned_normals; /* internal */
    kdr_sphere_light *owned_lights;      /* internal */
} kdr_shadow_request;

int kdr_proto_parse_shadow(const char *body, size_t len, size_t max_rays,
                           kdr_shadow_request *out, kdr_proto_error *err);
int kdr_proto_parse_shadow_as(kdr_media media, const char *body, size_t len,
                              size_t max_rays, kdr_shadow_request *out,
                              kdr_proto_error *err);
void kdr_shadow_request_free(kdr_shadow_request *req);
/* The checks that need the scene, made once its name is resolved: a
 * numeric epsilon whose offset (epsilon * the scene's diagonal, the core's
 * float product) is not finite is a 400 naming "epsilon". 0 or 400. */
int kdr_proto_check_shadow_scene(const kdr_shadow_request *req, float diagonal,
                                 kdr_proto_error *err);

/* POST /v1/scenes/{name}/frustum (owns nothing: no free function) */
typedef struct kdr_frustum_request {
    kdr_camera camera; /* validated: finite, eye != target, up not parallel */
    uint32_t tile;
    kdr_query query;
    kdr_encoding encoding;
    unsigned fields;   /* KDR_FIELD_* bits, never 0 */
    double deadline_ms; /* "deadline_ms": 0 when absent */
    size_t rays;       /* width * height */
} kdr_frustum_request;

int kdr_proto_parse_frustum(const char *body, size_t len, size_t max_rays,
                            kdr_frustum_request *out, kdr_proto_error *err);
int kdr_proto_parse_frustum_as(kdr_media media, const char *body, size_t len,
                               size_t max_rays, kdr_frustum_request *out,
                               kdr_proto_error *err);

/* POST /v1/scenes/{name}/closest-point (protocol/kdr_points.c): N points
 * (counted as N rays against the limit), "max_distance" >= 0 (default and
 * huge values: +inf), "signed" (boolean; not together with max_distance):
 * distances negative inside (kdr_occupancy1). */
typedef struct kdr_closest_request {
    const float *points; /* 3*n, ready for kdr_closest_point_batch */
    size_t n;
    float max_distance;
    int is_signed;
    kdr_encoding encoding;
    double deadline_ms;  /* "deadline_ms": 0 when absent */
    float *owned_points; /* internal */
} kdr_closest_request;

int kdr_proto_parse_closest(const char *body, size_t len, size_t max_rays,
                            kdr_closest_request *out, kdr_proto_error *err);
int kdr_proto_parse_closest_as(kdr_media media, const char *body, size_t len,
                               size_t max_rays, kdr_closest_request *out,
                               kdr_proto_error *err);
void kdr_closest_request_free(kdr_closest_request *req);

/* POST /v1/scenes/{name}/occupancy: N points (N rays against the limit;
 * each costs KDR_OCCUPANCY_RAYS hit counts). */
typedef struct kdr_occupancy_request {
    const float *points; /* 3*n */
    size_t n;
    kdr_encoding encoding;
    double deadline_ms;
    float *owned_points; /* internal */
} kdr_occupancy_request;

int kdr_proto_parse_occupancy_as(kdr_media media, const char *body, size_t len,
                                 size_t max_rays, kdr_occupancy_request *out,
                                 kdr_proto_error *err);
void kdr_occupancy_request_free(kdr_occupancy_request *req);

/* ---- responses ------------------------------------------------------------------ */

/* Bundle / frustum results for rays [0, n): closest ->
 * {"count":N,"t":[...],"prim":[...],"u":[...],"v":[...]}, any ->
 * {"count":N,"hit":[0|1,...]}. closest reads t, prim, u, v; any reads hit.
 * A ray with prim < 0 is written as a miss (t = -1, u = v = 0) whatever the
 * other arrays hold. */
int kdr_proto_encode_hits(const kdr_hits *hits, size_t n, kdr_query query,
                          kdr_encoding enc, kdr_buf *out);
/* The same with a choice of fields (a request's .fields): only those
 * arrays, in the order t, prim, u, v, hit. hit is read from hits->hit for
 * an any query and derived from prim (>= 0) for a closest one. fields must
 * be valid for the query (the parsers ensure it): else KDR_EINVAL. */
int kdr_proto_encode_hits_fields(const kdr_hits *hits, size_t n, kdr_query query,
                                 unsigned fields, kdr_encoding enc, kdr_buf *out);
/* The per-hit attributes of KDR_FIELDS_ATTRS: 3 values per ray (or per
 * hit of an all answer), the executor fills them from the scene. */
typedef struct kdr_hit_attrs {
    const float *normal;  /* 3 per entry */
    const int32_t *mesh;  /* 3 per entry: node, mesh, primitive */
} kdr_hit_attrs;
/* kdr_proto_encode_hits_fields with normal / mesh available (attrs may be
 * NULL when fields asks for neither). */
int kdr_proto_encode_hits_attrs(const kdr_hits *hits, const kdr_hit_attrs *attrs, size_t n,
                                kdr_query query, unsigned fields, kdr_encoding enc,
                                kdr_buf *out);
/* kdr_proto_encode_hits_attrs for arrays already in wire form, as the core
 * writes them (kdray.h: a miss has prim = -1, t = -1, u = v = 0; any-hit
 * bytes are 0 or 1) and the executor fills the attributes (a miss: 0,0,0
 * and -1,-1,-1): the same bytes for such arrays, without the pass that
 * normalises misses (which reads prim again for each of t, u and v): base64
 * is encoded from the arrays themselves, CBOR copied in one piece. */
int kdr_proto_encode_hits_wire(const kdr_hits *hits, const kdr_hit_attrs *attrs, size_t n,
                               kdr_query query, unsigned fields, kdr_encoding enc,
                               kdr_buf *out);

/* The CBOR answer of kdr_proto_encode_hits_attrs, byte for byte, as pieces
 * to be sent one after another (writev; kdrayd's large answers): the small
 * heads (map, "count", each member's name and typed-array head) are
 * written into head, and the arrays are referenced where they lie, so the
 * answer costs no copy of its arrays. The arrays must already be in wire
 * form, as the core writes them (kdray.h: a miss has prim = -1, t = -1,
 * u = v = 0; any-hit bytes are 0 or 1) and as the executor fills the
 * attributes (a miss: 0,0,0 and -1,-1,-1); the one-buffer encoder
 * normalises them on the way, so answers of arrays that break this
 * convention would differ. The one array that has no wire form in memory,
 * "hit" of a closest query (prim >= 0 as bytes), is written into a block
 * of n bytes returned in *hit_bytes (the caller frees it, also when this
 * fails; NULL when not needed). head must be empty: it gets one allocation that never moves, so
 * pieces may point into it. pieces has room for KDR_HITS_PIECES_MAX; empty
 * arrays make no piece. 0, KDR_EINVAL (as kdr_proto_encode_hits_attrs) or
 * KDR_ENOMEM. */
typedef struct kdr_piece {
    const void *data;
    size_t len;
} kdr_piece;
#define KDR_HITS_PIECES_MAX 16
int kdr_proto_hits_pieces(const kdr_hits *hits, const kdr_hit_attrs *attrs, size_t n,
                          kdr_query query, unsigned fields, kdr_buf *head,
                          uint8_t **hit_bytes, kdr_piece *pieces, size_t *npieces);

/* Bundle "query": "all": {"count":N,"nhits":[N],"offset":[N+1], then the
 * chosen fields of t, prim, u, v, each offset[N] long}: ray i's hits are
 * entries offset[i] .. offset[i+1]-1, in increasing t (ties by prim).
 * nhits and offset are int32 ({"i32": ...} in base64, tag 78 in CBOR). */
typedef struct kdr_all_answer {
    size_t n;               /* rays */
    const int32_t *nhits;   /* n */
    const int32_t *offset;  /* n + 1 */
    const float *t, *u, *v; /* offset[n] each (only the chosen fields read) */
    const int32_t *prim;
    kdr_hit_attrs attrs;    /* 3 * offset[n] each, when fields asks */
} kdr_all_answer;
int kdr_proto_encode_all(const kdr_all_answer *a, unsigned fields, kdr_encoding enc,
                         kdr_buf *out);
/* Bound for n rays of at most max_hits hits each (see the hits bound). */
size_t kdr_proto_all_answer_max(size_t n, size_t max_hits, unsigned fields,
                                kdr_encoding enc);
/* Bundle "query": "count": {"count":N,"nhits":[N int32]}. */
int kdr_proto_encode_counts(const uint32_t *counts, size_t n, kdr_encoding enc,
                            kdr_buf *out);
size_t kdr_proto_counts_answer_max(size_t n, kdr_encoding enc);

/* closest-point: {"count":N,"prim":[N int32],"distance":[N],"point":[3N],
 * "u":[N],"v":[N]}; a point with nothing within max_distance has prim -1,
 * distance -1, point 0,0,0, u = v = 0 (as the core leaves it). */
int kdr_proto_encode_closest(const kdr_closest *c, size_t n, kdr_encoding enc,
                             kdr_buf *out);
size_t kdr_proto_closest_answer_max(size_t n, kdr_encoding enc);
/* occupancy: {"count":N,"inside":[N 0|1]} (uint8, tag 64 in CBOR; base64
 * as {"i32": ...} like "hit"). */
int kdr_proto_encode_occupancy(const uint8_t *inside, size_t n, kdr_encoding enc,
                               kdr_buf *out);
size_t kdr_proto_occupancy_answer_max(size_t n, kdr_encoding enc);

/* {"count":N,"visibility":[N*nlights floats]} plus "stats" when stats is
 * not NULL. */
int kdr_proto_encode_shadow(const float *visibility, size_t n, size_t nlights,
                            const kdr_shadow_stats *stats, kdr_encoding enc,
                            kdr_buf *out);

/* The most bytes the two encoders above can need for an answer, known
 * before anything is traced (admission charges it). Encoding into an empty
 * kdr_buf allocates exactly this much once and never grows the buffer;
 * the answer's length is at most this (tests/test_protocol_fields.c checks
 * both for every encoding and field set, with the longest floats). */
size_t kdr_proto_hits_answer_max(size_t n, kdr_query query, unsigned fields,
                                 kdr_encoding enc);
size_t kdr_proto_shadow_answer_max(size_t n, size_t nlights, int stats,
                                   kdr_encoding enc);

/* Scene description, independent of scenes/: the server fills it. */
typedef struct kdr_proto_mesh_range {
    int64_t node, mesh, primitive;  /* glTF indices */
    uint64_t first_prim, count;     /* global triangle numbers */
} kdr_proto_mesh_range;

typedef struct kdr_proto_scene_info {
    const char *name;               /* UTF-8; escaped on output */
    uint64_t triangles;
    kdr_bounds bounds;
    kdr_tree_stats tree;
    const kdr_proto_mesh_range *meshes;
    size_t nmeshes;
} kdr_proto_scene_info;

/* SCENE as in the contract. */
int kdr_proto_encode_scene(const kdr_proto_scene_info *scene, kdr_buf *out);
/* {"scenes":[SCENE,...]} */
int kdr_proto_encode_scenes(const kdr_proto_scene_info *scenes, size_t n,
                            kdr_buf *out);
/* {"status":"ok","scenes":K} */
int kdr_proto_encode_health(const char *status, size_t nscenes, kdr_buf *out);

/* ---- streamed answers (application/cbor-seq, kdr_seq.c) --------------------- */

/* The items of a streamed answer (docs/API.md, "Streamed answers"), each a
 * CBOR map appended to out; 0 or KDR_ENOMEM (KDR_EINVAL for a slice that is
 * not a one-shot CBOR answer map). The head: {"kind", "count" (rays,
 * pixels or points of the whole answer), "items" (chunk items to follow)}. */
int kdr_proto_seq_head(kdr_buf *out, const char *kind, size_t count, size_t items);
/* A chunk item: {"first": first, then every member of slice}, where slice
 * is the one-shot CBOR answer of those rays alone ("count" and the arrays). */
int kdr_proto_seq_item(kdr_buf *out, size_t first, const kdr_buf *slice);
/* The final item after every chunk item: {"status": 200, "rays": traced,
 * "items": sent, "timing": {"queue_us", "parse_us", "trace_us"}} and, when
 * given, the cone-shadow "stats". timing_us: queue, parse, trace (what a
 * one-shot answer's Server-Timing header says; a streamed answer's headers
 * go out before the work is done). */
int kdr_proto_seq_end(kdr_buf *out, uint64_t rays, size_t items,
                      const uint64_t timing_us[3], const kdr_shadow_stats *stats);
/* The final item of a failed answer, the problem details as a map:
 * {"type": "about:blank", "title", "status", "detail"}. */
int kdr_proto_seq_problem(kdr_buf *out, int status, const char *detail);

/* ---- building blocks (public for the tests and the fuzzer) ---------------- */

/* Shortest decimal that reads back as exactly f (JSON number syntax:
 * "-0", "1", "0.1", "1e-45", "3.4028235e38"); "null" for NaN/Inf.
 * Writes KDR_FLOAT_CHARS bytes (one fixed-size copy), no NUL; returns the
 * length, at most KDR_FLOAT_MAX_LEN ("-0.0000123456875": checked for all
 * 2^32 floats by tests/float_exhaustive.c). */
#define KDR_FLOAT_CHARS 24
#define KDR_FLOAT_MAX_LEN 16
size_t kdr_format_float(float f, char *dst);

/* RFC 4648 base64 with padding. encode writes kdr_base64_encoded_len(n)
 * chars (no NUL) and returns that count. */
size_t kdr_base64_encoded_len(size_t n);
size_t kdr_base64_encode(const void *src, size_t n, char *dst);
/* Upper bound of the decoded size of n chars. */
size_t kdr_base64_decoded_max(size_t n);
/* Strict decode (length a multiple of 4, '=' only as final padding, no
 * whitespace, unused bits zero). Returns 0 and the byte count in *out_len,
 * or -1 with the offset of the first bad character in *err_offset (n when
 * the input is truncated). */
int kdr_base64_decode(const char *src, size_t n, void *dst, size_t *out_len,
                      size_t *err_offset);

#ifdef __cplusplus
}
#endif
#endif /* KDR_PROTOCOL_H */
