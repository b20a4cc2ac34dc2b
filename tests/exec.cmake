# Query executor (owner: exec): answers equal single-threaded core calls
# byte for byte, admission books, deadlines, cancellation, shutdown.
# JSON and CBOR bodies, JSON, base64 and CBOR answers, fields; the parse
# and answer charges. Bodies: support/exec_bodies.h.
add_executable(test_exec ${CMAKE_CURRENT_SOURCE_DIR}/test_exec.c)
target_include_directories(test_exec PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/support)
target_link_libraries(test_exec PRIVATE kdray_exec)
add_test(NAME exec COMMAND test_exec)
set_tests_properties(exec PROPERTIES TIMEOUT 300)
