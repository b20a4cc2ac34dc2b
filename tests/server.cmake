# Server integration tests (owner: server): the real kdrayd on a free
# loopback port, driven over HTTP by the Python client and by curl, answers
# compared with direct core calls (kdray-trace); operation (admission,
# deadlines, hang-ups, reload, logs), memory, health latency, install.
# Python 3 and curl are required (tests/cmake/required_tools.cmake): a
# missing tool fails the configure step rather than silently dropping these
# tests.
# systemd-analyze (Debian package systemd) checks the installed unit; the
# install test fails, naming it, when it is missing.
find_program(KDRAY_SYSTEMD_ANALYZE systemd-analyze)

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

# Streamed answers (application/cbor-seq): equal to one-shot answers, errors
# before and after streaming began, hang-ups. Debian's Python (cbor2).
add_test(NAME server_stream
         COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test_server_stream.py
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_stream PROPERTIES TIMEOUT 600)

# How a large body arrives: odd-sized paced pieces (announced and chunked)
# answer byte for byte as one send; bodies cut short, Content-Length lies
# and bodies over --max-body-mb never give a 200 and release their
# admission. Debian's Python (cbor2).
add_test(NAME server_arrival
         COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test_server_arrival.py
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_arrival PROPERTIES TIMEOUT 600)

add_test(NAME server_ops
         COMMAND ${KDRAY_PYTHON3} ${CMAKE_CURRENT_SOURCE_DIR}/test_server_ops.py
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_ops PROPERTIES TIMEOUT 600)

# Two tests belong to the normal build's run only. Latency: the sanitizers
# make every request cost two to three times the CPU, so a millisecond
# target says nothing there; it also runs alone, so that no other test's
# CPU use is measured. Memory: RSS and address-space limits mean nothing
# under AddressSanitizer (shadow memory, quarantine).
if(NOT KDRAY_SANITIZE)
  add_test(NAME server_health_latency
           COMMAND ${KDRAY_PYTHON3} ${CMAKE_CURRENT_SOURCE_DIR}/test_server_ops.py
                   $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients health_latency)
  set_tests_properties(server_health_latency PROPERTIES TIMEOUT 300 RUN_SERIAL TRUE)

  add_test(NAME server_memory
           COMMAND ${KDRAY_PYTHON3} ${CMAKE_CURRENT_SOURCE_DIR}/test_server_memory.py
                   $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
  set_tests_properties(server_memory PROPERTIES TIMEOUT 300)

  add_test(NAME server_stream_memory
           COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test_server_stream.py
                   $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients memory)
  set_tests_properties(server_stream_memory PROPERTIES TIMEOUT 300)
endif()

add_test(NAME server_install
         COMMAND ${KDRAY_PYTHON3} ${CMAKE_CURRENT_SOURCE_DIR}/test_install.py
                 ${CMAKE_BINARY_DIR} "${KDRAY_SYSTEMD_ANALYZE}" ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_install PROPERTIES TIMEOUT 300)

# --cache-dir: store, map, damaged files rebuilt, concurrent writers.
add_test(NAME server_cache
         COMMAND ${KDRAY_PYTHON3} ${CMAKE_CURRENT_SOURCE_DIR}/test_server_cache.py
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients
                 ${PROJECT_SOURCE_DIR}/scenes/default.glb)
set_tests_properties(server_cache PROPERTIES TIMEOUT 600)

# A tree loaded from the cache is read into 2 MiB-aligned memory advised
# for transparent huge pages (fails where THP is off).
add_executable(test_tree_cache_mem ${CMAKE_CURRENT_SOURCE_DIR}/test_tree_cache_mem.c)
target_include_directories(test_tree_cache_mem PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/support)
target_link_libraries(test_tree_cache_mem PRIVATE kdray_server)
add_test(NAME test_tree_cache_mem COMMAND test_tree_cache_mem)

# render.png against the daemon's own frustum and cone-shadow answers,
# decoded by Pillow. Debian's python3 (python3-pil, scripts/dev): the test
# fails, never skips, when Pillow is missing.
add_test(NAME render_png
         COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test_render.py
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(render_png PROPERTIES TIMEOUT 600)

# The page at / in headless Debian Chromium driven by Debian's chromedriver
# (scripts/dev installs both; the test fails, never skips, without them).
# Screenshots: build/tests/page-screenshots/.
add_test(NAME page
         COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test_page.py
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients
                 ${CMAKE_CURRENT_BINARY_DIR}/page-screenshots)
set_tests_properties(page PROPERTIES TIMEOUT 600)

# Bundle "query": "all" / "count" (issue 15) over HTTP, JSON, base64 and
# CBOR (Debian's python3 for python3-cbor2, as server_codecs).
add_test(NAME server_queries
         COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test_server_queries.py
                 $<TARGET_FILE:kdrayd> $<TARGET_FILE:kdray_trace>
                 ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(server_queries PROPERTIES TIMEOUT 600)

# clients/kdray_client.py keeps one connection per Client (and thread),
# reconnects once when a kept one was closed, closes a half-read stream's
# (issue 16): counted through a relay. Debian's python3 (python3-cbor2).
add_test(NAME client_keepalive
         COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test_client_keepalive.py
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(client_keepalive PROPERTIES TIMEOUT 300)

# clients/kdray_raycast.py (issue 15): installed offline the documented way
# into a throwaway venv, then every Open3D-named method against kdrayd.
add_test(NAME client_raycast
         COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test_client_raycast.py
                 $<TARGET_FILE:kdrayd> ${PROJECT_SOURCE_DIR}/clients)
set_tests_properties(client_raycast PROPERTIES TIMEOUT 600)
