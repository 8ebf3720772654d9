# What a vehicle's companion computer runs, and nothing else (docs/deploy.md): `cmake --install`
# and the Debian package (cmake/Packaging.cmake, tools/package.sh) put in place
#   bin/mppid                               the controller
#   bin/mppid-mavlink-bridge, bin/mppid-mission   Debian's python3 with lib/mppid/python
#   lib/mppid/python/                       the project's Python packages and the LCM types, with
#                                           the PyPI wheels Debian 12 lacks (pymavlink, fastcrc,
#                                           lcm: its lcm-logger is the flight recorder)
#   lib/systemd/system/mppid*.{target,service}   the units (drivers/systemd/)
#   /etc/mppid/{mppid,vehicle,mavlink-bridge}.yaml  the live settings (conffiles)
#   share/mppid/                            their templates: the link profiles per autopilot and
#                                           port, tasks, vehicles, missions, autopilot parameters
#   share/doc/mppid/                        first-flight.md, deploy.md
# Not installed: the simulator, the offline tools, the tests, the benchmarks, the live view and
# lcm-spy (they run on the ground, from a source tree).
include(GNUInstallDirs)

# The units name /usr/bin, /usr/lib/mppid and /etc/mppid: the package installs under /usr
# (a hand install: `cmake --install build --prefix /usr`). /etc/mppid is /etc/mppid whatever
# the prefix; the Python programs find lib/mppid/python beside their own bin/.
set(MPPID_INSTALL_PYTHONDIR lib/mppid/python)
set(_etc /etc/mppid)
set(_share ${CMAKE_INSTALL_DATADIR}/mppid)
# The build machine's Python (the venv's: pip, and lcm's version the C++ links) runs the install.
find_program(MPPID_HOST_PYTHON NAMES python3 PATHS ${PROJECT_SOURCE_DIR}/.venv/bin NO_DEFAULT_PATH)

