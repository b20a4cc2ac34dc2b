# Frustum benchmark (owner: frustum): full-frame primary rays, per-ray kd vs
# bundles vs single/four-frustum traversal vs Embree rtcIntersect1/8, with a
# tile-size sweep. Not a test.
if(TARGET kdray_scenes)
  add_executable(kdray_bench_frustum ${CMAKE_CURRENT_SOURCE_DIR}/bench_frustum.c)
  target_link_libraries(kdray_bench_frustum PRIVATE kdray_core kdray_testsupport
                        kdray_scenes m)
endif()
