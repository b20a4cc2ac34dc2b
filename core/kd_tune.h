/*
 * kd_tune.h — every performance knob of the core in one place (pbrt keeps
 * its SAH constants in the accelerator's constructor; we keep all of ours
 * here). Each value says what it trades and how it was measured. Nothing
 * here changes an answer: every traversal returns the same hits whatever
 * these are. Correctness margins (slacks, paddings, hard limits) stay
 * beside the code they protect (kd_traverse.h, kd_internal.h, kd_build.c).
 */
#ifndef KD_TUNE_H
#define KD_TUNE_H

/* ---- SAH build (kd_build.c, defaults of kdr_build_opts) ------------------ */

/*
 * SAH constants (pbrt-v3's values). Measured
 * on 2CylinderEngine (121K triangles) and lat-long spheres (2K-1M) with
 * random and camera rays: trav_cost 1..40 and empty_bonus 0.5..0.8 change
 * rays/s by less than the run-to-run noise; empty_bonus <= 0.2 grows the
 * tree 5x (perfect splits then keep cutting straddlers) and is slower.
 * Since single-ray leaves are tested 4 and 8 triangles at a time (SIMD),
 * leaves of up to 12 triangles (pbrt: 1; 3 before the SIMD leaves) build
 * 15-35% faster and trace random, AO and shadow rays 10-40% faster on
 * default.glb, haus, 2CylinderEngine, engine3 and the 1M sphere; with them
 * the depth limit 6 + 1.3 log2 N (kd_build.c) no longer costs the 1M
 * sphere anything (depth 32 / leaf 12 beats pbrt's 34 / leaf 3 there).
 */
#define KD_ISECT_COST 80.0f
#define KD_TRAV_COST 1.0f
#define KD_EMPTY_BONUS 0.5f
#define KD_LEAF_SIZE 12

/* pbrt's termination: splits that cost more than the leaf they replace are
 * tolerated KD_BAD_REFINES times on a path, and never below KD_BAD_SMALL
 * references. */
#define KD_BAD_REFINES 3
#define KD_BAD_SMALL 16
/* Default depth limit KD_DEPTH_BASE + KD_DEPTH_PER_LOG2 * log2(N): pbrt uses
 * 8 + 1.3 log2 N; 6 builds 20-25% faster and smaller trees with the same
 * single-ray speed (measured on haus, 2CylinderEngine, engine3), because
 * the last levels mostly re-split clusters of tiny triangles that no plane
 * separates. */
#define KD_DEPTH_BASE 6.0
#define KD_DEPTH_PER_LOG2 1.3

/* ---- binned and parallel build (kd_build*.c) -------------------------------
 * Nodes with more than KD_EXACT_MAX triangles choose their plane from
 * KD_BINS min-max bins per axis (Mitsuba 0.6's scheme and its 65536),
 * smaller ones by the exact sweep over sorted events. Measured
 * (kdray-tree-digest, kdray_bench_build --section ab, 262144 rays): at
 * 65536 the trees cost 0.6-4.7% less SAH than exact-everywhere on engine,
 * distinct and engine9 (+0.9% on engine3), triangle tests per AO ray
 * -31% / +3% (engine / engine9), ray speeds within noise, and one-thread
 * builds 11-14% faster on engine3, distinct, engine9; at 16384 builds are
 * another 5-7% faster but haus AO rays test 17% more triangles and engine
 * ones 2.5% more. A subtree with at least
 * max(KD_SPAWN_MIN, N / (KD_TASKS_PER_THREAD * threads)) triangles is
 * handed to another build thread. */
#define KD_EXACT_MAX 65536
#define KD_BINS 256
#define KD_SPAWN_MIN 4096
#define KD_TASKS_PER_THREAD 16
/* Build scratch arrays (kd_scratch_alloc, kd_mem.c) of at least this many bytes go to
 * 2 MiB transparent huge pages. */
