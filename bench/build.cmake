# Build benchmark (owner: core build): kd build on one and on all threads
# against Embree's HIGH and MEDIUM builds with the same threads, and the
# exact tree against the binned one on single rays, bundles and frusta, over
# the scene ladder. Its own main (it times builds, which bench_main does
# once per scene); ray workloads from kdray_bench_lib (bench.h), defined in
# programs.cmake and linked by name. Not a test.
add_executable(kdray_bench_build ${CMAKE_CURRENT_SOURCE_DIR}/bench_build.c)
target_link_libraries(kdray_bench_build PRIVATE kdray_bench_lib)

# A cached tree read into huge-page memory (kdrayd's load, server/
# tree_cache.c) against the same file mapped shared: load time, huge pages
# and single-ray speed in one process (issue 11). Prints only.
if(TARGET kdray_server)
  add_executable(kdray_bench_cache_mem ${CMAKE_CURRENT_SOURCE_DIR}/bench_cache_mem.c)
  set_target_properties(kdray_bench_cache_mem PROPERTIES OUTPUT_NAME kdray-bench-cache-mem)
  target_link_libraries(kdray_bench_cache_mem PRIVATE kdray_server)
  target_include_directories(kdray_bench_cache_mem PRIVATE ${CMAKE_SOURCE_DIR}/tests/support)
endif()

# The rival's memory: which of Embree's allocations are in huge pages and
# whether its traversal reads the vertex and index buffers (issue 11's
# fairness check). Prints only.
add_executable(kdray_bench_rival_mem ${CMAKE_CURRENT_SOURCE_DIR}/bench_rival_mem.c)
set_target_properties(kdray_bench_rival_mem PROPERTIES OUTPUT_NAME kdray-bench-rival-mem)
target_link_libraries(kdray_bench_rival_mem PRIVATE kdray_bench_lib kdray_scenes)
