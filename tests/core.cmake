# Core kd-tree build and single-ray traversal (owner: core): brute force
# versus kd-tree, bit for bit, plus tree invariants and error paths.
add_executable(test_core ${CMAKE_CURRENT_SOURCE_DIR}/test_core.c)
target_link_libraries(test_core PRIVATE kdray_core)
add_test(NAME test_core COMMAND test_core)

# Real scenes against brute force (121K triangles per ray: slow under ASan).
set(KDRAY_CORE_ENGINE /usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb)
if(TARGET kdray_scenes AND EXISTS ${KDRAY_CORE_ENGINE})
  add_executable(test_core_scene ${CMAKE_CURRENT_SOURCE_DIR}/test_core_scene.c)
  target_link_libraries(test_core_scene PRIVATE kdray_core kdray_scenes)
  add_test(NAME test_core_scene
           COMMAND test_core_scene 1500 ${CMAKE_SOURCE_DIR}/scenes/default.glb
                   ${KDRAY_CORE_ENGINE})
  set_tests_properties(test_core_scene PROPERTIES LABELS slow)
endif()

# test_core_perf: a measurement tool, not a test (never add_test it): kd
# build time and single-ray rays/s against Embree in the same run.
find_package(embree 3.13 QUIET)
if(TARGET kdray_scenes AND TARGET embree)
  add_executable(test_core_perf ${CMAKE_CURRENT_SOURCE_DIR}/test_core_perf.c)
  target_link_libraries(test_core_perf PRIVATE kdray_core kdray_scenes embree)
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
