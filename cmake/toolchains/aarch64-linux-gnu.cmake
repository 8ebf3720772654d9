# Cross build for aarch64 (arm64) Linux from an x86-64 Debian 12: Debian's cross compiler
# (g++-aarch64-linux-gnu) and the arm64 packages of the libraries beside the amd64 ones
# (multiarch, /usr/lib/aarch64-linux-gnu); tests and programs run under qemu-user. The
# `aarch64` preset (CMakePresets.json) uses this file; tools/setup.sh --aarch64 installs
# what it needs, tools/aarch64.sh is CI's stage, docs/aarch64.md the whole story.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)

# Libraries and CMake packages: the target's only (/usr/lib/aarch64-linux-gnu and the
# architecture-independent /usr/share, /usr/include); programs run while building: the host's.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(ENV{PKG_CONFIG_LIBDIR} /usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig)

# ctest, gtest_discover_tests and try_run run target programs through qemu-user, as a
# Cortex-A76 (the Raspberry Pi 5's core; Jetson Orin's A78AE has the same Armv8.2-A features
# Highway's NEON target uses), with the arm64 runtime of the multiarch packages (libc6,
# libstdc++6, libgomp1 :arm64), as a Debian board would. (Not `-L /usr/aarch64-linux-gnu`, the
# cross toolchain's copy: under qemu 7.2 its pthread_create never returns.)
find_program(MPPID_QEMU_AARCH64 NAMES qemu-aarch64-static qemu-aarch64 REQUIRED)
set(CMAKE_CROSSCOMPILING_EMULATOR ${MPPID_QEMU_AARCH64} -cpu cortex-a76)

# Debian 12's libyaml-cpp-dev is not Multi-Arch: same, so its arm64 package cannot sit beside
# the amd64 one: the arm64 runtime library (libyaml-cpp0.7:arm64) with the amd64 package's
# headers, which are the same on every architecture (cmake/aarch64/yaml-cpp-config.cmake).
set(yaml-cpp_DIR ${CMAKE_CURRENT_LIST_DIR}/../aarch64 CACHE PATH "yaml-cpp for the aarch64 cross build")
# liblcm (static, from the lcm wheel for aarch64) needs glib: the arm64 runtime library as
# it is (no arm64 glib headers needed: lcmtypes/CMakeLists.txt, MPPID_GLIB_LIBRARY).
set(MPPID_GLIB_LIBRARY /usr/lib/aarch64-linux-gnu/libglib-2.0.so.0 CACHE FILEPATH "arm64 glib")