#define KD_SCRATCH_HUGE_MIN ((size_t)1 << 20)
/* A worker's stack of children's event lists (kd_build_events.c) is made
 * this many times the first split's worst case: room for the lists down a
 * path (haus needed more than 3; pages that are never touched cost
 * nothing). A node that does not fit gets a block of its own instead.
 * test_core_build_stack1 builds with 1, so that every path overflows. */
#ifndef KD_STACK_SLACK
#define KD_STACK_SLACK 8
#endif

/* ---- single rays (kd_traverse_single.c) ----------------------------------- */

/* Leaves with at least this many references are tested four at a time,
 * and on AVX2 CPUs those with at least KD_LEAF_AVX2_MIN eight at a time. */
#define KD_LEAF_SIMD_MIN 3
#define KD_LEAF_AVX2_MIN 8

/* ---- interleaved walks of a batch's incoherent rays (kd_traverse_stream.c) */

/* Rays in flight per thread in the scalar form (the AVX-512 and AVX2
 * forms have 16 and 8, one per lane). */
#define KD_STREAM_RAYS 8
/* Scenes whose nodes, references and triangles take at least this many
 * bytes (kdr_tree_stats.bytes) are walked with every next node requested
 * as soon as it is known and a leaf's triangles requested one turn before
 * their test. */
#define KD_STREAM_STAGE_MIN_BYTES ((size_t)16 << 20)
/* kdr_trace_batch sends a chunk of incoherent rays to the interleaved walk
 * without trying bundles when its origins change at least every this many
 * rays on average (AO rays of one point share theirs: bundles). */
#define KD_STREAM_MAX_RUN 2
/* ... and on scenes of at least this many bytes when a chunk holds more
 * than one origin (a chunk with a single origin, a cone's samples of one
 * point, stays with bundles: through the interleaved walk cone64 ran at
 * 0.82 on the 1.09M scene and 0.73 on the distinct 1M one, bench/ab 2f3b672
 * 9c08ffa and 01c9790 bd29679).
 * bench/ab, batches of AO rays (16 per point, 4096 per call), interleaved /
 * bundles: any hit 0.79 on haus (2 MiB), 0.98-1.05 on 2CylinderEngine
 * (6 MiB), 1.16 on engine3 (20 MiB), 1.42 on the 1.09M scene (59 MiB);
 * closest hit 0.78, 0.97, 1.15, 1.33. Batches with one shared origin
 * (stride 0) stay with bundles on every scene: the interleaved walk lost
 * there (64-ray AO batches 0.64-0.90, cone samples 0.77-1.00). */
#define KD_STREAM_RUNS_MIN_BYTES ((size_t)8 << 20)

/* ---- leaves of every walk (kd_layout.c) ------------------------------------ */

/* Scenes whose triangles, references and nodes take at least this many
 * bytes are walked with every triangle of a leaf requested (prefetched)
 * before its tests, so their cache misses overlap. bench/ab, 8-wide AO
 * bundles: +21 % (2CylinderEngine, 6 MB) and +25 % (1.09M, 59 MB); 4-frusta
 * +15 % on the 1.09M scene; but -2 % and -6 % on a 3K-triangle scene that
 * lives in L2 anyway, hence the threshold (a core's L2 is 1 MiB here). */
#define KD_PREFETCH_MIN_BYTES ((size_t)1 << 20)

/* ---- scene memory (kd_mem.c) ------------------------------------------------
 * Arrays of a scene (triangles, nodes, references) of at least this many
 * bytes are 2 MiB-aligned and advised for transparent huge pages; smaller
 * ones stay plain malloc, where rounding up to a 2 MiB page would waste
 * more than it saves (a 1 MiB array fits a core's L2 TLB reach anyway). */
#define KD_HUGE_MIN_BYTES ((size_t)1 << 20)

/* ---- bundles (kd_batch.c, kd_traverse_bundle_run.h) ------------------------
 * Rays are bundled in chunks of KB_CHUNK; a chunk whose mean direction
 * spread per 8 rays exceeds KB_SORT_SPREAD is regrouped by direction first. */
