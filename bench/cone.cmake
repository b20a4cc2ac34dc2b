# Cone-shadow benchmark (owner: cone): run time against RMSE for Embree
# per-ray sampling, kd single rays and cone traversal. Not a test.
find_package(embree 3.13 REQUIRED)
# kdray_testsupport (tests/oracle.cmake) is defined after bench/, so it is
# linked by name and resolved at generate time.
if(TARGET kdray_scenes)
  add_executable(kdray_bench_cone ${CMAKE_CURRENT_SOURCE_DIR}/bench_cone.c)
  target_link_libraries(kdray_bench_cone PRIVATE kdray_testsupport kdray_scenes
                        kdray_core embree m)
  target_compile_definitions(kdray_bench_cone PRIVATE
    KDRAY_CONE_PLOT="${CMAKE_CURRENT_SOURCE_DIR}/plot_cone.gp")
endif()
