# Warnings applied per target, as the house style asks.
function(lrfnet_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wconversion -Wshadow
                                           -Wno-sign-conversion)
  if(LRFNET_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()

# Sanitizers for the whole build: -DLRFNET_SANITIZE=address,undefined
if(LRFNET_SANITIZE)
  add_compile_options(-fsanitize=${LRFNET_SANITIZE} -fno-omit-frame-pointer)
  add_link_options(-fsanitize=${LRFNET_SANITIZE})
endif()

# A unit test beside the code: lrfnet_test(NAME SOURCES... LIBS ...)
function(lrfnet_test name)
  if(LRFNET_FUZZ OR NOT BUILD_TESTING)
    return()
  endif()
  cmake_parse_arguments(T "" "" "SOURCES;LIBS" ${ARGN})
  add_executable(${name} ${T_SOURCES})
  target_link_libraries(${name} PRIVATE ${T_LIBS} lrfnet_test_support GTest::gtest_main)
  lrfnet_warnings(${name})
  if(CMAKE_CROSSCOMPILING)
    target_compile_definitions(${name} PRIVATE LRFNET_CROSS_EMULATED_TESTS=1)
  endif()
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 120 PROPERTIES TIMEOUT 300)
endfunction()
