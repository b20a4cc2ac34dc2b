# Query executor (owner: exec): answers equal single-threaded core calls
# byte for byte, admission books, deadlines, cancellation, shutdown.
# JSON and CBOR bodies, JSON, base64 and CBOR answers, fields; the parse
# and answer charges. Bodies: support/exec_bodies.h.
add_executable(test_exec ${CMAKE_CURRENT_SOURCE_DIR}/test_exec.c)
target_include_directories(test_exec PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/support)
target_link_libraries(test_exec PRIVATE kdray_exec)
add_test(NAME exec COMMAND test_exec)
set_tests_properties(exec PROPERTIES TIMEOUT 300)

# Streamed answers (exec/kdr_exec_stream.c) without HTTP: items equal the
# one-shot answer, the bundle window (wrap, stall, deadline, cancel), 406.
add_executable(test_exec_stream ${CMAKE_CURRENT_SOURCE_DIR}/test_exec_stream.c)
target_include_directories(test_exec_stream PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/support)
target_link_libraries(test_exec_stream PRIVATE kdray_exec)
add_test(NAME exec_stream COMMAND test_exec_stream)
set_tests_properties(exec_stream PROPERTIES TIMEOUT 300)

# render/ and the executor's render kind: parameters, framing, bands in any
# order, the shadow index contract, PNG decoded by libpng equal to the image.
find_package(PNG REQUIRED)
add_executable(test_render_module ${CMAKE_CURRENT_SOURCE_DIR}/test_render_module.c)
target_link_libraries(test_render_module PRIVATE kdray_exec kdray_render PNG::PNG)
add_test(NAME render_module COMMAND test_render_module)
set_tests_properties(render_module PROPERTIES TIMEOUT 300)
