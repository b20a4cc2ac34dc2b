# Frustum benchmark (owner: frustum): full-frame primary rays, per-ray kd vs
# bundles vs single/four-frustum traversal vs Embree rtcIntersect1/8, with a
# tile-size sweep, over the scene ladder (bench.h harness). Not a test.
add_executable(kdray_bench_frustum ${CMAKE_CURRENT_SOURCE_DIR}/bench_frustum.c)
target_link_libraries(kdray_bench_frustum PRIVATE kdray_bench_harness)