#define KB_CHUNK 256
#define KB_SORT_SPREAD 0.5f
/* Rays are incoherent when the average lane occupancy (active lanes per
 * node step / lanes that entered the tree) of a chunk's first KB_PROBE or
 * more bundles falls under KB_OCC_MIN; the rest of the chunk and the next
 * KB_FALLBACK_CHUNKS chunks of the batch then go through the interleaved
 * walk (kd_stream_trace), in the caller's order (no regrouping), after
 * which the next chunk probes again. Chunks that kd_batch_scattered calls
 * scattered go there without a probe (KB_FALLBACK flag only). */
#define KB_OCC_MIN 0.3
#define KB_PROBE 4
#define KB_FALLBACK_CHUNKS 4
/* Any-hit chunks of rays with their own origins whose ends (o + tmax d)
 * lie in a box narrower than KD_FAR_END_SPREAD times their origins' box
 * (widest axis of each) walk far end first (kd_batch_far_first): shadow
 * rays toward one light. docs/TRAVERSAL.md, "Round: far end first". */
#define KD_FAR_END_SPREAD 0.25f
/* Such chunks first trace KD_FAR_PROBE_RAYS rays each way, then walk far
 * end first while that order's work per ray (node steps + triangle tests)
 * stays under KD_FAR_GAIN times the other's (kd_far_pick). */
#define KD_FAR_PROBE_RAYS 32
#define KD_FAR_GAIN 0.85
/* Any-hit chunks whose ends are finite but do not cluster (AO rays: short,
 * from surface points, ends around their origins) walk far end first in
 * the interleaved walk, without a probe, and their runs of shared origins
 * go to that walk from scenes of KD_FAR_RUNS_MIN_BYTES (not
 * KD_STREAM_RUNS_MIN_BYTES); below it they stay front to back in bundles.
 * bench/ab main, AO 16 / 64 rays per point in calls of 4096 (bao / bao64),
 * far walk against the front-to-back route before: haus (2 MiB) 0.94 /
 * 0.88 (bundles stay), 2CylinderEngine (6 MiB) 1.29 / 1.08, engine3 1.83 /
 * 1.65, engine9 1.60 / 1.40; far bundles instead lost on bao64 (0.90,
 * 0.91): they give up the origin's path replay. The probe's work count
 * (node steps + tests, replayed levels included) misjudges these rays and
 * one point per call decides it (bao64 engine3 1.37 with it against 1.67
 * without). docs/TRAVERSAL.md, "Round: AO batches". */
#define KD_FAR_RUNS_MIN_BYTES ((size_t)4 << 20)
/* ...where every sampled ray is at most KD_FAR_SPREAD_MAX_LEN times the
 * scene's diagonal long (AO rays reach 0.1 of it in the benchmarks).
 * Longer rays whose ends spread (shadow rays of many points toward a large
 * light: KB_ENDS_LONG) walk far end first in the interleaved walk too, but
 * neither go there in runs from KD_FAR_RUNS_MIN_BYTES nor stage their
 * leaves from KD_FAR_STAGE_MIN_BYTES: on 2CylinderEngine, one shadow ray per
 * camera hit point toward bench/ab's large light (set bcamlarge) ran 1.28x
 * faster unstaged with the same node steps and tests (bench/ab, 3 rounds,
 * load 1.6-2.7; haus, engine3, engine9 0.98-1.03: haus is under 4 MiB, the
 * other two stage from 16 MiB anyway); front to back instead lost on haus
 * (0.845). Staging had also cost cone queries' large-light samples there
 * (kdray_bench_cone, 2CylinderEngine large light 8 spp 0.66 -> 0.34x Embree
 * before round conelow took them off kdr_trace_batch). */
