# Cone-shadow queries (owner: cone), three programs sharing
# test_cone_util.h; in each, KDR_SHADOW_CONE == KDR_SHADOW_RAYS == brute
# force sample by sample.
# cone: bad queries, the sample rays' definition, analytic visibilities,
# normals, offsets and point ranges.
add_executable(test_cone ${CMAKE_CURRENT_SOURCE_DIR}/test_cone.c)
target_link_libraries(test_cone PRIVATE kdray_testsupport kdray_core m)
add_test(NAME cone COMMAND test_cone)
# cone_trees: a random soup (and Embree on the same sample rays), cones on
# the tree's own split planes, the SIMD packet tests.
add_executable(test_cone_trees ${CMAKE_CURRENT_SOURCE_DIR}/test_cone_trees.c)
target_link_libraries(test_cone_trees PRIVATE kdray_testsupport kdray_core m)
add_test(NAME cone_trees COMMAND test_cone_trees --caps cone)
# cone_proofs: the one-triangle proofs (kd_cone_proof.c) against float rays.
add_executable(test_cone_proofs ${CMAKE_CURRENT_SOURCE_DIR}/test_cone_proofs.c)
target_link_libraries(test_cone_proofs PRIVATE kdray_testsupport kdray_core m)
add_test(NAME cone_proofs COMMAND test_cone_proofs)

# Cone-shadow visibility on a scene with parts 1e5 away, against robust
# Embree at 4096 samples from starts just off the surfaces (API v1.1:
# "auto" offsets, normals as given); also checks that v1's starts fail.
# Shares test_cone_util.h (triangle buffer, generator, basis) with test_cone*.
add_executable(test_cone_accuracy ${CMAKE_CURRENT_SOURCE_DIR}/test_cone_accuracy.c)
target_link_libraries(test_cone_accuracy PRIVATE kdray_testsupport kdray_core m)
add_test(NAME cone_accuracy COMMAND test_cone_accuracy)

# Shared walks: a group's cone holds every segment of its points, and every
# walk policy (groups automatic and forced, walks on and off) equals the
# reference mode and brute force on coherent runs of points.
add_executable(test_cone_group ${CMAKE_CURRENT_SOURCE_DIR}/test_cone_group.c)
target_link_libraries(test_cone_group PRIVATE kdray_testsupport kdray_core m)
add_test(NAME cone_group COMMAND test_cone_group)

# The group list's four-wide cull (kd_cone_cull4.c) answers every triangle
# as the scalar kd_cone_pre_may_block does.
add_executable(test_cone_cull4 ${CMAKE_CURRENT_SOURCE_DIR}/test_cone_cull4.c)
target_link_libraries(test_cone_cull4 PRIVATE kdray_testsupport kdray_core m)
add_test(NAME cone_cull4 COMMAND test_cone_cull4)
