# Query executor (owner: exec): answers equal single-threaded core calls
# byte for byte, admission books, deadlines, cancellation, shutdown.
add_executable(test_exec ${CMAKE_CURRENT_SOURCE_DIR}/test_exec.c)
target_link_libraries(test_exec PRIVATE kdray_exec)
add_test(NAME exec COMMAND test_exec)
set_tests_properties(exec PROPERTIES TIMEOUT 300)
