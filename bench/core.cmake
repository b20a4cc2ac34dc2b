# Core benchmark (owner: oracle): kd build and single rays vs Embree on the
# scene ladder, plus the reusable harness (bench.h) other benchmarks may use.
# kdray_testsupport (tests/oracle.cmake) is defined after bench/, so it is
# linked by name and resolved at generate time. Not a test.
find_package(embree 3.13 REQUIRED)
add_library(kdray_bench_harness STATIC ${CMAKE_CURRENT_SOURCE_DIR}/bench_harness.c)
target_include_directories(kdray_bench_harness PUBLIC ${CMAKE_CURRENT_SOURCE_DIR})
target_link_libraries(kdray_bench_harness PUBLIC kdray_testsupport kdray_core embree m)

add_executable(kdray_bench ${CMAKE_CURRENT_SOURCE_DIR}/bench_core.c)
target_link_libraries(kdray_bench PRIVATE kdray_bench_harness)
