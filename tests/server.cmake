# Server integration tests (owner: server): the real kdrayd on a free
# loopback port, driven over HTTP by the Python client and by curl, answers
# compared with direct core calls (kdray-trace); plus the job pool unit test.
add_executable(test_server_pool ${CMAKE_CURRENT_SOURCE_DIR}/test_server_pool.c)
target_link_libraries(test_server_pool PRIVATE kdray_server)
add_test(NAME server_pool COMMAND test_server_pool)

# python3 and curl: tests/cmake/required_tools.cmake (configure fails
# without them).
add_test(NAME server_integration
         COMMAND ${KDRAY_PYTHON3} ${CMAKE_CURRENT_SOURCE_DIR}/test_server.py
                 $<TARGET_FILE:kdrayd> $<TARGET_FILE:kdray_trace>
                 ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_integration PROPERTIES TIMEOUT 900)
add_test(NAME server_curl_examples
         COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/test_server_curl.sh
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_curl_examples PROPERTIES TIMEOUT 600)

# Binary (CBOR) bodies over HTTP. Run by Debian's own Python, for which
# python3-cbor2 is installed (scripts/dev): the python3 on PATH may be
# another interpreter without Debian's modules. The test fails, never
# skips, when that interpreter or the module is missing.
add_test(NAME server_codecs
         COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test_server_codecs.py
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_codecs PROPERTIES TIMEOUT 600)
