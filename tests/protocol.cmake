# protocol/ (owner: protocol): request parsing and validation with exact
# error details, base64, float formatting and response encoding.
add_executable(test_protocol ${CMAKE_CURRENT_SOURCE_DIR}/test_protocol.c)
target_link_libraries(test_protocol PRIVATE kdray_protocol)
add_test(NAME protocol COMMAND test_protocol)

# Throughput of parsing and encoding 1M-ray bundles (not a test: run by hand,
# `test_protocol_speed [rays]`).
add_executable(test_protocol_speed ${CMAKE_CURRENT_SOURCE_DIR}/test_protocol_speed.c)
target_link_libraries(test_protocol_speed PRIVATE kdray_protocol)

# libFuzzer target for the three request parsers and the base64 decoder,
# with -DKDRAY_FUZZ=ON (the sanitizer pass of scripts/dev test). The project
# builds with gcc, so the fuzzer is compiled separately with clang
# (KDRAY_CLANG, required with KDRAY_FUZZ: tests/cmake/required_tools.cmake)
# from the protocol and core sources (the core only for
# kdr_camera_validate), linked against the system cJSON, then run for a
# bounded time on the committed seed corpus.
if(KDRAY_FUZZ)
  set(KDRAY_FUZZ_BIN ${CMAKE_CURRENT_BINARY_DIR}/fuzz_request)
  file(GLOB KDRAY_FUZZ_PROTOCOL_SOURCES ${PROJECT_SOURCE_DIR}/protocol/*.c)
  file(GLOB KDRAY_FUZZ_PROTOCOL_HEADERS ${PROJECT_SOURCE_DIR}/protocol/*.h)
  file(GLOB KDRAY_FUZZ_CORE_SOURCES ${PROJECT_SOURCE_DIR}/core/*.c)
  add_custom_command(
    OUTPUT ${KDRAY_FUZZ_BIN}
    COMMAND ${KDRAY_CLANG} -std=c11 -g -O1 -fsanitize=fuzzer,address,undefined
            -fno-sanitize-recover=all -ffp-contract=off
            -I${PROJECT_SOURCE_DIR}/protocol -I${PROJECT_SOURCE_DIR}/core
            ${CMAKE_CURRENT_SOURCE_DIR}/fuzz/fuzz_request.c
            ${KDRAY_FUZZ_PROTOCOL_SOURCES} ${KDRAY_FUZZ_CORE_SOURCES} -lcjson -lm
            -o ${KDRAY_FUZZ_BIN}
    DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/fuzz/fuzz_request.c
            ${KDRAY_FUZZ_PROTOCOL_SOURCES} ${KDRAY_FUZZ_PROTOCOL_HEADERS}
            ${KDRAY_FUZZ_CORE_SOURCES}
    COMMENT "Building the request-parser fuzzer with clang"
    VERBATIM)
  add_custom_target(fuzz_request ALL DEPENDS ${KDRAY_FUZZ_BIN})
  # Work on a copy: libFuzzer adds what it finds to the first corpus dir.
  add_test(NAME protocol_fuzz
           COMMAND ${CMAKE_COMMAND} -E env ASAN_OPTIONS=detect_leaks=1
                   sh -c "rm -rf fuzz-corpus && cp -r '${CMAKE_CURRENT_SOURCE_DIR}/fuzz/corpus' fuzz-corpus && '${KDRAY_FUZZ_BIN}' -max_total_time=20 -rss_limit_mb=2048 -max_len=4096 -timeout=10 -dict='${CMAKE_CURRENT_SOURCE_DIR}/fuzz/request.dict' fuzz-corpus"
           WORKING_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR})
endif()
