# The Embree oracle, stress generator and accuracy suites (owner: oracle).
# kdray_testsupport is the shared test library: Embree reference answers,
# adversarial scenes and rays, the scene ladder and the kd-vs-Embree judge.
find_package(embree 3.13 REQUIRED)

file(GLOB KDRAY_TESTSUPPORT_SOURCES CONFIGURE_DEPENDS
     ${CMAKE_CURRENT_SOURCE_DIR}/support/*.c)
add_library(kdray_testsupport STATIC ${KDRAY_TESTSUPPORT_SOURCES})
target_include_directories(kdray_testsupport PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/support)
target_link_libraries(kdray_testsupport PUBLIC kdray_core embree m)
target_compile_definitions(kdray_testsupport PRIVATE
                           KDRAY_SCENE_DIR="${KDRAY_SCENE_DIR}")
if(TARGET kdray_scenes)
  target_link_libraries(kdray_testsupport PUBLIC kdray_scenes)
  target_compile_definitions(kdray_testsupport PRIVATE KDRAY_HAVE_GLTF=1)
endif()
