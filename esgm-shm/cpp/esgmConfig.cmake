# The esgm package in a checkout of the workspace (find_package(esgm CONFIG) with
# PATHS <checkout>/esgm-shm/cpp): the headers in the source tree, the library where
# cargo builds it. Which build:
#   ESGM_LIBRARY_DIR    a directory holding libesgm_c.so (and .a), if set;
#   else the release build, <target>/release, else the debug one, <target>/debug,
#   where <target> is $CARGO_TARGET_DIR or <checkout>/target;
#   else it runs `cargo build --release -p esgm-c` once, here, and takes that.
# An installed package (cmake --install of esgm-shm/cpp) has its own configuration.
cmake_minimum_required(VERSION 3.16)
get_filename_component(_esgm_checkout "${CMAKE_CURRENT_LIST_DIR}/../.." ABSOLUTE)
set(esgm_VERSION 0.1.0)

if(NOT ESGM_LIBRARY_DIR)
  if(DEFINED ENV{CARGO_TARGET_DIR})
    set(_esgm_target "$ENV{CARGO_TARGET_DIR}")
  else()
    set(_esgm_target "${_esgm_checkout}/target")
  endif()
  foreach(_esgm_profile release debug)
    if(EXISTS "${_esgm_target}/${_esgm_profile}/libesgm_c.so")
      set(ESGM_LIBRARY_DIR "${_esgm_target}/${_esgm_profile}")
      break()
    endif()
  endforeach()
  if(NOT ESGM_LIBRARY_DIR)
    find_program(_esgm_cargo cargo REQUIRED)
    message(STATUS "esgm: building libesgm_c (cargo build --release -p esgm-c)")
    execute_process(
      COMMAND "${_esgm_cargo}" build --release -p esgm-c
      WORKING_DIRECTORY "${_esgm_checkout}"
      RESULT_VARIABLE _esgm_built)
    if(NOT _esgm_built EQUAL 0)
      message(FATAL_ERROR "esgm: `cargo build --release -p esgm-c` failed in ${_esgm_checkout}")
    endif()
    set(ESGM_LIBRARY_DIR "${_esgm_target}/release")
  endif()
endif()

include("${CMAKE_CURRENT_LIST_DIR}/cmake/esgmTargets.cmake")
esgm_make_targets("${_esgm_checkout}/esgm-shm/c/include;${_esgm_checkout}/esgm-shm/cpp/include"
                  "${ESGM_LIBRARY_DIR}")
message(STATUS "esgm: the workspace's library in ${ESGM_LIBRARY_DIR}")
