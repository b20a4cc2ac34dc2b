# Frustum traversal tests (owner: frustum): every pixel of kdr_frustum_trace
# equals the single-ray answer bit for bit, on adversarial scenes and (with
# the scenes_fetch fixture) on the real-scene ladder.
add_executable(test_frustum ${CMAKE_CURRENT_SOURCE_DIR}/test_frustum.c)
target_link_libraries(test_frustum PRIVATE kdray_testsupport kdray_core m)
add_test(NAME frustum COMMAND test_frustum --caps frustum)
add_test(NAME frustum_ladder COMMAND test_frustum ${KDRAY_SCENE_DIR})
set_tests_properties(frustum_ladder PROPERTIES FIXTURES_REQUIRED scenes_fetch
                     LABELS slow)
# No skip code: a missing ladder (exit 77) after scenes_fetch is a failure.
