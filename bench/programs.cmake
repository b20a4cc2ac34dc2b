# The benchmark programs (not tests): one library holding the harness, the
# Embree rival and every section, and one main (bench_main.c) built four
# times with different default sections. kdray_testsupport (the ladder,
# the Embree scene builder, the RNG) is defined after bench/ and is linked
# by name. Run them all with bench/run-all; compare two commits with
# bench/compare (docs/BENCHMARKS.md).
find_package(embree 3.13 REQUIRED)
add_library(kdray_bench_lib STATIC
  ${CMAKE_CURRENT_SOURCE_DIR}/bench_harness.c
  ${CMAKE_CURRENT_SOURCE_DIR}/bench_rays.c
  ${CMAKE_CURRENT_SOURCE_DIR}/rival.c
  ${CMAKE_CURRENT_SOURCE_DIR}/rival_trace.c
  ${CMAKE_CURRENT_SOURCE_DIR}/bench_core.c
  ${CMAKE_CURRENT_SOURCE_DIR}/bench_bundle.c
  ${CMAKE_CURRENT_SOURCE_DIR}/bench_frustum.c
  ${CMAKE_CURRENT_SOURCE_DIR}/bench_cone.c
  ${CMAKE_CURRENT_SOURCE_DIR}/bench_queries.c)
target_include_directories(kdray_bench_lib PUBLIC ${CMAKE_CURRENT_SOURCE_DIR})
target_link_libraries(kdray_bench_lib PUBLIC kdray_testsupport kdray_core embree m)
target_compile_definitions(kdray_bench_lib PRIVATE
  KDRAY_CONE_PLOT="${CMAKE_CURRENT_SOURCE_DIR}/plot_cone.gp")

set(KDRAY_BENCH_PROGRAMS kdray_bench kdray_bench_bundle kdray_bench_frustum kdray_bench_cone)
set(index 0)
foreach(prog ${KDRAY_BENCH_PROGRAMS})
  add_executable(${prog} ${CMAKE_CURRENT_SOURCE_DIR}/bench_main.c)
  target_link_libraries(${prog} PRIVATE kdray_bench_lib)
  target_compile_definitions(${prog} PRIVATE BENCH_PROGRAM=${index})
  math(EXPR index "${index} + 1")
endforeach()

# Smoke test (not a measurement): every section in one quick run on the two
# smallest rungs, in the normal and the ASan/UBSan build. It fails if a
# section fails, if a rival API's answers disagree with kdray's (the ray
# conversion), or if kd_cone and kd_rays differ (cone_split: under any walk
# policy, or for any point traced alone). The ladder comes from the
# scenes_fetch fixture (tests/scenes.cmake); KDRAY_SCENE_DIR is set by
# tests/CMakeLists.txt, which is read after this file, hence the path.
add_test(NAME bench_smoke
  COMMAND kdray_bench --dir ${CMAKE_BINARY_DIR}/scene-ladder --only box --only teapots
          --section core --section bundle --section frustum --section cone --section cone_split --section queries --quick
          --rays 4096 --frame 64 --res 16 --samples 1,16 --ref-samples 64 --repeat 1)
set_tests_properties(bench_smoke PROPERTIES FIXTURES_REQUIRED scenes_fetch)

# A picture's cost by stage on one thread (render/), against one plain
# cone-shadow call over the same points; with --threads N also the picture
# on N threads as kdrayd's executor runs it (wall, summed CPU, tail). No
# Embree: nothing renders the same picture there. Prints only.
add_executable(kdray_bench_render ${CMAKE_CURRENT_SOURCE_DIR}/bench_render.c)
set_target_properties(kdray_bench_render PROPERTIES OUTPUT_NAME kdray-bench-render)
target_link_libraries(kdray_bench_render PRIVATE kdray_render kdray_scenes kdray_core
                      Threads::Threads)

# What rays that cannot hit cost in kdr_trace_batch (a generated scene, no
# Embree: nothing to compare against). Prints only; the smoke test runs it
# small and fails if a ray that cannot hit is answered with a hit.
add_executable(kdray_bench_dead ${CMAKE_CURRENT_SOURCE_DIR}/bench_dead.c)
set_target_properties(kdray_bench_dead PROPERTIES OUTPUT_NAME kdray-bench-dead)
target_link_libraries(kdray_bench_dead PRIVATE kdray_core m)
add_test(NAME bench_dead_smoke
  COMMAND kdray_bench_dead --rays 4096 --tris 2000 --repeat 1)

# The end-to-end benchmark (issue 16): kdrayd over loopback with CBOR
# against Embree with the same thread count in this process. Not a test:
# `cmake --build build --target bench_e2e` (haus and 2CylinderEngine, 1M
# rays per workload, about a minute).
if(TARGET kdrayd AND TARGET kdray_trace)
  add_executable(kdray_bench_e2e ${CMAKE_CURRENT_SOURCE_DIR}/bench_e2e.c
                 ${CMAKE_CURRENT_SOURCE_DIR}/e2e_wire.c)
  target_link_libraries(kdray_bench_e2e PRIVATE kdray_bench_lib Threads::Threads)
  add_custom_target(bench_e2e
    COMMAND kdray_bench_e2e $<TARGET_FILE:kdrayd> $<TARGET_FILE:kdray_trace>
            --dir ${CMAKE_BINARY_DIR}/scene-ladder
    DEPENDS kdray_bench_e2e kdrayd kdray_trace
    USES_TERMINAL
    COMMENT "kdrayd end to end against Embree in-process")
endif()
if(TARGET kdray_bench_e2e)
  # Smoke test (not a measurement): the end-to-end benchmark's client,
  # CBOR bodies and answer reader against a real kdrayd on the two smallest
  # rungs; fails if a request fails or kdrayd's and Embree's hit counts
  # differ by more than 0.1%.
  add_test(NAME bench_e2e_smoke
    COMMAND kdray_bench_e2e $<TARGET_FILE:kdrayd> $<TARGET_FILE:kdray_trace>
            --dir ${CMAKE_BINARY_DIR}/scene-ladder --only box --only teapots
            --rays 8192 --repeat 1)
  set_tests_properties(bench_e2e_smoke PROPERTIES FIXTURES_REQUIRED scenes_fetch)
endif()
