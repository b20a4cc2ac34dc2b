# Core kd-tree build and single-ray traversal (owner: core): brute force
# versus kd-tree, bit for bit, plus tree invariants and error paths.
add_executable(test_core ${CMAKE_CURRENT_SOURCE_DIR}/test_core.c)
target_link_libraries(test_core PRIVATE kdray_core)
add_test(NAME test_core COMMAND test_core)

# Real scenes against brute force (121K triangles per ray: slow under ASan).
# The model's presence is checked by tests/cmake/required_tools.cmake.
set(KDRAY_CORE_ENGINE ${KDRAY_ASSIMP_MODELS}/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb)
add_executable(test_core_scene ${CMAKE_CURRENT_SOURCE_DIR}/test_core_scene.c)
target_link_libraries(test_core_scene PRIVATE kdray_core kdray_scenes)
add_test(NAME test_core_scene
         COMMAND test_core_scene 1500 ${CMAKE_SOURCE_DIR}/scenes/default.glb
                 ${KDRAY_CORE_ENGINE})
set_tests_properties(test_core_scene PROPERTIES LABELS slow)

# test_core_perf: a measurement tool, not a test (never add_test it): kd
# build time and single-ray rays/s against Embree in the same run.
find_package(embree 3.13 QUIET)
if(TARGET kdray_scenes AND TARGET embree)
  add_executable(test_core_perf ${CMAKE_CURRENT_SOURCE_DIR}/test_core_perf.c)
  target_link_libraries(test_core_perf PRIVATE kdray_core kdray_scenes embree)
endif()

# The scene's large arrays are 2 MiB-aligned and advised for transparent
# huge pages (core/kd_mem.c); fails where THP is off (mode never).
add_executable(test_core_mem ${CMAKE_CURRENT_SOURCE_DIR}/test_core_mem.c)
target_include_directories(test_core_mem PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/support)
target_link_libraries(test_core_mem PRIVATE kdray_core)
add_test(NAME test_core_mem COMMAND test_core_mem)

# The binned and parallel build: same tree for every thread count, binned
# trees against brute force.
add_executable(test_core_build ${CMAKE_CURRENT_SOURCE_DIR}/test_core_build.c)
target_link_libraries(test_core_build PRIVATE kdray_core)
add_test(NAME test_core_build COMMAND test_core_build)

# The build's scratch memory: large arrays 2 MiB-aligned and advised for
# transparent huge pages.
# The same program with the event-list stack of kd_build_events.c made as
# small as it can be (KD_STACK_SLACK 1): below each task's first split every
# node overflows it and takes the block-of-its-own path, which must build
# the same trees (the pinned digests). Only kd_build_events.c is compiled
# differently; the linker takes it before the library's copy.
add_executable(test_core_build_stack1 ${CMAKE_CURRENT_SOURCE_DIR}/test_core_build.c
               ${CMAKE_SOURCE_DIR}/core/kd_build_events.c)
target_compile_definitions(test_core_build_stack1 PRIVATE KD_STACK_SLACK=1)
target_link_libraries(test_core_build_stack1 PRIVATE kdray_core)
add_test(NAME test_core_build_stack1 COMMAND test_core_build_stack1)
# a stack mix-up may loop rather than crash: fail it in minutes, not ctest's default
set_tests_properties(test_core_build_stack1 PROPERTIES TIMEOUT 300)

add_executable(test_core_build_mem ${CMAKE_CURRENT_SOURCE_DIR}/test_core_build_mem.c)
target_include_directories(test_core_build_mem PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/support)
target_link_libraries(test_core_build_mem PRIVATE kdray_core)
add_test(NAME test_core_build_mem COMMAND test_core_build_mem)

# The build's split-search kernels (scalar and AVX-512) against a plain sweep.
add_executable(test_core_build_simd ${CMAKE_CURRENT_SOURCE_DIR}/test_core_build_simd.c)
target_include_directories(test_core_build_simd PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/support)
target_link_libraries(test_core_build_simd PRIVATE kdray_core)
add_test(NAME test_core_build_simd COMMAND test_core_build_simd)

# The same program under ThreadSanitizer: clang compiles it with every core
# source and -fsanitize=thread (the project itself builds with gcc). Not in
# the ASan/UBSan build (one run is enough). Without clang the test fails.
find_program(KDRAY_CLANG NAMES clang clang-14)
if(NOT KDRAY_SANITIZE)
  if(KDRAY_CLANG)
    file(GLOB KDRAY_TSAN_CORE ${CMAKE_SOURCE_DIR}/core/*.c ${CMAKE_SOURCE_DIR}/core/*.h)
    list(FILTER KDRAY_TSAN_CORE INCLUDE REGEX "\\.c$")
    set(KDRAY_TSAN_BIN ${CMAKE_CURRENT_BINARY_DIR}/test_core_build_tsan)
    add_custom_command(
      OUTPUT ${KDRAY_TSAN_BIN}
      COMMAND ${KDRAY_CLANG} -std=c11 -g -O1 -fsanitize=thread -ffp-contract=off
              -fno-strict-aliasing -I${CMAKE_SOURCE_DIR}/core
              -I${CMAKE_CURRENT_SOURCE_DIR}/support
              ${CMAKE_CURRENT_SOURCE_DIR}/test_core_build.c ${KDRAY_TSAN_CORE}
              -lm -lpthread -o ${KDRAY_TSAN_BIN}
      DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/test_core_build.c
              ${CMAKE_CURRENT_SOURCE_DIR}/test_core_util.h
              ${CMAKE_CURRENT_SOURCE_DIR}/support/check.h
              ${CMAKE_CURRENT_SOURCE_DIR}/support/tree_hash.h ${KDRAY_TSAN_CORE}
      COMMENT "Building test_core_build with clang -fsanitize=thread"
      VERBATIM)
    add_custom_target(test_core_build_tsan ALL DEPENDS ${KDRAY_TSAN_BIN})
    add_test(NAME test_core_build_tsan COMMAND ${KDRAY_TSAN_BIN})
    set_tests_properties(test_core_build_tsan PROPERTIES
                         ENVIRONMENT "TSAN_OPTIONS=halt_on_error=1:exitcode=66")
  else()
    add_test(NAME test_core_build_tsan
             COMMAND sh -c "echo 'test_core_build_tsan: clang not found (install clang, see scripts/dev)' >&2; exit 1")
  endif()
endif()

# The four-triangle single-ray test against the scalar one, bit for bit.
add_executable(test_core_tri4 ${CMAKE_CURRENT_SOURCE_DIR}/test_core_tri4.c)
target_include_directories(test_core_tri4 PRIVATE ${CMAKE_SOURCE_DIR}/core)
add_test(NAME test_core_tri4 COMMAND test_core_tri4)

# kdray-tree-digest: a tool, not a test: per ladder scene the tree's
# statistics, build time and digests of its node and reference arrays (equal
# digests = byte-identical trees; used to check pure refactors of the build).
add_executable(kdray_tree_digest ${CMAKE_CURRENT_SOURCE_DIR}/tree_digest.c)
set_target_properties(kdray_tree_digest PROPERTIES OUTPUT_NAME kdray-tree-digest)
target_link_libraries(kdray_tree_digest PRIVATE kdray_testsupport)
