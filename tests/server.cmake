# Server integration tests (owner: server): the real kdrayd on a free
# loopback port, driven over HTTP by the Python client and by curl, answers
# compared with direct core calls (kdray-trace); plus the job pool unit test.
add_executable(test_server_pool ${CMAKE_CURRENT_SOURCE_DIR}/test_server_pool.c)
target_link_libraries(test_server_pool PRIVATE kdray_server)
add_test(NAME server_pool COMMAND test_server_pool)

find_package(Python3 COMPONENTS Interpreter)
find_program(KDRAY_CURL curl)
if(Python3_Interpreter_FOUND AND TARGET kdrayd AND TARGET kdray_trace)
  add_test(NAME server_integration
           COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/test_server.py
                   $<TARGET_FILE:kdrayd> $<TARGET_FILE:kdray_trace>
                   ${PROJECT_SOURCE_DIR}/clients)
  set_tests_properties(server_integration PROPERTIES TIMEOUT 900)
endif()
if(Python3_Interpreter_FOUND AND KDRAY_CURL AND TARGET kdrayd)
  add_test(NAME server_curl_examples
           COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/test_server_curl.sh
                   $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
  set_tests_properties(server_curl_examples PROPERTIES TIMEOUT 600)
endif()

# Binary (CBOR) bodies over HTTP. Run by Debian's own Python, for which
# python3-cbor2 is installed (scripts/dev); the test fails, never skips,
# when the module or that interpreter is missing.
find_program(KDRAY_DEBIAN_PYTHON python3 PATHS /usr/bin NO_DEFAULT_PATH)
if(TARGET kdrayd)
  if(NOT KDRAY_DEBIAN_PYTHON)
    set(KDRAY_DEBIAN_PYTHON /usr/bin/python3) # absent: the test fails loudly
  endif()
  add_test(NAME server_codecs
           COMMAND ${KDRAY_DEBIAN_PYTHON} ${CMAKE_CURRENT_SOURCE_DIR}/test_server_codecs.py
                   $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
  set_tests_properties(server_codecs PROPERTIES TIMEOUT 600)
endif()
