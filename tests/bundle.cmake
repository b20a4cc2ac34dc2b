# Omni-directional ray bundles (owner: bundle): every bundle answer equals
# the single-ray answer bit for bit, 4- and 8-wide, on generated scenes and
# (with the scenes_fetch fixture) on the real-scene ladder.
add_executable(test_bundle ${CMAKE_CURRENT_SOURCE_DIR}/test_bundle.c
                           ${CMAKE_CURRENT_SOURCE_DIR}/test_bundle_sets.c)
target_link_libraries(test_bundle PRIVATE kdray_testsupport kdray_core m)
add_test(NAME bundle COMMAND test_bundle)
add_test(NAME bundle_ladder COMMAND test_bundle ${KDRAY_SCENE_DIR})
# No skip code: the scenes_fetch fixture fills the ladder first, so a
# missing ladder (exit 77) is a failure.
set_tests_properties(bundle_ladder PROPERTIES FIXTURES_REQUIRED scenes_fetch
                     LABELS slow)
# Where kdr_trace_batch routes a chunk (bundles or the interleaved walk):
# one origin, runs of origins and scattered origins on scenes below and
# above KD_STREAM_RUNS_MIN_BYTES.
add_executable(test_batch_route ${CMAKE_CURRENT_SOURCE_DIR}/test_batch_route.c)
target_link_libraries(test_batch_route PRIVATE kdray_core m)
add_test(NAME bundle_route COMMAND test_batch_route)
# Entry points of rays that share an origin (core/kd_entry.h): every ray's
# answer and work equal the single walk's, scalar and AVX-512 replays agree.
add_executable(test_entry ${CMAKE_CURRENT_SOURCE_DIR}/test_entry.c
                          ${CMAKE_CURRENT_SOURCE_DIR}/test_bundle_sets.c)
target_link_libraries(test_entry PRIVATE kdray_core m)
add_test(NAME entry COMMAND test_entry)
