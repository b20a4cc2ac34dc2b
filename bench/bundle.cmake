# Bundle benchmark (owner: bundle): kd single rays vs 4/8-wide bundles vs
# Embree rtcIntersect1/4/8 on camera, AO and random rays, for every ladder
# scene, built on the oracle's harness (bench.h). Not a test.
add_executable(kdray_bench_bundle ${CMAKE_CURRENT_SOURCE_DIR}/bench_bundle.c)
target_link_libraries(kdray_bench_bundle PRIVATE kdray_bench_harness)
