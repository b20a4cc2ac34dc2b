# Server integration tests (owner: server): the real kdrayd on a free
# loopback port, driven over HTTP by the Python client and by curl, answers
# compared with direct core calls (kdray-trace); operation (admission,
# deadlines, hang-ups, reload, logs), memory, health latency, install.
# Python 3 and curl are required: a missing tool fails the configure step
# rather than silently dropping these tests.
find_package(Python3 REQUIRED COMPONENTS Interpreter)
find_program(KDRAY_CURL curl REQUIRED)
# systemd-analyze (Debian package systemd) checks the installed unit; the
# install test fails, naming it, when it is missing.
find_program(KDRAY_SYSTEMD_ANALYZE systemd-analyze)

add_test(NAME server_integration
         COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/test_server.py
                 $<TARGET_FILE:kdrayd> $<TARGET_FILE:kdray_trace>
                 ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_integration PROPERTIES TIMEOUT 900)

add_test(NAME server_curl_examples
         COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/test_server_curl.sh
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_curl_examples PROPERTIES TIMEOUT 600)

add_test(NAME server_ops
         COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/test_server_ops.py
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_ops PROPERTIES TIMEOUT 600)

# Two tests belong to the normal build's run only. Latency: the sanitizers
# make every request cost two to three times the CPU, so a millisecond
# target says nothing there; it also runs alone, so that no other test's
# CPU use is measured. Memory: RSS and address-space limits mean nothing
# under AddressSanitizer (shadow memory, quarantine).
if(NOT KDRAY_SANITIZE)
  add_test(NAME server_health_latency
           COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/test_server_ops.py
                   $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients health_latency)
  set_tests_properties(server_health_latency PROPERTIES TIMEOUT 300 RUN_SERIAL TRUE)

  add_test(NAME server_memory
           COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/test_server_memory.py
                   $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
  set_tests_properties(server_memory PROPERTIES TIMEOUT 300)
endif()

add_test(NAME server_install
         COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/test_install.py
                 ${CMAKE_BINARY_DIR} "${KDRAY_SYSTEMD_ANALYZE}" ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_install PROPERTIES TIMEOUT 300)
