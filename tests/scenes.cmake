# glTF loading and the real-scene ladder (owner: scenes).
# scenes_fetch prepares ${KDRAY_SCENE_DIR} from Debian packages and is the
# fixture for every ladder test (fixture names: scenes and scenes_fetch).
add_test(NAME scenes_fetch COMMAND ${CMAKE_SOURCE_DIR}/scenes/fetch ${KDRAY_SCENE_DIR})
set_tests_properties(scenes_fetch PROPERTIES FIXTURES_SETUP "scenes;scenes_fetch")

if(TARGET kdray_scenes)
  # Synthetic files written by the test: every feature and error path.
  add_executable(test_scenes ${CMAKE_CURRENT_SOURCE_DIR}/test_scenes.c)
  target_link_libraries(test_scenes PRIVATE kdray_scenes m)
  add_test(NAME scenes_loader COMMAND test_scenes)

  # Real files: assimp-testmodels, the default scene, the fetched ladder.
  add_executable(test_scenes_real ${CMAKE_CURRENT_SOURCE_DIR}/test_scenes_real.c)
  target_link_libraries(test_scenes_real PRIVATE kdray_scenes m)
  add_test(NAME scenes_models COMMAND test_scenes_real models /usr/share/assimp/models)
  add_test(NAME scenes_default COMMAND test_scenes_real default
           ${CMAKE_SOURCE_DIR}/scenes/default.glb)
  add_test(NAME scenes_ladder COMMAND test_scenes_real ladder ${KDRAY_SCENE_DIR}/ladder.txt)
  set_tests_properties(scenes_models scenes_ladder PROPERTIES SKIP_RETURN_CODE 77)
  set_tests_properties(scenes_ladder PROPERTIES FIXTURES_REQUIRED scenes)
endif()

if(TARGET kdray_scene_info)
  add_test(NAME scenes_info COMMAND kdray_scene_info ${CMAKE_SOURCE_DIR}/scenes/default.glb)
  set_tests_properties(scenes_info PROPERTIES
    PASS_REGULAR_EXPRESSION "triangles: +[1-9][0-9]*.*kd-tree: +[1-9]")
endif()
