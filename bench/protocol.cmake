# Protocol codecs (owner: codecs): parse and encode 1M-ray bodies in every
# form (JSON numbers, base64, CBOR typed arrays in place and copied), base64
# and float printing, each against memcpy of the same bytes in the same run;
# prints the targets and whether each is met (exit 1 if one is not).
# Not a test: `cmake --build build --target bench_protocol` (a few seconds).
# (test_protocol_speed is defined in tests/, configured after bench/: the
# generator expression and the dependency resolve at generate time.)
add_custom_target(bench_protocol
  COMMAND $<TARGET_FILE:test_protocol_speed> 1000000 --targets
  DEPENDS test_protocol_speed
  USES_TERMINAL
  COMMENT "protocol codecs: 1M-ray bodies against memcpy, same run")
