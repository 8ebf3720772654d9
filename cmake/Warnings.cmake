# One warnings policy for every target, C++ and CUDA alike. Warnings are errors in CI
# (MPPID_WERROR=ON there) so the build stays warning-free.
option(MPPID_WERROR "Treat warnings as errors" OFF)

add_library(mppid_warnings INTERFACE)
set(_cxx_warn -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion
    -Wnon-virtual-dtor -Wold-style-cast)
# clang only (the sanitizer and fuzz builds): -Wunused-private-field, which gcc, the
# reference build, does not have, is left to gcc's policy.
if(CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
  list(APPEND _cxx_warn -Wno-unused-private-field)
endif()
target_compile_options(mppid_warnings INTERFACE
  $<$<COMPILE_LANGUAGE:CXX>:${_cxx_warn}>
  $<$<COMPILE_LANGUAGE:CUDA>:-Xcompiler=-Wall,-Wextra --Werror=all-warnings>)
if(MPPID_WERROR)
  target_compile_options(mppid_warnings INTERFACE $<$<COMPILE_LANGUAGE:CXX>:-Werror>
                                                  $<$<COMPILE_LANGUAGE:CUDA>:-Xcompiler=-Werror>)
endif()

add_library(mppid_arch INTERFACE)
if(MPPID_NATIVE)
  target_compile_options(mppid_arch INTERFACE $<$<COMPILE_LANGUAGE:CXX>:-march=native>)
endif()
