# Core kd-tree build and single-ray traversal (owner: core): brute force
# versus kd-tree, bit for bit, plus tree invariants and error paths.
add_executable(test_core ${CMAKE_CURRENT_SOURCE_DIR}/test_core.c)
target_link_libraries(test_core PRIVATE kdray_core)
add_test(NAME test_core COMMAND test_core)
