# The Debian package `mppid` (CPack's DEB generator; tools/package.sh builds it for amd64 from
# build/ and for arm64 from the aarch64 cross build, build-aarch64/). What it holds is
# cmake/Install.cmake's; docs/deploy.md says what it depends on and why.
set(CPACK_GENERATOR DEB)
# Packaging builds only what it installs (tools/package.sh names the targets), not `all`:
# the aarch64 cross build holds only what its stage runs.
set(CMAKE_SKIP_INSTALL_ALL_DEPENDENCY ON)
set(CPACK_PACKAGE_NAME mppid)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
# The Maintainer field: whoever builds and ships the package puts their address here. The
# default is the reserved domain example.org (RFC 2606): a valid mail host (lintian checks the
# syntax), which reaches nobody rather than pretending to be an address (docs/deploy.md, lintian).
set(MPPID_DEB_MAINTAINER "mppid maintainers <mppid@example.org>" CACHE STRING "The package's Maintainer field")
set(CPACK_PACKAGE_CONTACT "${MPPID_DEB_MAINTAINER}")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "real-time MPPI quadrotor controller for a companion computer")
# (lines under 80 characters: lintian's extended-description-line-too-long)
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION
    "mppid flies a quadrotor through its autopilot (PX4 or ArduPilot) from a\n\
 companion computer: the controller (mppid), the local mapper, the MAVLink\n\
 bridge, the mission tool and the flight recorder, with systemd units\n\
 (mppid.target) and settings in /etc/mppid. docs: /usr/share/doc/mppid.")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION misc)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
if(CMAKE_SYSTEM_PROCESSOR STREQUAL "aarch64")
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE arm64)
elseif(CMAKE_SYSTEM_PROCESSOR STREQUAL "x86_64")
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE amd64)
endif()
# What runs on the board, by Debian 12 package: mppid's shared libraries (liblcm is linked in
# statically), the Python the bridge and the mission tool run on with the modules Debian has
# (the rest travels in /usr/lib/mppid/python), `ip` for the LCM route. Nothing for building.
# tools/package-test.sh installs the package into a Debian 12 root holding only these.
set(MPPID_DEB_DEPENDS
    "libc6 (>= 2.36), libstdc++6 (>= 12), libgcc-s1, libgomp1, libyaml-cpp0.7, libspdlog1.10, libfmt9, libhwy1, libsystemd0, libglib2.0-0, python3 (>= 3.11), python3 (<< 3.12), python3-numpy, python3-yaml, python3-serial, iproute2"
    CACHE STRING "The package's Depends (Debian 12 names)")
set(CPACK_DEBIAN_PACKAGE_DEPENDS "${MPPID_DEB_DEPENDS}")
# mppid-realsense's pyrealsense2 (not carried: docs/deploy.md) links libusb.
set(CPACK_DEBIAN_PACKAGE_SUGGESTS "libusb-1.0-0")
# The live settings are the operator's: an upgrade keeps edited files (dpkg asks).
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
    ${PROJECT_SOURCE_DIR}/cmake/debian/conffiles ${PROJECT_SOURCE_DIR}/cmake/debian/postinst
    ${PROJECT_SOURCE_DIR}/cmake/debian/prerm ${PROJECT_SOURCE_DIR}/cmake/debian/postrm)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
# Debug information stays in the build (mppid: 15 MB unstripped, 2 MB stripped); the wheels'
# programs and extension modules are stripped by cmake/install_python.py.
set(CPACK_STRIP_FILES ON)
include(CPack)
