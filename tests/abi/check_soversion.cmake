# SPDX-License-Identifier: MIT
# cmake -DLIB=libnbmc.so -DHEADER=nbmc.h -DREADELF=readelf [-DTARGET_SOVERSION=N] -P check_soversion.cmake
#
# The SONAME of the built library must be libnbmc.so.<NBMC_VERSION_MAJOR>, so
# that a major version bump (an ABI break) gives a new file name and old
# binaries keep loading the old library.
foreach(v LIB HEADER READELF)
  if(NOT ${v})
    message(FATAL_ERROR "check_soversion.cmake: -D${v}=... is required")
  endif()
endforeach()

file(STRINGS ${HEADER} major_line REGEX "^#define NBMC_VERSION_MAJOR +[0-9]+")
if(NOT major_line MATCHES "NBMC_VERSION_MAJOR +([0-9]+)")
  message(FATAL_ERROR "NBMC_VERSION_MAJOR not found in ${HEADER}")
endif()
set(major ${CMAKE_MATCH_1})

if(DEFINED TARGET_SOVERSION AND NOT TARGET_SOVERSION STREQUAL "${major}")
  message(FATAL_ERROR "target property SOVERSION is '${TARGET_SOVERSION}', NBMC_VERSION_MAJOR is ${major}")
endif()

execute_process(COMMAND ${READELF} -d ${LIB} OUTPUT_VARIABLE out ERROR_VARIABLE err RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${READELF} -d ${LIB} failed (${rc}): ${err}")
endif()
if(NOT out MATCHES "\\(SONAME\\)[^\n]*\\[([^]]+)\\]")
  message(FATAL_ERROR "${LIB} has no SONAME")
endif()
set(soname ${CMAKE_MATCH_1})
if(NOT soname STREQUAL "libnbmc.so.${major}")
  message(FATAL_ERROR "SONAME is ${soname}, expected libnbmc.so.${major} (NBMC_VERSION_MAJOR ${major})")
endif()
message(STATUS "SONAME ${soname} matches NBMC_VERSION_MAJOR ${major}")
