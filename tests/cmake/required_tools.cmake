# required_tools.cmake — the programs and files the test suite runs, checked
# when the tests are configured (tests/CMakeLists.txt includes this before
# any fragment; the tools_required test also runs it alone with `cmake -P`).
#
# A missing one stops the configure step with its name, the Debian package
# that provides it and the tests that need it. Leaving those tests out
# instead would give a green suite that tested less. `./scripts/dev deps`
# installs every package; -DBUILD_TESTING=OFF builds kdrayd and the tools
# without tests and without any of these.
#
# Sets: KDRAY_PYTHON3, KDRAY_CURL, KDRAY_ASSIMP, KDRAY_ASSIMP_MODELS, and
# with KDRAY_FUZZ also KDRAY_CLANG and KDRAY_CLANGXX.

set(KDRAY_ASSIMP_MODELS /usr/share/assimp/models CACHE PATH
    "assimp-testmodels' model tree (real scenes and broken files for the tests)")

function(kdray_tool_missing what package users)
  message(FATAL_ERROR
    "kdray tests: ${what} is missing; ${users} need it. Install the Debian "
    "package ${package} (./scripts/dev deps installs every test tool), or "
    "configure with -DBUILD_TESTING=OFF to build kdrayd and the tools without "
    "tests.")
endfunction()

# kdray_require_program(VAR PACKAGE USERS NAME...): VAR = the first NAME on
# the search path. A VAR given on the command line is kept as it is, and
# must then exist.
function(kdray_require_program var package users)
  find_program(${var} NAMES ${ARGN})
  if(NOT ${var} OR NOT EXISTS "${${var}}")
    kdray_tool_missing("the program ${ARGV3}" ${package} "${users}")
  endif()
endfunction()

kdray_require_program(KDRAY_PYTHON3 python3
  "server_integration, scenes_fetch (scenes/fetch) and every ladder test" python3)
kdray_require_program(KDRAY_CURL curl "server_curl_examples" curl)
kdray_require_program(KDRAY_ASSIMP assimp-utils
  "the scenes_vs_assimp_* tests and scenes_fetch (format conversions)" assimp)

# The one model every user of the tree reads (the ladder's key rung).
if(NOT EXISTS ${KDRAY_ASSIMP_MODELS}/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb)
  kdray_tool_missing("the model tree ${KDRAY_ASSIMP_MODELS} (2CylinderEngine.glb)"
    assimp-testmodels
    "test_core_scene, scenes_models, scenes_fuzz and scenes_fetch")
endif()

if(KDRAY_FUZZ)
  kdray_require_program(KDRAY_CLANG clang "protocol_fuzz (-DKDRAY_FUZZ=ON)"
    clang clang-14)
  kdray_require_program(KDRAY_CLANGXX clang "scenes_fuzz (-DKDRAY_FUZZ=ON)"
    clang++ clang++-14)
  # clang links -fsanitize=fuzzer only with its libFuzzer runtime, a package
  # of its own: link an empty target once, here, rather than at build time.
  set(probe_dir ${CMAKE_CURRENT_BINARY_DIR}/fuzz-runtime-probe)
  file(MAKE_DIRECTORY ${probe_dir})
  file(WRITE ${probe_dir}/probe.c
       "#include <stddef.h>\n#include <stdint.h>\n"
       "int LLVMFuzzerTestOneInput(const uint8_t *d, size_t n) "
       "{ (void)d; (void)n; return 0; }\n")
  execute_process(
    COMMAND ${KDRAY_CLANG} -fsanitize=fuzzer ${probe_dir}/probe.c -o ${probe_dir}/probe
    RESULT_VARIABLE probe_rc OUTPUT_QUIET ERROR_VARIABLE probe_err)
  file(REMOVE_RECURSE ${probe_dir})
  if(NOT probe_rc EQUAL 0)
    kdray_tool_missing("clang's libFuzzer runtime (${KDRAY_CLANG} -fsanitize=fuzzer: ${probe_err})"
      libclang-rt-14-dev "protocol_fuzz and scenes_fuzz (-DKDRAY_FUZZ=ON)")
  endif()
endif()

# The cluster test: replicas behind HAProxy (deploy/haproxy/kdray.cfg)
# under wrk load.
kdray_require_program(KDRAY_HAPROXY haproxy "cluster (tests/test_cluster.py)" haproxy)
kdray_require_program(KDRAY_WRK wrk "cluster (tests/test_cluster.py)" wrk)

# The k8s_manifests test: Node.js and the npm packages of tests/k8s
# (kubernetes-models, yaml), which ./scripts/dev deps installs.
kdray_require_program(KDRAY_NODE "nodejs" "k8s_manifests (tests/k8s/validate.mjs)" node)
set(KDRAY_K8S_MODULES ${CMAKE_CURRENT_LIST_DIR}/../k8s/node_modules CACHE PATH
    "npm packages of the Kubernetes manifest validator (tests/k8s)")
if(NOT EXISTS "${KDRAY_K8S_MODULES}/kubernetes-models/package.json" OR
   NOT EXISTS "${KDRAY_K8S_MODULES}/yaml/package.json")
  kdray_tool_missing("the npm packages kubernetes-models and yaml in ${KDRAY_K8S_MODULES}"
                     "nodejs/npm (then: cd tests/k8s && npm install)"
                     "k8s_manifests")
endif()
