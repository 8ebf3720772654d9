# Every dependency comes from Debian or PyPI (installed by tools/setup.sh); nothing is vendored.
find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(OpenMP REQUIRED COMPONENTS CXX)
option(MPPID_SIMD "Build the SIMD kernels of the CPU backend (needs Google Highway)" ON)
if(MPPID_SIMD)
  find_package(hwy REQUIRED)  # Google Highway (Debian libhwy-dev): SIMD targets and vector math
endif()
find_path(RANDOM123_INCLUDE_DIR Random123/philox.h REQUIRED)
add_library(random123 INTERFACE)
target_include_directories(random123 SYSTEM INTERFACE ${RANDOM123_INCLUDE_DIR})

# CUDA: ON requires it, AUTO uses it when nvcc is found, OFF skips it.
set(MPPID_WITH_CUDA OFF)
if(NOT MPPID_CUDA STREQUAL "OFF")
  include(CheckLanguage)
  check_language(CUDA)
  if(CMAKE_CUDA_COMPILER)
    if(NOT DEFINED CMAKE_CUDA_ARCHITECTURES)
      # Ampere and Hopper SASS plus PTX for anything newer; gpu/CMakeLists.txt adds the Jetson
      # Orin's (MPPID_CUDA_ORIN).
      set(CMAKE_CUDA_ARCHITECTURES 80-real 90-real 90-virtual)
    endif()
    enable_language(CUDA)
    set(CMAKE_CUDA_STANDARD 17)
    set(CMAKE_CUDA_STANDARD_REQUIRED ON)
    find_package(CUDAToolkit REQUIRED)
    set(MPPID_WITH_CUDA ON)
  elseif(MPPID_CUDA STREQUAL "ON")
    message(FATAL_ERROR "MPPID_CUDA=ON but no CUDA compiler was found (set CUDACXX or PATH)")
  endif()
endif()
message(STATUS "mppid: CUDA backend ${MPPID_WITH_CUDA}")

if(MPPID_TESTS)
  # MPPID_GTEST_SOURCE: build GoogleTest from a source tree (a copy of Debian's
  # /usr/src/googletest) on machines without the installed package, e.g. the GPU machine.
  set(MPPID_GTEST_SOURCE "" CACHE PATH "GoogleTest source tree to build instead of find_package(GTest)")
  if(MPPID_GTEST_SOURCE)
    set(INSTALL_GTEST OFF CACHE BOOL "" FORCE)
    set(BUILD_GMOCK OFF CACHE BOOL "" FORCE)
    add_subdirectory(${MPPID_GTEST_SOURCE} ${CMAKE_BINARY_DIR}/_deps/googletest EXCLUDE_FROM_ALL SYSTEM)
  else()
    find_package(GTest REQUIRED)
  endif()
  include(GoogleTest)
endif()
if(MPPID_BENCH)
  find_package(benchmark QUIET)
endif()

if(MPPID_LCM)
  # The lcm wheel (PyPI, 1.5.x) installed in the project venv ships lcmConfig.cmake.
  if(NOT lcm_DIR)
    find_program(MPPID_VENV_PYTHON NAMES python3 PATHS ${CMAKE_SOURCE_DIR}/.venv/bin NO_DEFAULT_PATH)
    if(MPPID_VENV_PYTHON)
      execute_process(COMMAND ${MPPID_VENV_PYTHON} -c
        "import lcm,os;print(os.path.join(os.path.dirname(os.path.dirname(lcm.__file__)),'lib','lcm','cmake'))"
        OUTPUT_VARIABLE _lcm_dir OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
      set(lcm_DIR ${_lcm_dir} CACHE PATH "lcmConfig.cmake from the lcm wheel")
    endif()
  endif()
  find_package(lcm 1.5 CONFIG REQUIRED)
  if(CMAKE_CROSSCOMPILING)
    # The target's lcm (the aarch64 wheel: headers, liblcm) generates code with this
    # machine's lcm-gen, the same version from the host wheel in the venv.
    find_program(MPPID_HOST_LCM_GEN lcm-gen PATHS ${CMAKE_SOURCE_DIR}/.venv/bin NO_DEFAULT_PATH REQUIRED)
    set_target_properties(lcm-gen PROPERTIES IMPORTED_LOCATION_RELEASE ${MPPID_HOST_LCM_GEN})
  endif()
  include(${LCM_USE_FILE})
  find_package(PkgConfig REQUIRED)
  pkg_check_modules(LIBSYSTEMD IMPORTED_TARGET libsystemd)
endif()
