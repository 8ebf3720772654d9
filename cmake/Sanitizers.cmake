# Sanitizer and fuzzing builds (clang; CMakePresets.json: `asan`, `tsan`).
#   MPPID_SANITIZE=address,undefined | thread: every C++ target of the project is built and
#     linked with -fsanitize=...; UBSan reports are fatal (-fno-sanitize-recover), so a test
#     that triggers one fails.
#   MPPID_FUZZ=ON: the libFuzzer targets of test/fuzz (with MPPID_SANITIZE=address,undefined),
#     and coverage instrumentation (-fsanitize=fuzzer-no-link) of the code under test.
set(MPPID_SANITIZE "" CACHE STRING "Sanitizers for every target (clang): address,undefined | thread | empty")
option(MPPID_FUZZ "Build the libFuzzer targets of test/fuzz (clang)" OFF)

if(MPPID_SANITIZE OR MPPID_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "MPPID_SANITIZE / MPPID_FUZZ need clang (e.g. cmake --preset asan)")
  endif()
  if(MPPID_WITH_CUDA)
    message(FATAL_ERROR "sanitizer builds are CPU-only: configure with -DMPPID_CUDA=OFF")
  endif()
endif()
if(MPPID_SANITIZE)
  add_compile_options($<$<COMPILE_LANGUAGE:CXX>:-fsanitize=${MPPID_SANITIZE}>
                      $<$<COMPILE_LANGUAGE:CXX>:-fno-sanitize-recover=all>
                      $<$<COMPILE_LANGUAGE:CXX>:-fno-omit-frame-pointer>)
  add_link_options(-fsanitize=${MPPID_SANITIZE})
  message(STATUS "mppid: sanitizers ${MPPID_SANITIZE}")
endif()
if(MPPID_FUZZ)
  add_compile_options($<$<COMPILE_LANGUAGE:CXX>:-fsanitize=fuzzer-no-link>)
  message(STATUS "mppid: libFuzzer targets in ${CMAKE_BINARY_DIR}/fuzz")
endif()
