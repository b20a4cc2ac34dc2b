# check_required_tools.cmake — the tools_required test (cmake -P): hides
# one test tool at a time and checks that configuring the tests stops with
# an error naming the tool and its Debian package, instead of leaving tests
# out. Also: nothing hidden configures; the whole project with a tool hidden
# fails; the whole project with -DBUILD_TESTING=OFF and every tool hidden
# configures (kdrayd alone needs none of them).
#
#   cmake -DSRC=<source dir> -DWORK=<scratch dir> -DGENERATOR=<generator>
#         -DCC=<C compiler> -DCXX=<C++ compiler> -P check_required_tools.cmake

set(tools ${SRC}/tests/cmake/required_tools.cmake)
set(failures 0)

# run(NAME EXPECT_FAIL NEEDLES ARGS...): runs cmake with ARGS; if EXPECT_FAIL,
# it must fail and its error text must hold every needle of NEEDLES (a
# ;-list); else it must succeed.
function(run name expect_fail needles)
  execute_process(COMMAND ${CMAKE_COMMAND} ${ARGN}
                  WORKING_DIRECTORY ${WORK}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  string(REGEX REPLACE "[ \t\r\n]+" " " text "${err}")
  set(ok 1)
  if(expect_fail AND rc EQUAL 0)
    set(ok 0)
    set(why "configured although the tool was hidden")
  elseif(NOT expect_fail AND NOT rc EQUAL 0)
    set(ok 0)
    set(why "failed: ${text}")
  endif()
  if(ok AND expect_fail)
    foreach(n IN LISTS needles)
      string(FIND "${text}" "${n}" at)
      if(at LESS 0)
        set(ok 0)
        set(why "the error does not say \"${n}\": ${text}")
      endif()
    endforeach()
  endif()
  if(ok)
    message(STATUS "ok   ${name}")
  else()
    message(STATUS "FAIL ${name}: ${why}")
    math(EXPR n "${failures} + 1")
    set(failures ${n} PARENT_SCOPE)
  endif()
endfunction()

file(REMOVE_RECURSE ${WORK})
file(MAKE_DIRECTORY ${WORK})

run("nothing hidden" 0 "" -P ${tools})
run("nothing hidden, fuzzers on" 0 "" -DKDRAY_FUZZ=ON -P ${tools})
run("python3 hidden" 1 "the program python3;package python3;server_integration"
    -DKDRAY_PYTHON3=/nonexistent/python3 -P ${tools})
run("curl hidden" 1 "the program curl;package curl;server_curl_examples"
    -DKDRAY_CURL=/nonexistent/curl -P ${tools})
run("assimp hidden" 1 "the program assimp;package assimp-utils;scenes_vs_assimp"
    -DKDRAY_ASSIMP=/nonexistent/assimp -P ${tools})
run("haproxy hidden" 1 "the program haproxy;package haproxy;cluster"
    -DKDRAY_HAPROXY=/nonexistent/haproxy -P ${tools})
run("wrk hidden" 1 "the program wrk;package wrk;cluster"
    -DKDRAY_WRK=/nonexistent/wrk -P ${tools})
run("node hidden" 1 "the program node;package nodejs;k8s_manifests"
    -DKDRAY_NODE=/nonexistent/node -P ${tools})
run("k8s npm packages hidden" 1 "kubernetes-models;npm install;k8s_manifests"
    -DKDRAY_K8S_MODULES=/nonexistent/node_modules -P ${tools})
run("models hidden" 1 "package assimp-testmodels;test_core_scene;scenes_fuzz"
    -DKDRAY_ASSIMP_MODELS=/nonexistent/models -P ${tools})
run("clang hidden" 1 "the program clang;package clang;protocol_fuzz"
    -DKDRAY_FUZZ=ON -DKDRAY_CLANG=/nonexistent/clang -P ${tools})
run("clang++ hidden" 1 "the program clang++;package clang;scenes_fuzz"
    -DKDRAY_FUZZ=ON -DKDRAY_CLANGXX=/nonexistent/clang++ -P ${tools})
# a clang that cannot link a fuzzer stands for a missing libFuzzer runtime
run("libFuzzer runtime missing" 1 "libFuzzer runtime;package libclang-rt-14-dev"
    -DKDRAY_FUZZ=ON -DKDRAY_CLANG=/bin/false -P ${tools})

set(project -S ${SRC} -G ${GENERATOR} -DCMAKE_C_COMPILER=${CC}
            -DCMAKE_CXX_COMPILER=${CXX})
run("project, curl hidden" 1 "the program curl;package curl"
    ${project} -B ${WORK}/with-tests -DKDRAY_CURL=/nonexistent/curl)
run("project without tests, every tool hidden" 0 ""
    ${project} -B ${WORK}/no-tests -DBUILD_TESTING=OFF -DKDRAY_FUZZ=ON
    -DKDRAY_PYTHON3=/nonexistent/python3 -DKDRAY_CURL=/nonexistent/curl
    -DKDRAY_ASSIMP=/nonexistent/assimp -DKDRAY_ASSIMP_MODELS=/nonexistent/models
    -DKDRAY_CLANG=/nonexistent/clang -DKDRAY_CLANGXX=/nonexistent/clang++)

file(REMOVE_RECURSE ${WORK})
if(failures GREATER 0)
  message(FATAL_ERROR "${failures} case(s) failed")
endif()
