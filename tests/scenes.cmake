# glTF loading and the real-scene ladder (owner: scenes).
# scenes_fetch prepares ${KDRAY_SCENE_DIR} from Debian packages and is the
# fixture for every ladder test (fixture names: scenes and scenes_fetch).
# Its tools (python3, assimp) and models are checked by
# tests/cmake/required_tools.cmake; a missing model file fails the test.
add_test(NAME scenes_fetch COMMAND ${CMAKE_SOURCE_DIR}/scenes/fetch ${KDRAY_SCENE_DIR})
set_tests_properties(scenes_fetch PROPERTIES FIXTURES_SETUP "scenes;scenes_fetch"
                     ENVIRONMENT "KDRAY_ASSIMP_MODELS=${KDRAY_ASSIMP_MODELS}")
# A ladder missing rungs fails scenes/fetch unless --partial.
add_test(NAME scenes_fetch_partial
         COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/test_fetch_partial.sh
                 ${CMAKE_SOURCE_DIR}/scenes/fetch ${KDRAY_ASSIMP_MODELS})

# Synthetic files written by the tests (test_scenes_util.h): every feature
# (scenes_loader) and every error path (scenes_loader_errors).
foreach(t scenes scenes_errors)
  add_executable(test_${t} ${CMAKE_CURRENT_SOURCE_DIR}/test_${t}.c)
  target_link_libraries(test_${t} PRIVATE kdray_scenes m)
endforeach()
add_test(NAME scenes_loader COMMAND test_scenes)
add_test(NAME scenes_loader_errors COMMAND test_scenes_errors)

# Real files: assimp-testmodels, the default scene, the fetched ladder.
add_executable(test_scenes_real ${CMAKE_CURRENT_SOURCE_DIR}/test_scenes_real.c)
target_link_libraries(test_scenes_real PRIVATE kdray_scenes m)
add_test(NAME scenes_models COMMAND test_scenes_real models ${KDRAY_ASSIMP_MODELS})
add_test(NAME scenes_default COMMAND test_scenes_real default
         ${CMAKE_SOURCE_DIR}/scenes/default.glb)
add_test(NAME scenes_ladder COMMAND test_scenes_real ladder ${KDRAY_SCENE_DIR}/ladder.txt)
set_tests_properties(scenes_ladder PROPERTIES FIXTURES_REQUIRED scenes)

# An independent oracle for transforms, hierarchy and numbering: assimp's
# OBJ export flattens the same file in the same order; every triangle must
# match. A missing model file fails the test.
set(KDRAY_G2 ${KDRAY_ASSIMP_MODELS}/glTF2)
foreach(pair "engine=${KDRAY_G2}/2CylinderEngine-glTF-Binary/2CylinderEngine.glb"
             "clearcoat=${KDRAY_G2}/ClearCoat-glTF/ClearCoatTest.gltf"
             "texture_transform=${KDRAY_G2}/textureTransform/TextureTransformTest.gltf"
             "default=${CMAKE_SOURCE_DIR}/scenes/default.glb")
  string(REPLACE "=" ";" kv "${pair}")
  list(GET kv 0 name)
  list(GET kv 1 file)
  add_test(NAME scenes_vs_assimp_${name}
           COMMAND sh -c "'${KDRAY_ASSIMP}' export '${file}' 'assimp_${name}.obj' >/dev/null && '$<TARGET_FILE:test_scenes_real>' obj 'assimp_${name}.obj' '${file}'"
           WORKING_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR})
endforeach()

add_test(NAME scenes_info COMMAND kdray_scene_info ${CMAKE_SOURCE_DIR}/scenes/default.glb)
set_tests_properties(scenes_info PROPERTIES
  PASS_REGULAR_EXPRESSION "triangles: +[1-9][0-9]*.*kd-tree: +[1-9]")

# libFuzzer target for the loader, with -DKDRAY_FUZZ=ON (the sanitizer pass
# of scripts/dev test): the project builds with gcc, so clang++ compiles the
# harness and the loader (tinygltf included) separately (KDRAY_CLANGXX,
# required with KDRAY_FUZZ: tests/cmake/required_tools.cmake), then runs it
# for a bounded time on assimp-testmodels' small glTF 2.0 files.
if(KDRAY_FUZZ)
  set(KDRAY_FUZZ_GLTF_BIN ${CMAKE_CURRENT_BINARY_DIR}/fuzz_gltf)
  add_custom_command(
    OUTPUT ${KDRAY_FUZZ_GLTF_BIN}
    COMMAND ${KDRAY_CLANGXX} -g -O1 -fsanitize=fuzzer,address,undefined
            -fno-sanitize-recover=all -ffp-contract=off -I${PROJECT_SOURCE_DIR}/scenes
            -x c ${CMAKE_CURRENT_SOURCE_DIR}/test_scenes_fuzz.c
            ${PROJECT_SOURCE_DIR}/scenes/gltf_schema.c
            -x c++ ${PROJECT_SOURCE_DIR}/scenes/gltf_shim.cpp -lcjson
            -o ${KDRAY_FUZZ_GLTF_BIN}
    DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/test_scenes_fuzz.c
            ${PROJECT_SOURCE_DIR}/scenes/gltf_schema.c ${PROJECT_SOURCE_DIR}/scenes/gltf_schema.h
            ${PROJECT_SOURCE_DIR}/scenes/gltf_shim.cpp ${PROJECT_SOURCE_DIR}/scenes/kdr_gltf.h
    COMMENT "Building the glTF loader fuzzer with clang++"
    VERBATIM)
  add_custom_target(fuzz_gltf ALL DEPENDS ${KDRAY_FUZZ_GLTF_BIN})
  add_test(NAME scenes_fuzz
           COMMAND ${CMAKE_COMMAND} -E env ASAN_OPTIONS=detect_leaks=1
                   sh -c "rm -rf scenes-fuzz-corpus && mkdir scenes-fuzz-corpus && find '${KDRAY_G2}' -name '*.gltf' -size -40k -exec cp {} scenes-fuzz-corpus/ \\; && '${KDRAY_FUZZ_GLTF_BIN}' -max_total_time=20 -rss_limit_mb=2048 -max_len=20000 -timeout=10 scenes-fuzz-corpus; rc=$?; rm -f scenes-fuzz-input-*; exit $rc"
           WORKING_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR})
endif()