#define KD_FAR_SPREAD_MAX_LEN 0.25f
/* Those far walks stage their leaves (KD_STREAM_STAGE) from this size on
 * (others from KD_STREAM_STAGE_MIN_BYTES): their ends scatter over the
 * scene, so each far descent misses where a shadow ray's shares the
 * light's path. bench/ab 0678403 ., staged from 1 MiB, 5 rounds:
 * 2CylinderEngine bao / bao64 / bao1 1.083 / 1.040 / 1.172, haus bao1
 * 0.840; shadow rays' far walks staged lost (bshadow 0.765 / 0.835), so
 * they keep the old threshold. */
#define KD_FAR_STAGE_MIN_BYTES ((size_t)4 << 20)
/* kdr_occluded1 (one ray, any hit) walks a ray far end first
 * (kd_occluded1_far's order) when its tmax is finite, front to back
 * otherwise (a ray without an end has no far cell to start from).
 * bench/ab main ., 65536 rays, 3 rounds, load 3.7-5.1, default / haus /
 * 2CylinderEngine / engine3 / engine9: ao 1.22 / 1.45 / 1.23 / 1.42 /
 * 1.30, ao64 1.18 / 1.37 / 1.22 / 1.25 / 1.07, shadow (random surface
 * points) 1.30 / 4.18 / 3.47 / 3.79 / 3.27, camshadow (camera hit points)
 * 0.99 / 1.12 / 1.02 / 1.23 / 1.33 (5 rounds on 2CylinderEngine: 0.967,
 * its far walk takes 3 % more node steps). No per-ray rule on the
 * root-clipped segment kept the shadow gains and avoided camshadow's
 * loss: far first only when the end lies inside the root box or the
 * segment is under 0.2 of its diagonal gave default / 2CylinderEngine
 * shadow 0.98 / 2.39 and camshadow 0.96 / 0.94. docs/TRAVERSAL.md,
 * "Round: AO single rays". */
#define KD_FAR1_FINITE 1

/* ---- cone shadows (kd_cone.c, kd_cone_cells.c) ------------------------------
 * Measured with kdray_bench_cone (default scene and 2CylinderEngine, a small
 * and a large light each, auto offsets, kd_cone time against the strongest
 * Embree API in the same run), at 10b8208 and after. */

/* Forced walks (KD_WALK_ALWAYS; kdr_shadow_trace's cheap test below sends
 * such points to bundles without a walk): below this many samples the walk
 * only looks for an empty cone, stopping at its first candidate, and
 * everything else goes through the tree (bundles, or one by one under
 * TREE_MIN_RAYS), after the light's last blocker. A walk with its proofs
 * costs about what 8 rays do, and below 9 samples it decides too little
 * to repay it: rays only at 1-8 spp 0.36-0.62x against walks 0.11-0.49x;
 * at 16 spp walks won on three of the four views against rays traced
 * point by point (0.50-0.68x against 0.38-0.55x; chunked bundles, below,
 * beat both). */
#define CONE_RAYS_BELOW 9u
/* The whole light's walk is over budget past CONE_MAX_CANDS candidates (the
 * triangles its cull keeps that no proof dismisses) or CONE_NODES_BASE +
 * CONE_NODES_PER_SAMPLE * samples nodes: the cone is then "busy" and its
 * samples are traced otherwise. Below CONE_WALK_MIN_SAMPLES samples the
 * candidate budget is CONE_FEW_CANDS: a walk that meets more than a couple
 * of candidates seldom decides the point, and stopping early halves its
 * cost (16 spp: 2 candidates 0.35-0.66x, 4: 0.34-0.65x, 32: 0.26-0.64x).
 * 64 candidates instead of 32 lost 2-15% at 64 and 256 spp. */
