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

option(LRFNET_UNITY_TESTS "Compile each test binary as one translation unit" ON)
option(LRFNET_PCH "Precompiled headers for the libraries whose many files share heavy headers" ON)
# The test binaries' own code (test cases, fixtures, support code) at -O1 in optimized builds; the code
# under test keeps the build type's level (its libraries are compiled as usual). Half the test
# binaries' compile time is optimization, mostly of gtest's assertion templates; -O1 takes a fifth
# to two fifths less CPU (daemon_io_test 14.9 -> 10.7 s, calib_align_test 50.5 -> 42.2 s) and the
# results are the same on x86-64 (no -ffast-math; x86-64's baseline has no fused multiply-add).
# GCC contracts a * b + c into a fused multiply-add in C++ whatever the -std mode (its default
# -ffp-contract=fast; the ISO mode turns it off for C only), from -O2 on where the target has one:
# on aarch64 the tests' own arithmetic at -O1 (not fused) may differ in the last bit from the same
# expression in the code under test (fused).
# -DLRFNET_TEST_OPTIMIZE= (empty) compiles them like the rest.
set(LRFNET_TEST_OPTIMIZE "-O1" CACHE STRING
    "Optimization flag for the test binaries' own sources in Release/RelWithDebInfo builds")

# A unit test beside the code: lrfnet_test(NAME SOURCES... LIBS ...)
function(lrfnet_test name)
  if(LRFNET_FUZZ OR NOT BUILD_TESTING)
    return()
  endif()
  cmake_parse_arguments(T "" "" "SOURCES;LIBS" ${ARGN})
  add_executable(${name} ${T_SOURCES})
  # One translation unit per test binary (LRFNET_UNITY_TESTS, see "Building by hand" in README.md):
  # the test files of a binary share gtest, Eigen and the code under test; compiled together they are
  # parsed and instantiated once.
  if(LRFNET_UNITY_TESTS)
    set_target_properties(${name} PROPERTIES UNITY_BUILD ON UNITY_BUILD_BATCH_SIZE 0)
  endif()
  target_link_libraries(${name} PRIVATE ${T_LIBS} lrfnet_test_support GTest::gtest_main)
  lrfnet_warnings(${name})
  # Not in the cross (aarch64) build: tests there compare the tracker's points bit for bit with
  # their own r * cos(angle), and GCC at -O1 calls cos and sin where at -O2 it calls sincos, whose
  # last bits differ from them in aarch64's libm (x86-64's agree).
  if(LRFNET_TEST_OPTIMIZE AND NOT CMAKE_CROSSCOMPILING)
    target_compile_options(${name} PRIVATE
                           $<$<CONFIG:Release,RelWithDebInfo>:${LRFNET_TEST_OPTIMIZE}>)
  endif()
  if(CMAKE_CROSSCOMPILING)
    target_compile_definitions(${name} PRIVATE LRFNET_CROSS_EMULATED_TESTS=1)
  endif()
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 120 PROPERTIES TIMEOUT 300)
endfunction()

# The per-scan path's libraries (CoLa decoding, tracking, the uplink, the tracker node) with every
# function starting on a 64-byte boundary (a cache line): where the linker puts a function then
# decides nothing about which cache lines and fetch blocks its loops share. With the compiler's
# default (16 bytes), the same code moved by 16, 32 or 48 bytes (code added in front of it, e.g. a
# change to an unrelated function) moved tracker_benchmark's 10-people ratio to the empty scene
# between 2.085 and 2.155 (medians of four runs in turns each); aligned to 64 bytes the shift
# changes no address in them, and one binary's medians spread 2.07-2.09 within one sitting (the
# machine's load moves a binary's median by up to 0.05 between sittings minutes apart: compare
# builds only alternated, run after run). It applies to every scene alike (the empty scene's code too) and
# changes no result (alignment padding only). -DLRFNET_ALIGN_HOT_FUNCTIONS= (empty) leaves the compiler's default.
set(LRFNET_ALIGN_HOT_FUNCTIONS "64" CACHE STRING
    "Function alignment in bytes for the tracker's per-scan libraries (empty: the compiler's default)")
function(lrfnet_hot_code target)
  if(LRFNET_ALIGN_HOT_FUNCTIONS)
    target_compile_options(${target} PRIVATE -falign-functions=${LRFNET_ALIGN_HOT_FUNCTIONS})
  endif()
endfunction()

# The per-track code of the per-scan path (the shape fit, the tracks' filters, gate and assignment,
# the pipeline's measurements, the encoding of the tracks: work that grows with the people in view
# and is nearly absent from an empty scene) built with -O3 (inlining, unrolling and vectorising
# across the fit's fixed-size loops), -fno-math-errno (a square root is one instruction, without
# the branch to libm that only sets errno) and -fno-plt (libm's sincos, hypot and atan2 called
# without the PLT's jump), on top of the build type's flags. None of them changes a result on
# x86-64: no reassociation of floating point, and no fused multiply-add in x86-64's baseline to
# contract into (tracking_benchmark's tables byte for byte the same). Where the target has one
# (aarch64), GCC contracts a * b + c in C++ at -O2 and -O3 alike, ISO mode or not (its default
# -ffp-contract=fast), and the loops -O3 vectorises may fuse differently from -O2's scalar code:
# the last bit may differ there. The per-beam code every scan runs (background model,
# segmentation, the scan's decoding) keeps the build type's flags: -O3 inlines the background
# model's per-beam update into its loop, which makes every scene faster alike. Measured
# (tracker_benchmark, callgrind inside
# TrackerNode::OnScan per scan): instructions 130.0k / 257.6k / 559.2k -> 130.0k / 247.7k / 528.9k
# at 0 / 10 / 50 people. In time the gain is smaller and partly not the code's: in turns, alternated
# with the tree without these flags, 10 people 2.04-2.06x -> 1.98-2.00x and 50 people 5.12-5.17x
# -> 5.00x, but the empty scene took 2-3 % longer in turns (not when run alone: 10.40 against 10.40
# us); the same binary with only 3 KiB of cold padding in front of the per-scan code (no code
# changed) showed the same: its empty scene 2 % slower in turns and 10 people 2.055x -> 2.030x
# (1 KiB of padding instead: the empty scene 2 % faster, 10 people 2.06x -> 2.07x, 50 people 5.23x
# -> 5.33x; where the linker puts the per-beam code moves the ratios by as much as these flags).
# Over three placements (0, 1 and 3 KiB of padding, each with and without the flags, in turns, six
# runs each) the flags gave 10 people 21.15 -> 20.75 us, 50 people 53.0 -> 52.2 us, the empty scene
# 10.25 -> 10.32 us; the ratios 2.06 -> 2.02x and 5.22 -> 5.10x: not yet 2x at 10 people.
# Only in optimised builds (RelWithDebInfo, Release); -DLRFNET_PER_TRACK_FLAGS= (empty) builds these
# files like the others.
set(LRFNET_PER_TRACK_FLAGS "-O3;-fno-math-errno;-fno-plt" CACHE STRING
    "Extra compiler flags for the tracker's per-track sources in optimised builds (empty: none)")
function(lrfnet_per_track_sources target)
  foreach(flag IN LISTS LRFNET_PER_TRACK_FLAGS)
    set_property(SOURCE ${ARGN} TARGET_DIRECTORY ${target} APPEND PROPERTY COMPILE_OPTIONS
                 "$<$<CONFIG:RelWithDebInfo,Release>:${flag}>")
  endforeach()
endfunction()
