# Service benchmark (owner: server): kdrayd over loopback HTTP (wrk + Lua)
# against the core's in-process rate from kdray-trace in the same run, for
# 1, 1K and 64K-ray bundles in JSON and base64, plus the 1-ray round trip.
# Not a test: `cmake --build build --target bench_service` (< 1 min).
find_package(Python3 COMPONENTS Interpreter)
if(Python3_Interpreter_FOUND AND TARGET kdrayd AND TARGET kdray_trace)
  add_custom_target(bench_service
    COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/bench_service.py
            $<TARGET_FILE:kdrayd> $<TARGET_FILE:kdray_trace>
    DEPENDS kdrayd kdray_trace
    USES_TERMINAL
    COMMENT "kdrayd end-to-end throughput vs in-process core")
endif()
