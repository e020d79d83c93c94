# The imported targets of the esgm package, made by both of its configurations (the
# workspace's build tree, esgm-shm/cpp/esgmConfig.cmake, and an installed one):
#   esgm::esgm         libesgm_c.so with esgm.h and esgm/esgm.hpp (C++17)
#   esgm::esgm_static  libesgm_c.a, with the system libraries a Rust static library needs
function(esgm_make_targets include_dirs library_dir)
  if(TARGET esgm::esgm)
    return()
  endif()
  set(shared "${library_dir}/libesgm_c.so")
  set(static "${library_dir}/libesgm_c.a")
  if(NOT EXISTS "${shared}")
    message(FATAL_ERROR "esgm: no ${shared}; build it with `cargo build --release -p esgm-c`")
  endif()
  add_library(esgm::esgm SHARED IMPORTED)
  set_target_properties(esgm::esgm PROPERTIES
    IMPORTED_LOCATION "${shared}"
    IMPORTED_SONAME "libesgm_c.so"
    INTERFACE_INCLUDE_DIRECTORIES "${include_dirs}")
  if(EXISTS "${static}")
    find_package(Threads REQUIRED)
    add_library(esgm::esgm_static STATIC IMPORTED)
    set_target_properties(esgm::esgm_static PROPERTIES
      IMPORTED_LOCATION "${static}"
      INTERFACE_INCLUDE_DIRECTORIES "${include_dirs}"
      INTERFACE_LINK_LIBRARIES "Threads::Threads;${CMAKE_DL_LIBS};m;rt;util;gcc_s")
  endif()
endfunction()
