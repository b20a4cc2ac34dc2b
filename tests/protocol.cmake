# protocol/ (owner: protocol): request parsing and validation with exact
# error details (protocol); base64, float formatting and response encoding
# (protocol_encode).
add_executable(test_protocol ${CMAKE_CURRENT_SOURCE_DIR}/test_protocol.c)
target_link_libraries(test_protocol PRIVATE kdray_protocol)
add_test(NAME protocol COMMAND test_protocol)
add_executable(test_protocol_encode ${CMAKE_CURRENT_SOURCE_DIR}/test_protocol_encode.c)
target_link_libraries(test_protocol_encode PRIVATE kdray_protocol)
add_test(NAME protocol_encode COMMAND test_protocol_encode)

# Throughput of parsing and encoding 1M-ray bundles (not a test: run by hand,
# `test_protocol_speed [rays]`).
add_executable(test_protocol_speed ${CMAKE_CURRENT_SOURCE_DIR}/test_protocol_speed.c)
target_link_libraries(test_protocol_speed PRIVATE kdray_protocol)

# libFuzzer target for the request parsers (JSON and CBOR) and the base64
# decoder, with -DKDRAY_FUZZ=ON (the sanitizer pass of scripts/dev test).
# The project builds with gcc, so the fuzzer is compiled separately with
# clang and clang++ (KDRAY_CLANG, KDRAY_CLANGXX, required with KDRAY_FUZZ:
# tests/cmake/required_tools.cmake) from the protocol and core sources (the
# core only for kdr_camera_validate) and the Dragonbox shim, linked against
# the system cJSON and libcbor, then run for a bounded time on the committed
# seed corpus.
if(KDRAY_FUZZ)
  set(KDRAY_FUZZ_BIN ${CMAKE_CURRENT_BINARY_DIR}/fuzz_request)
  set(KDRAY_FUZZ_SHIM ${CMAKE_CURRENT_BINARY_DIR}/fuzz_float_shortest.o)
  file(GLOB KDRAY_FUZZ_PROTOCOL_SOURCES ${PROJECT_SOURCE_DIR}/protocol/*.c)
  file(GLOB KDRAY_FUZZ_PROTOCOL_HEADERS ${PROJECT_SOURCE_DIR}/protocol/*.h)
  file(GLOB KDRAY_FUZZ_CORE_SOURCES ${PROJECT_SOURCE_DIR}/core/*.c)
  find_package(dragonbox 1.1 REQUIRED) # imported targets are per directory
  get_target_property(KDRAY_DRAGONBOX_INC dragonbox::dragonbox INTERFACE_INCLUDE_DIRECTORIES)
  set(KDRAY_FUZZ_FLAGS -g -O1 -fsanitize=fuzzer-no-link,address,undefined
      -fno-sanitize-recover=all -ffp-contract=off)
  add_custom_command(
    OUTPUT ${KDRAY_FUZZ_SHIM}
    COMMAND ${KDRAY_CLANGXX} -std=c++17 ${KDRAY_FUZZ_FLAGS} -I${KDRAY_DRAGONBOX_INC}
            -c ${PROJECT_SOURCE_DIR}/protocol/kdr_float_shortest.cpp -o ${KDRAY_FUZZ_SHIM}
    DEPENDS ${PROJECT_SOURCE_DIR}/protocol/kdr_float_shortest.cpp
    COMMENT "Building the Dragonbox shim for the fuzzer with clang++"
    VERBATIM)
  add_custom_command(
    OUTPUT ${KDRAY_FUZZ_BIN}
    COMMAND ${KDRAY_CLANGXX} -x c -std=c11 ${KDRAY_FUZZ_FLAGS}
            -I${PROJECT_SOURCE_DIR}/protocol -I${PROJECT_SOURCE_DIR}/core
            ${CMAKE_CURRENT_SOURCE_DIR}/fuzz/fuzz_request.c
            ${KDRAY_FUZZ_PROTOCOL_SOURCES} ${KDRAY_FUZZ_CORE_SOURCES}
            -x none ${KDRAY_FUZZ_SHIM} -fsanitize=fuzzer,address,undefined
            -lcjson -lcbor -lm -o ${KDRAY_FUZZ_BIN}
    DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/fuzz/fuzz_request.c ${KDRAY_FUZZ_SHIM}
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

# The SIMD base64 and the Dragonbox float printer against the scalar code
# they replaced (tests/support/old_codecs.c) and strtof.
add_executable(test_codecs ${CMAKE_CURRENT_SOURCE_DIR}/test_codecs.c
               ${CMAKE_CURRENT_SOURCE_DIR}/support/old_codecs.c)
target_include_directories(test_codecs PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/support)
target_link_libraries(test_codecs PRIVATE kdray_protocol)
add_test(NAME protocol_codecs COMMAND test_codecs)

# Not a test (minutes): all 2^32 floats through the printer, by hand.
add_executable(float_exhaustive ${CMAKE_CURRENT_SOURCE_DIR}/float_exhaustive.c
               ${CMAKE_CURRENT_SOURCE_DIR}/support/old_codecs.c)
target_include_directories(float_exhaustive PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/support)
target_link_libraries(float_exhaustive PRIVATE kdray_protocol Threads::Threads)

# CBOR bodies and answers (JSON twins, in place, answers read back), CBOR
# errors, answer fields and media negotiation, the parse meter.
foreach(t cbor cbor_errors fields meter)
  add_executable(test_protocol_${t} ${CMAKE_CURRENT_SOURCE_DIR}/test_protocol_${t}.c)
  target_include_directories(test_protocol_${t} PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/support)
  target_link_libraries(test_protocol_${t} PRIVATE kdray_protocol)
  add_test(NAME protocol_${t} COMMAND test_protocol_${t})
endforeach()

# Large bodies and answers in 2 MiB-aligned, huge-page-advised blocks
# (kdr_block_alloc; issue 16, svc8 round). Needs THP (fails without it).
add_executable(test_protocol_block ${CMAKE_CURRENT_SOURCE_DIR}/test_protocol_block.c)
target_include_directories(test_protocol_block PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/support)
target_link_libraries(test_protocol_block PRIVATE kdray_protocol)
add_test(NAME protocol_block COMMAND test_protocol_block)
