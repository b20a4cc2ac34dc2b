# Bundle benchmark (owner: bundle): kd single rays vs 4/8-wide bundles vs
# Embree rtcIntersect1/4/8, camera, AO and random rays. Not a test.
find_package(embree 3.13 REQUIRED)
add_executable(kdray_bench_bundle ${CMAKE_CURRENT_SOURCE_DIR}/bench_bundle.c)
target_link_libraries(kdray_bench_bundle PRIVATE kdray_core embree m)
if(TARGET kdray_scenes)
  target_link_libraries(kdray_bench_bundle PRIVATE kdray_scenes)
  target_compile_definitions(kdray_bench_bundle PRIVATE KDRAY_HAVE_GLTF=1)
endif()
