# Server integration tests (owner: server): the real kdrayd on a free
# loopback port, driven over HTTP by the Python client and by curl, answers
# compared with direct core calls (kdray-trace).

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
