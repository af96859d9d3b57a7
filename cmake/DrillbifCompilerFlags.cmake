# Compiler flags.
#
# drillbif_build_flags: an INTERFACE target carrying the warning flags. Link it PRIVATE into
# drillbif's own targets only (drillbif_add_* helpers and the engine/client/bench CMakeLists do);
# generated protobuf code and third-party headers do not get it.
#
# Sanitizers apply to every target in the tree (global flags), so that the engine, the tests and
# everything linked together agree on instrumentation.

add_library(drillbif_build_flags INTERFACE)
if(CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
  target_compile_options(drillbif_build_flags INTERFACE -Wall -Wextra -Wpedantic -Wshadow)
  if(DRILLBIF_WERROR)
    target_compile_options(drillbif_build_flags INTERFACE -Werror)
  endif()
endif()

if(DRILLBIF_SANITIZE)
  if(NOT CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
    message(FATAL_ERROR "DRILLBIF_SANITIZE needs GCC or Clang")
  endif()
  # -fno-sanitize-recover=all: a UBSan report aborts the process, so a test with undefined
  # behaviour fails instead of printing a warning that nobody reads.
  set(_drillbif_sanitize_flags -fsanitize=address,undefined -fno-omit-frame-pointer
      -fno-sanitize-recover=all)
  add_compile_options(${_drillbif_sanitize_flags})
  add_link_options(${_drillbif_sanitize_flags})
endif()

# The fuzz build (fuzz/CMakeLists.txt): every library is compiled with libFuzzer's coverage
# instrumentation and the sanitizers, so a finding deep in the jobs or the engine is caught where
# it happens; the fuzz targets alone link -fsanitize=fuzzer (libFuzzer's main).
if(DRILLBIF_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "DRILLBIF_FUZZ needs Clang (CMAKE_CXX_COMPILER=clang++)")
  endif()
  if(DRILLBIF_SANITIZE)
    message(FATAL_ERROR "DRILLBIF_FUZZ already sanitizes; leave DRILLBIF_SANITIZE off")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=all
                      -fno-omit-frame-pointer)
  add_link_options(-fsanitize=address,undefined)
endif()
