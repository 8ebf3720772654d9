# SIMD kernels of the CPU backend: one translation unit per (task, target), each compiled
# with its target's instruction set, so one binary carries them all and picks one at
# start-up (mppi/simd.hpp). Highway's flags per target (hwy/ops/set_macros-inl.h).
set(MPPID_SIMD_TASKS CartpoleSwingup RacecarEllipse QuadrotorForest QuadrotorTrack
    RateQuadrotorForest RateQuadrotorTrack Team3Forest Team9Forest)  # = kNamedTask (tasks.hpp)

set(MPPID_SIMD_TARGETS "")
if(MPPID_SIMD AND CMAKE_SYSTEM_PROCESSOR MATCHES "^(x86_64|AMD64|amd64)$")
  set(MPPID_SIMD_TARGETS kSse4 kAvx2 kAvx3)
  set(_simd_flags_kSse4 -mssse3 -msse4.1 -msse4.2 -mpclmul -maes)
  set(_simd_flags_kAvx2 ${_simd_flags_kSse4} -mavx -mavx2 -mbmi -mbmi2 -mfma -mf16c)
  set(_simd_flags_kAvx3 ${_simd_flags_kAvx2} -mavx512f -mavx512vl -mavx512dq -mavx512bw)
elseif(MPPID_SIMD AND CMAKE_SYSTEM_PROCESSOR MATCHES "^(aarch64|arm64)$")
  set(MPPID_SIMD_TARGETS kNeon)
  # Highway's NEON target is Armv8-A with the AES extension: with runtime dispatch (GCC on
  # Linux) its functions carry target("+crypto"), so the kernels are compiled with it too.
  set(_simd_flags_kNeon -march=armv8-a+crypto)
endif()
# Sanitizer builds compile every kernel twice (the backend's and the tests' libm variant) under
# ASan; one target is enough there to check the vector code's memory use (CMakePresets.json).
set(MPPID_SIMD_ONLY "" CACHE STRING "Build only these SIMD targets (e.g. kAvx2); empty: all")
if(MPPID_SIMD_ONLY)
  string(REPLACE ";" "|" _only "${MPPID_SIMD_ONLY}")
  list(FILTER MPPID_SIMD_TARGETS INCLUDE REGEX "^(${_only})$")
  message(STATUS "mppid: SIMD targets ${MPPID_SIMD_TARGETS} only (MPPID_SIMD_ONLY)")
endif()

# Generates the kernel sources of every task for every target into OUT_VAR, each defining
# FUNCTION<Task, Target> (cpu::simd_kernel_ops, or a test's) with transcendentals MATH
# (HwyMath or LibmMath).
function(mppi_simd_kernel_sources out_var function math)
  set(_sources "")
  foreach(target IN LISTS MPPID_SIMD_TARGETS)
    foreach(task IN LISTS MPPID_SIMD_TASKS)
      set(TASK ${task})
      set(TARGET ${target})
      set(FUNCTION ${function})
      set(MATH ${math})
      set(_file ${CMAKE_CURRENT_BINARY_DIR}/simd_${function}_${task}_${target}.cpp)
      configure_file(${PROJECT_SOURCE_DIR}/core/src/simd/kernels.cpp.in ${_file} @ONLY)
      # -O2 in a Debug build too: unoptimised, the always-inline vector code would leave
      # out-of-line copies of shared inline functions compiled for this target.
      set_source_files_properties(${_file} PROPERTIES COMPILE_OPTIONS
        "${_simd_flags_${target}};$<$<CONFIG:Debug>:-O2>")
      list(APPEND _sources ${_file})
    endforeach()
  endforeach()
  set(${out_var} ${_sources} PARENT_SCOPE)
endfunction()
