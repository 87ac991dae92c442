# sandtable_add_library(<name> SOURCES ... [DEPS ...] [PRIVATE_DEPS ...])
#   Adds static library <name> with alias sandtable::<name>. Include paths are rooted at the
#   project source dir, so headers are included as "common/geometry/rigid3.h".
function(sandtable_add_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(${name} STATIC ${ARG_SOURCES})
  add_library(sandtable::${name} ALIAS ${name})
  target_include_directories(${name} PUBLIC ${PROJECT_SOURCE_DIR} ${PROJECT_BINARY_DIR})
  target_link_libraries(${name} PUBLIC ${ARG_DEPS} PRIVATE sandtable::options ${ARG_PRIVATE_DEPS})
endfunction()

# sandtable_add_test(<name> SOURCES ... DEPS ... [LABELS ...] [TIMEOUT s])
#   Adds a GoogleTest executable and registers each of its tests with CTest
#   (gtest_discover_tests), run from the project root so ../shared/data paths resolve.
function(sandtable_add_test name)
  cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;DEPS;LABELS" ${ARGN})
  if(NOT SANDTABLE_BUILD_TESTS)
    return()
  endif()
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main
    sandtable::options)
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  set(properties TIMEOUT ${ARG_TIMEOUT})
  if(ARG_LABELS)
    list(APPEND properties LABELS "${ARG_LABELS}")
  endif()
  gtest_discover_tests(${name}
    WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
    PROPERTIES ${properties}
    DISCOVERY_TIMEOUT 60)
endfunction()

# sandtable_add_benchmark(<name> SOURCES ... DEPS ...)
function(sandtable_add_benchmark name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  if(NOT SANDTABLE_BUILD_BENCHMARKS)
    return()
  endif()
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} benchmark::benchmark sandtable::options)
endfunction()

# sandtable_add_window_test(<name> SOURCES ... DEPS ...)
#   A GoogleTest executable that needs an X display: CTest runs the whole binary under xvfb-run
#   with a 24-bit screen (xvfb-run's default screen is 8 bits deep), label "window". Without
#   xvfb-run it runs as is (its tests that need a display skip). Two run one after the other
#   (RESOURCE_LOCK): `xvfb-run -a` started at once may both pick the same free display, and the
#   first to end kills the X server under the other.
function(sandtable_add_window_test name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  if(NOT SANDTABLE_BUILD_TESTS)
    return()
  endif()
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main
    sandtable::options)
  find_program(XVFB_RUN xvfb-run)
  if(XVFB_RUN)
    add_test(NAME ${name}
      COMMAND ${XVFB_RUN} -a -s "-screen 0 1280x1024x24" $<TARGET_FILE:${name}>)
  else()
    add_test(NAME ${name} COMMAND ${name})
  endif()
  set_tests_properties(${name} PROPERTIES LABELS window TIMEOUT 120
    WORKING_DIRECTORY ${PROJECT_SOURCE_DIR} RESOURCE_LOCK xvfb_display)
endfunction()

# sandtable_embed_text(<target> HEADER <path under the build tree> NAMESPACE <ns>
#                      FILES <name>=<source file> ...)
#   Generates HEADER (included as "<path>") holding each file's text as `<name>[]`, rebuilt when
#   a file changes, and makes <target> depend on it (cmake/EmbedText.cmake).
function(sandtable_embed_text target)
  cmake_parse_arguments(ARG "" "HEADER;NAMESPACE" "FILES" ${ARGN})
  set(output ${PROJECT_BINARY_DIR}/${ARG_HEADER})
  set(inputs "")
  set(depends "")
  foreach(pair IN LISTS ARG_FILES)
    string(FIND "${pair}" "=" at)
    math(EXPR from "${at} + 1")
    string(SUBSTRING "${pair}" 0 ${at} name)
    string(SUBSTRING "${pair}" ${from} -1 file)
    get_filename_component(file "${file}" ABSOLUTE BASE_DIR ${CMAKE_CURRENT_SOURCE_DIR})
    list(APPEND inputs "${name}=${file}")
    list(APPEND depends "${file}")
  endforeach()
  string(REPLACE ";" "|" inputs_arg "${inputs}")
  add_custom_command(OUTPUT ${output}
    COMMAND ${CMAKE_COMMAND} -DOUTPUT=${output} -DNAMESPACE=${ARG_NAMESPACE}
      "-DINPUTS=${inputs_arg}" -P ${PROJECT_SOURCE_DIR}/cmake/EmbedText.cmake
    DEPENDS ${depends} ${PROJECT_SOURCE_DIR}/cmake/EmbedText.cmake
    COMMENT "Embedding ${ARG_HEADER}"
    VERBATIM)
  target_sources(${target} PRIVATE ${output})
endfunction()
