# paps_add_module(NAME SOURCES ... DEPENDS ...)
# Declares library paps_<NAME> with alias paps::<NAME>, public include dir
# modules/<NAME>/include, installs and exports it.
function(paps_add_module name)
  cmake_parse_arguments(M "" "" "SOURCES;DEPENDS" ${ARGN})
  set(target paps_${name})
  add_library(${target} ${M_SOURCES})
  add_library(paps::${name} ALIAS ${target})
  set_target_properties(${target} PROPERTIES EXPORT_NAME ${name} OUTPUT_NAME paps_${name})
  target_include_directories(${target} PUBLIC
    $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
    $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  target_link_libraries(${target} PUBLIC ${M_DEPENDS})
  target_compile_options(${target} PRIVATE -Wall -Wextra)
  install(TARGETS ${target} EXPORT PAPSTargets
    ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
    LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
  install(DIRECTORY include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endfunction()

# paps_add_test(NAME SOURCES ... DEPENDS ... [LABELS ...] [UNITY])
# UNITY: the sources are compiled a few at a time as one unit (PAPS_UNITY_TESTS). Parsing
# PCL, Eigen and GoogleTest was over half of each test file's compile; a module's test files
# in one program also save the links. Each such file keeps its names in a namespace of its own.
function(paps_add_test name)
  cmake_parse_arguments(T "UNITY" "" "SOURCES;DEPENDS;LABELS" ${ARGN})
  add_executable(${name} ${T_SOURCES})
  if(T_UNITY AND PAPS_UNITY_TESTS)
    set_target_properties(${name} PROPERTIES UNITY_BUILD ON UNITY_BUILD_BATCH_SIZE 6)
  endif()
  target_link_libraries(${name} PRIVATE ${T_DEPENDS} GTest::gtest GTest::gtest_main)
  gtest_discover_tests(${name} PROPERTIES LABELS "${T_LABELS}" DISCOVERY_TIMEOUT 60)
endfunction()
