# Tree images (owner: deploy): core/kd_image.c round trips bit for bit
# through every traversal kind, and truncated, corrupt, forged, other-version
# and other-option images are refused (run under ASan/UBSan in the suite).
add_executable(test_image ${CMAKE_CURRENT_SOURCE_DIR}/test_image.c)
target_include_directories(test_image PRIVATE ${CMAKE_SOURCE_DIR}/core)
target_link_libraries(test_image PRIVATE kdray_core m)
add_test(NAME test_image COMMAND test_image)
