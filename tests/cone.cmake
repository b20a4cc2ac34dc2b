# Cone-shadow queries (owner: cone): sample rays, analytic visibilities,
# KDR_SHADOW_CONE == KDR_SHADOW_RAYS == brute force sample by sample, Embree
# on the same rays, and cones placed on the tree's own split planes.
add_executable(test_cone ${CMAKE_CURRENT_SOURCE_DIR}/test_cone.c)
target_link_libraries(test_cone PRIVATE kdray_testsupport kdray_core m)
add_test(NAME cone COMMAND test_cone --caps cone)

# Cone-shadow visibility on a scene with parts 1e5 away, against robust
# Embree at 4096 samples from starts just off the surfaces (API v1.1:
# "auto" offsets, normals as given); also checks that v1's starts fail.
add_executable(test_cone_accuracy ${CMAKE_CURRENT_SOURCE_DIR}/test_cone_accuracy.c)
target_link_libraries(test_cone_accuracy PRIVATE kdray_testsupport kdray_core m)
add_test(NAME cone_accuracy COMMAND test_cone_accuracy)

# Shared walks: a group's cone holds every segment of its points, and every
# walk policy (groups automatic and forced, walks on and off) equals the
# reference mode and brute force on coherent runs of points.
add_executable(test_cone_group ${CMAKE_CURRENT_SOURCE_DIR}/test_cone_group.c)
target_link_libraries(test_cone_group PRIVATE kdray_testsupport kdray_core m)
add_test(NAME cone_group COMMAND test_cone_group)
