# SPDX-License-Identifier: MIT
# ctest check of bench/nbmc_quality (tests/CMakeLists.txt): runs it on the
# shipped example frame and on one particle, parses every QUALITY line and
# checks the figures that are known:
#  - every configuration of the example frame parses, with all keys and
#    numeric values, and its mesh is closed, manifold and oriented; the
#    cleaned variants have no degenerate triangle and none below 1 degree
#    (ssp07, zb05 and yt10: the clean-up's last round repairs the crease
#    that left yt10 6 such triangles at cell r before it);
#  - one particle is a sphere of radius r: the vertices lie at about 1 r from
#    it (marching cubes puts them on the iso-surface, inside by a little
#    between grid edges), none beyond 2 r, one component, and the volume
#    over r^3 is below that of the sphere (4.19) and not far from it.
# Usage: cmake -DPROG=nbmc_quality -DFRAME=double_dam_break_4732.xyz -P check_quality.cmake
foreach(v PROG FRAME)
  if(NOT DEFINED ${v})
    message(FATAL_ERROR "check_quality.cmake: -D${v}= missing")
  endif()
endforeach()

set(keys particles vertices triangles raw_triangles closed manifold oriented degenerate slivers below1deg
    min_angle dihedral_mean dihedral_p99 dist_p50 dist_p99 dist_max beyond2r volume_ratio components seconds)

# Sets ${prefix}_<key> for every key of line; fails when one is missing or not a number.
function(parse_line line prefix)
  foreach(k ${keys})
    if(NOT line MATCHES " ${k}=([-+0-9.eE]+)( |$)")
      message(FATAL_ERROR "no numeric ${k}= in: ${line}")
    endif()
    set(${prefix}_${k} "${CMAKE_MATCH_1}" PARENT_SCOPE)
  endforeach()
endfunction()

function(expect cond msg)
  if(NOT ${cond})
    message(FATAL_ERROR "check_quality: ${msg}")
  endif()
endfunction()

# ---- the example frame
execute_process(COMMAND ${PROG} ${FRAME} --spacing 0.05 --methods ssp07,zb05,yt10 --cells 1
                        --variants raw,clean,smooth --threads 2
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "nbmc_quality failed (${rc}): ${err}\n${out}")
endif()
string(REGEX MATCHALL "QUALITY [^\n]*" lines "${out}")
list(LENGTH lines n)
if(NOT n EQUAL 9)
  message(FATAL_ERROR "expected 9 QUALITY lines, got ${n}:\n${out}")
endif()
set(ok 0)
foreach(line IN LISTS lines)
  if(NOT line MATCHES "status=ok")
    message(FATAL_ERROR "configuration failed: ${line}")
  endif()
  parse_line("${line}" q)
  math(EXPR ok "${ok} + 1")
  if(NOT (q_closed EQUAL 1 AND q_manifold EQUAL 1 AND q_oriented EQUAL 1))
    message(FATAL_ERROR "mesh not closed/manifold/oriented: ${line}")
  endif()
  if(NOT q_particles EQUAL 4732 OR q_triangles LESS 1000 OR q_triangles GREATER q_raw_triangles)
    message(FATAL_ERROR "implausible counts: ${line}")
  endif()
  if(NOT line MATCHES "variant=raw" AND NOT (q_degenerate EQUAL 0 AND q_below1deg EQUAL 0))
    message(FATAL_ERROR "cleaned mesh with degenerate or < 1 degree triangles: ${line}")
  endif()
  if(q_below1deg LESS q_slivers OR q_dist_p50 GREATER q_dist_p99 OR q_dist_p99 GREATER q_dist_max
     OR q_dihedral_mean GREATER q_dihedral_p99 OR q_dist_p50 LESS 0.5 OR q_dist_p50 GREATER 1.5)
    message(FATAL_ERROR "inconsistent figures: ${line}")
  endif()
endforeach()
if(NOT ok EQUAL 9)
  message(FATAL_ERROR "expected 9 measured configurations, got ${ok}")
endif()

# ---- one particle: a sphere of radius r = 1
execute_process(COMMAND ${PROG} --single-particle --spacing 1 --methods ssp07 --cells 0.25 --variants clean
                        --threads 1
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "nbmc_quality --single-particle failed (${rc}): ${err}\n${out}")
endif()
string(REGEX MATCH "QUALITY [^\n]*" line "${out}")
parse_line("${line}" s)
if(s_dist_p50 LESS 0.95 OR s_dist_max GREATER 1.0001 OR NOT s_beyond2r EQUAL 0 OR NOT s_components EQUAL 1
   OR s_volume_ratio GREATER 4.19 OR s_volume_ratio LESS 3.7 OR s_dihedral_mean GREATER 15)
  message(FATAL_ERROR "one particle is not a sphere of radius r: ${line}")
endif()
message(STATUS "check_quality: ${ok} configurations of the example frame and the one-particle sphere passed")