#define CONE_MAX_CANDS 32u
#define CONE_FEW_CANDS 2u
#define CONE_WALK_MIN_SAMPLES 32u
#define CONE_NODES_BASE 24u
#define CONE_NODES_PER_SAMPLE 6u
/* A cell (sub-cone) holding at most this many samples tests them against
 * its candidates instead of splitting again. Splitting further costs more
 * than it saves: at 256 spp, leaves of 8 / 16 / 32 / 64 / 128 samples ran
 * 1.90 / 2.06 / 2.07 / 2.27 / 2.33x (default, small light), 2.42 / 2.90 /
 * 2.99 / 3.20 / 3.18x (engine, small light); large lights 0.76-0.86x
 * whatever the size. */
#define CELL_LEAF_SAMPLES 64u
/* Busy cones: the samples are cut into packets of 4 or 8 neighbours on the
 * light's disc, each walking its own narrow cone; a packet's lanes still
 * undecided after GROUP_MAX_NODES nodes go through the tree one by one. */
#define GROUP_MAX_NODES 512u
/* A packet whose cone is wider than this (radians) is traced as rays: a wide
 * cone reaches far more leaves than its rays do (measured on 2CylinderEngine:
 * packets win for a 3-degree light at 64+ spp, lose for a 30-degree one). */
#define GROUP_MAX_ANGLE 0.035
/* After a whole-light walk over budget the next 1, 3, 7, then 15 points of
 * that light skip the walk (neighbouring points see the same busy cone);
 * any successful walk resets the back-off. Answers are the same either way. */
#define WALK_BACKOFF_MAX 15u
/* Samples of a point going through the tree above which closest hits are
 * spent to learn blockers first (learn_blockers), and how many. */
#define LEARN_MIN 8u
#define LEARN_ROUNDS 3u
/* Fewer pending samples than this go through the tree one by one: a batch's
 * set-up (grouping, sorting) costs more than a bundle saves (bench_cone at
 * 2 spp: bundles 0.0018 s vs single rays 0.0015 s on default/small). */
#define TREE_MIN_RAYS 3u

/* The cheap test (kd_cone.c, kd_walk_pays): below CONE_WALK_FROM samples per
 * point no whole-light cone walks; the samples of UNWALKED_CHUNK_RAYS / (S x
 * lights) consecutive points go through the tree in one call (any-hit
 * bundles, or the interleaved walk: UNWALKED_STREAM_* below), with no
 * cone set-up. A walk (with its proofs)
 * costs more than the 1-16 rays it may save even where it decides the
 * point, and over the chunk the batch's set-up is paid once. Measured with
 * kdray_bench_cone (default and 2CylinderEngine, small and large light,
 * --repeat 3), kd_cone against the strongest Embree API, walks (bbaa220)
 * against chunked bundles: 1-8 spp 0.08-0.49x -> 0.44-0.83x; 16 spp
 * 0.26-0.67x -> 0.46-0.73x; 32 spp small lights 0.73 / 1.04x -> 0.63 /
 * 0.76x (walks kept), large lights 0.36 / 0.43x -> 0.50 / 0.75x. A
 * per-light moving average of the samples walks saved (walk only where it
 * repays, probe one point in 8 otherwise) lost to both at 16-256 spp.
 * Stop 29, with the sampler 4.5x cheaper (82ee76d): `kdray_bench_cone
 * --section cone_split`, small lights, walks (auto) against none (never),
 * same process: 32 spp default 5.09 / 4.12 ms, 2CylinderEngine 2.19 /
 * 2.27, engine9 3.46 / 2.67; 64 spp 5.91 / 7.41, 2.31 / 3.82, 3.69 / 4.16
 * (walks win): from 32 to 64. */