# ---- programs ------------------------------------------------------------------------
if(TARGET mppid)
  install(TARGETS mppid RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
endif()
# The Python programs: Debian's python3 on the package's own Python directory (no venv: a
# venv's absolute paths would be the build machine's).
foreach(_prog mppid-mavlink-bridge:mppi_mavlink mppid-mission:mppi_mission)
  string(REPLACE ":" ";" _pm ${_prog})
  list(GET _pm 0 MPPID_PROGRAM)
  list(GET _pm 1 MPPID_PY_MODULE)
  configure_file(${CMAKE_CURRENT_LIST_DIR}/python-program.sh.in ${CMAKE_BINARY_DIR}/deploy/bin/${MPPID_PROGRAM} @ONLY)
  install(PROGRAMS ${CMAKE_BINARY_DIR}/deploy/bin/${MPPID_PROGRAM} DESTINATION ${CMAKE_INSTALL_BINDIR})
endforeach()

# ---- Python --------------------------------------------------------------------------
# MPPID_PYTHON_PACKAGES: the project's Python package folders. One with a pyproject.toml is
# installed with `pip install --no-deps --no-build-isolation --target`; one without is a
# PYTHONPATH root (drivers/mavlink today), whose packages are copied as they are.
set(MPPID_PYTHON_PACKAGES
    "${PROJECT_SOURCE_DIR}/drivers/mavlink;${PROJECT_SOURCE_DIR}/drivers/mission;${CMAKE_BINARY_DIR}/python"
    CACHE STRING "Python package folders the package carries (pyproject.toml: pip; else copied)")
# MPPID_PYTHON_WHEELS: what Debian 12 lacks, from PyPI for the target (pinned to the venv's).
set(_wheels "")
foreach(_dist lcm pymavlink fastcrc)
  set(_ver "")
  if(MPPID_HOST_PYTHON)
    execute_process(COMMAND ${MPPID_HOST_PYTHON} -c "import importlib.metadata as m; print(m.version('${_dist}'))"
                    OUTPUT_VARIABLE _ver OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
  endif()
  if(_ver)
    list(APPEND _wheels "${_dist}==${_ver}")
  else()
    list(APPEND _wheels "${_dist}")
  endif()
endforeach()
set(MPPID_PYTHON_WHEELS "${_wheels}" CACHE STRING "PyPI distributions the package carries (name==version)")
# The board's Python: Debian 12's 3.11 (a Jetson's Ubuntu 22.04 has 3.10: build there, docs/deploy.md).
set(MPPID_PYTHON_VERSION "3.11" CACHE STRING "The target's python3 version (wheels are chosen for it)")
set(MPPID_WHEEL_CACHE "$ENV{HOME}/.cache/mppid/wheels" CACHE PATH "Downloaded wheels, kept between builds")
install(CODE "
  execute_process(COMMAND \"${MPPID_HOST_PYTHON}\" \"${CMAKE_CURRENT_LIST_DIR}/install_python.py\"
      --dest \"\$ENV{DESTDIR}\${CMAKE_INSTALL_PREFIX}/${MPPID_INSTALL_PYTHONDIR}\"
      --final-dir \"\${CMAKE_INSTALL_PREFIX}/${MPPID_INSTALL_PYTHONDIR}\"
      --arch ${CMAKE_SYSTEM_PROCESSOR} --python-version ${MPPID_PYTHON_VERSION}
      --wheel-cache \"${MPPID_WHEEL_CACHE}\"
      --wheels \"${MPPID_PYTHON_WHEELS}\" --packages \"${MPPID_PYTHON_PACKAGES}\"
    RESULT_VARIABLE _rc)
  if(NOT _rc EQUAL 0)
    message(FATAL_ERROR \"install_python.py failed (\${_rc})\")
  endif()")

# ---- systemd units -------------------------------------------------------------------
install(FILES ${PROJECT_SOURCE_DIR}/drivers/systemd/mppid.target
              ${PROJECT_SOURCE_DIR}/drivers/systemd/mppid.service
              ${PROJECT_SOURCE_DIR}/drivers/systemd/mppid-mavlink-bridge.service
              ${PROJECT_SOURCE_DIR}/drivers/systemd/mppid-recorder.service
              ${PROJECT_SOURCE_DIR}/drivers/systemd/mppid-lcm-route.service
        DESTINATION lib/systemd/system)

# ---- settings: live files in /etc/mppid, templates in share/mppid ---------------------
# /etc/mppid/mppid.yaml is the rate-tracking task (thrust and body rates: what the bridge
# forwards) with its vehicle beside it: the task file's `vehicle: ../vehicles/...` rewritten
# to the vehicle.yaml in the same folder, so the file resolves under /etc/mppid.
file(READ ${PROJECT_SOURCE_DIR}/config/tasks/quadrotor_rate_track.yaml _task)
string(REGEX REPLACE "\nvehicle: [^\n]*" "\nvehicle: vehicle.yaml" _task "${_task}")
file(WRITE ${CMAKE_BINARY_DIR}/deploy/etc/mppid.yaml "${_task}")
install(FILES ${CMAKE_BINARY_DIR}/deploy/etc/mppid.yaml
              ${PROJECT_SOURCE_DIR}/config/deploy/vehicle.yaml
        DESTINATION ${_etc})
install(FILES ${PROJECT_SOURCE_DIR}/config/bridge/px4_pi5_uart.yaml DESTINATION ${_etc} RENAME mavlink-bridge.yaml)
file(GLOB _bridge_profiles ${PROJECT_SOURCE_DIR}/config/bridge/px4_*.yaml ${PROJECT_SOURCE_DIR}/config/bridge/ardupilot_*.yaml)
# Not the simulators' (this machine's SITL) nor px4_serial.yaml (a vehicle path of the source tree).
list(FILTER _bridge_profiles EXCLUDE REGEX "(_sitl|px4_serial)\\.yaml$")
install(FILES ${_bridge_profiles} DESTINATION ${_share}/bridge)
install(FILES ${PROJECT_SOURCE_DIR}/config/tasks/quadrotor_rate_track.yaml
              ${PROJECT_SOURCE_DIR}/config/tasks/quadrotor_rate_track_pi5.yaml
              ${PROJECT_SOURCE_DIR}/config/tasks/quadrotor_rate_forest.yaml
        DESTINATION ${_share}/tasks)
install(FILES ${PROJECT_SOURCE_DIR}/config/deploy/vehicle.yaml ${PROJECT_SOURCE_DIR}/config/vehicles/sim_rate_1kg.yaml
        DESTINATION ${_share}/vehicles)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/config/missions/ DESTINATION ${_share}/missions FILES_MATCHING PATTERN "*.yaml")
# The autopilots' parameter files (config/ardupilot/*.parm, config/px4/*.params).
foreach(_ap ardupilot px4)
  if(EXISTS ${PROJECT_SOURCE_DIR}/config/${_ap})
    install(DIRECTORY ${PROJECT_SOURCE_DIR}/config/${_ap}/ DESTINATION ${_share}/autopilot/${_ap}
            FILES_MATCHING PATTERN "*.parm" PATTERN "*.params")
  endif()
endforeach()
install(FILES ${PROJECT_SOURCE_DIR}/docs/first-flight.md ${PROJECT_SOURCE_DIR}/docs/deploy.md
        DESTINATION ${CMAKE_INSTALL_DOCDIR})
