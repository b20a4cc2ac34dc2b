# Omni-directional ray bundles (owner: bundle): every bundle answer equals
# the single-ray answer bit for bit, 4- and 8-wide.
add_executable(test_bundle ${CMAKE_CURRENT_SOURCE_DIR}/test_bundle.c)
target_link_libraries(test_bundle PRIVATE kdray_core m)
add_test(NAME bundle COMMAND test_bundle)
