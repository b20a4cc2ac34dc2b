# Service benchmark (owner: soak): kdrayd over loopback HTTP (wrk + Lua)
# against the core's in-process rate from kdray-trace in the same run, for
# 1, 1K and 64K-ray bundles in JSON, base64 and CBOR, the 1-ray round trip,
# and 1M-ray requests of every kind and encoding with kdrayd's Server-Timing
# split. Not a test: `cmake --build build --target bench_service` (~2 min);
# `--target bench_service_soak` runs only the 60 s mixed-query soak (errors,
# RSS growth, /metrics agreement).
find_package(Python3 COMPONENTS Interpreter)
if(NOT Python3_Interpreter_FOUND)
  message(FATAL_ERROR "bench/service.cmake: python3 is missing; bench_service and "
    "bench_service_soak need it (Debian package python3; ./scripts/dev deps), or "
    "configure with -DBUILD_TESTING=OFF to build without tests and benchmarks.")
endif()
if(TARGET kdrayd AND TARGET kdray_trace)
  add_custom_target(bench_service
    COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/bench_service.py
            $<TARGET_FILE:kdrayd> $<TARGET_FILE:kdray_trace>
    DEPENDS kdrayd kdray_trace
    USES_TERMINAL
    COMMENT "kdrayd end-to-end throughput vs in-process core")
  add_custom_target(bench_service_soak
    COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/bench_service.py
            $<TARGET_FILE:kdrayd> $<TARGET_FILE:kdray_trace> --soak 60 --soak-only
    DEPENDS kdrayd kdray_trace
    USES_TERMINAL
    COMMENT "kdrayd 60 s soak: errors, memory, metrics")
endif()

# The loopback floor under the service's transport (bench/loopback_floor.c):
# N bytes between two threads over TCP loopback, read the way
# libmicrohttpd reads a body in kdrayd and in larger pieces. Prints only.
add_executable(kdray_loopback_floor ${CMAKE_CURRENT_SOURCE_DIR}/loopback_floor.c)
set_target_properties(kdray_loopback_floor PROPERTIES OUTPUT_NAME kdray-loopback-floor)
target_link_libraries(kdray_loopback_floor PRIVATE Threads::Threads)
