# yaml-cpp for the aarch64 cross build (cmake/toolchains/aarch64-linux-gnu.cmake says why):
# the target `yaml-cpp` of Debian's own yaml-cpp-config.cmake, made of the arm64 runtime
# library (libyaml-cpp0.7:arm64) and the architecture-independent headers in /usr/include.
set(yaml-cpp_VERSION 0.7.0)
find_library(MPPID_YAML_CPP_ARM64 NAMES libyaml-cpp.so.0.7 PATHS /usr/lib/aarch64-linux-gnu NO_DEFAULT_PATH)
find_path(MPPID_YAML_CPP_INCLUDE yaml-cpp/yaml.h PATHS /usr/include NO_DEFAULT_PATH)
if(NOT MPPID_YAML_CPP_ARM64 OR NOT MPPID_YAML_CPP_INCLUDE)
  set(yaml-cpp_FOUND FALSE)
  set(yaml-cpp_NOT_FOUND_MESSAGE "needs libyaml-cpp0.7:arm64 and libyaml-cpp-dev (tools/setup.sh --aarch64)")
  return()
endif()
if(NOT TARGET yaml-cpp)
  add_library(yaml-cpp SHARED IMPORTED)
  set_target_properties(yaml-cpp PROPERTIES IMPORTED_LOCATION ${MPPID_YAML_CPP_ARM64}
                                            IMPORTED_SONAME libyaml-cpp.so.0.7
                                            INTERFACE_INCLUDE_DIRECTORIES ${MPPID_YAML_CPP_INCLUDE})
endif()