#define CONE_WALK_FROM 64u
/* From CONE_WALK_FROM samples on, a point whose light is wider than
 * CONE_WIDE_SIN (sin of the cone's half-angle; 0.1 is 5.7 degrees) walks
 * only from CONE_WALK_WIDE_FROM samples on; below, its samples go through
 * the tree with those of the unwalked points (chunks of
 * UNWALKED_CHUNK_RAYS: since stop 28; before, one kdr_trace_batch call per
 * point, 8-11 % slower at 64 spp toward the large lights). Tuned on the benchmark's two light sizes only (small:
 * about 2 degrees, large: about 27), large lights, walks against bundles
 * (every point unwalked): default 0.35 / 0.48 / 0.64 / 0.79x against 0.50 /
 * 0.53 / 0.56 / 0.59x at 32 / 64 / 128 / 256 spp, 2CylinderEngine 0.44 /
 * 0.57 / 0.73 / 0.87x against 0.76 / 0.76 / 0.78 / 0.83x. Stop 29, after
 * the sampler became 4.5x cheaper (82ee76d): `kdray_bench_cone --section
 * cone_split`, large lights, walks (auto at 128) against none (never) at
 * 128 spp: default 28.1 / 27.9 ms, 2CylinderEngine 17.7 / 13.5 ms, engine9
 * 16.0 / 13.5 ms; at 256 spp walks still win (default 43.4 / 53.2 ms,
 * 2CylinderEngine 26.6 / 25.3, engine9 22.7 / 24.8): from 128 to 256.
 * Then the unwalked samples went through the tree in disc order
 * (UNWALKED_ORDER_FROM, 288c98d) and walks lost at every count measured
 * (auto = walks from 256 against never, same process): 256 spp default
 * 47.2 / 39.2 ms, 2CylinderEngine 26.1 / 17.4, engine9 24.4 / 18.0; 512
 * spp 77.3 / 67.2, 44.3 / 32.4, 37.3 / 32.1; 2048 spp default 397 / 246,
 * 2CylinderEngine 226 / 117. So a wide light's cone never walks (4097 is
 * above the contract's 4096 samples). Measured on the benchmark's two
 * light sizes only (about 2 and 27 degrees): a light just above
 * CONE_WIDE_SIN has no row of its own. */
#define CONE_WIDE_SIN 0.1
#define CONE_WALK_WIDE_FROM 4097u
#define UNWALKED_CHUNK_RAYS 1024u
/* From this many samples on, a pair's unwalked samples are traced in the
 * order of their positions on the light's disc (kd_cone_sample.c,
 * kd_shadow_disc_order) and the chunk's bundles are not sorted by direction. */
#define UNWALKED_ORDER_FROM 16u
/* The route of those chunks (kd_cone_query.c, trace_chunk): at 1 to
 * UNWALKED_STREAM_MAX_SAMPLES samples on scenes of at least samples x
 * UNWALKED_STREAM_BYTES_PER_SAMPLE bytes the interleaved walk, far end
 * first; else bundles without kdr_trace_batch's fallback to the
 * interleaved walk (its tests, tuned on AO rays, sent a wide light's 1-2
 * samples on every scene, and its 4-16 on scenes over 8 MiB, there).
 * kdray_bench_cone, kd_cone against Embree, 17ed08b's binary and this
 * one alternated twice (load 2.6-3.7; docs/TRAVERSAL.md, round "few
 * samples"): 2 spp large light default 0.29 -> 0.45x, haus 0.40 -> 0.57x,
 * 2CylinderEngine 0.41 -> 0.55x, engine3 0.44 -> 0.57x, engine9 0.50 ->
 * 0.66x; 1 spp small light 2CylinderEngine 0.47 -> 0.64x; engine3 /
 * engine9 large light 4 spp 0.44 / 0.48 -> 0.56 / 0.54x, 8 spp 0.44 /
 * 0.47 -> 0.66 / 0.63x, 16 spp 0.41 / 0.44 -> 0.87 / 0.83x; no row lost
 * more than 4%. Each route measured against the others in one build
 * (interleaved far first / front to back / bundles with no fallback): on
 * default (0.3 MB) bundles won at 1-2 spp (small light 0.50 / 0.53x
 * against 0.42 / 0.34x far first); from haus (2 MB) up the far-first walk
 * won at 1 spp (haus large light 0.61 against 0.53x), from
 * 2CylinderEngine (6 MB) up at 2 spp (engine3 large light 0.59 against
 * 0.45x; 2CylinderEngine a tie, 0.53-0.56 against 0.50-0.55x); at 4 spp
 * bundles won but on engine3 / engine9's large light (a tie); front to
 * back lost everywhere. */
