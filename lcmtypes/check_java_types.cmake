# ctest helper: every mppi_lcm type must load from the jar the way lcm-spy finds it
# (lcm.util.ClassDiscoverer scans the CLASSPATH).
# Usage: cmake -DJAVA=<java> -DCLASSPATH=<lcm.jar:mppi_lcm_types.jar> -DTYPES=<a.lcm;b.lcm> -P this
execute_process(
  COMMAND ${JAVA} -Djava.awt.headless=true -cp ${CLASSPATH} lcm.util.ClassDiscoverer
  OUTPUT_VARIABLE _out ERROR_VARIABLE _err RESULT_VARIABLE _rc)
if(NOT _rc EQUAL 0)
  message(FATAL_ERROR "ClassDiscoverer failed (${_rc}):\n${_err}")
endif()
set(_missing "")
foreach(_file IN LISTS TYPES)
  get_filename_component(_type ${_file} NAME_WE)
  if(NOT _out MATCHES "class mppi_lcm\\.${_type}\n")
    list(APPEND _missing ${_type})
  endif()
endforeach()
list(LENGTH TYPES _n)
if(_missing)
  message(FATAL_ERROR "types missing from the jar: ${_missing}\n${_out}")
endif()
message(STATUS "all ${_n} mppi_lcm types load from the jar")