#define UNWALKED_STREAM_MAX_SAMPLES 2u
#define UNWALKED_STREAM_BYTES_PER_SAMPLE ((uint64_t)3 << 19)
/* ... and of the bundles: on scenes of at least UNWALKED_NARROW_MIN_BYTES,
 * chunks of 3 to UNWALKED_NARROW_MAX_SAMPLES samples go to 8-lane bundles
 * even with AVX-512 (one or two points a bundle instead of two to five).
 * Measured in one build (8 lanes against 16, kdray_bench_cone --only haus
 * --only engine3 --only engine9 [--only default --only engine]
 * --ref-samples 0 --repeat 3, kd_cone against Embree, two runs each, load
 * 4.3-5.8): 8 spp small / large light 2CylinderEngine 0.84 0.83 / 0.74
 * 0.75x against 0.80 0.79 / 0.70 0.67x, engine3 0.84 0.82 / 0.78 0.77x
 * against 0.81 0.79 / 0.69 0.66x, engine9 0.89 0.90 / 0.82 0.72x against
 * 0.78 0.81 / 0.66 0.66x; 4 spp engine3 large 0.61 0.61 against 0.56
 * 0.55x, engine9 small / large 0.70 0.67 / 0.67 0.66x against 0.64 0.63 /
 * 0.58 0.58x, 2CylinderEngine within 3%; 3 spp engine3 / engine9 large
 * 0.53-0.57 against 0.49-0.51x. It lost on haus (2 MB; 8 spp small 0.77
 * 0.78 against 0.79 0.80x) and default (4 spp large 0.43 against 0.46
 * 0.47x), and at 16 spp everywhere (engine9 0.69 / 0.65x against 0.88 /
 * 0.86x, one point fills a 16-lane bundle); 4 lanes at 4 spp lost
 * everywhere (default large 0.30 against 0.46x). */
#define UNWALKED_NARROW_MAX_SAMPLES 8u
#define UNWALKED_NARROW_MIN_BYTES ((uint64_t)4 << 20)
/* Shared walks (kd_cone_query.c trace_grouped, kd_cone_group.c): up to
 * GROUP_POINTS consecutive points walk one cone toward a light when the
 * ball around their apexes is at most GROUP_MAX_SPREAD times the light's;
 * the group's walk is over budget (the points then walk on their own) past
 * GROUP_MAX_CANDS triangles or GROUP_WALK_NODES_BASE +
 * GROUP_WALK_NODES_PER_POINT x points nodes. Flat around these values on
 * the 1024x768 64-spp default render (callgrind, instructions of the
 * picture, at 55b8c0d): spread 0.8 +0.3 %, 32 candidates +0.3 %, 8 points
 * +1.0 %, 32 points +6.6 %; failed groups cut into halves down to 4 points
 * +3.8 %. */
#define GROUP_POINTS 16u
#define GROUP_MAX_SPREAD 0.5
#define GROUP_MAX_CANDS 64u
#define GROUP_WALK_NODES_BASE 64u
#define GROUP_WALK_NODES_PER_POINT 16u
/* A run whose group cone does not exist (its apexes too spread out: a
 * square of pixels across a depth step) is cut in two by position (the
 * middle of its apexes' box), up to GROUP_SPLITS times, while both parts
 * keep at least GROUP_SPLIT_MIN points. callgrind of the 1024x768 64-spp
 * pictures (kdray-bench-render --repeat 1): default 4.020G -> 3.954G with
 * 1 cut (2, 3 or 4 cuts: 3.954G; at least 4 points a part: 3.983G);
 * 2CylinderEngine 5.814G -> 5.834G (+0.3%). */
#define GROUP_SPLITS 1
#define GROUP_SPLIT_MIN 2u

#endif /* KD_TUNE_H */
