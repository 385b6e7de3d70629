# Fallback when no OpenVDB CMake config was found: OpenVDB's own
# FindOpenVDB.cmake (Debian's libopenvdb-dev ships it, next to its
# FindTBB/FindBlosc helpers, but no package config). Put its folder on the
# module path and find OpenVDB through it. PQDC_OPENVDB_MODULE_DIR may name
# the folder; otherwise it is searched under the prefixes CMake knows
# (CMAKE_PREFIX_PATH, /usr, /usr/local...). Shared by the build and the
# installed package.
if(NOT TARGET OpenVDB::openvdb)
  # TBB's own config first, when it has one (Debian's does): OpenVDB's Find
  # module defines only some of its TBB:: targets, after which TBBConfig.cmake
  # refuses to run ("Some (but not all) targets in this export set were
  # already defined"), so a consumer's find_package(TBB) after pqdc failed.
  if(NOT TARGET TBB::tbb)
    find_package(TBB CONFIG QUIET)
  endif()
  find_path(PQDC_OPENVDB_MODULE_DIR FindOpenVDB.cmake
    PATH_SUFFIXES lib/${CMAKE_LIBRARY_ARCHITECTURE}/cmake/OpenVDB lib/cmake/OpenVDB share/cmake/OpenVDB
                  lib64/cmake/OpenVDB
    PATHS /usr /usr/local)
  set(_pqdc_openvdb_error "")
  if(NOT PQDC_OPENVDB_MODULE_DIR)
    set(_pqdc_openvdb_error
        "pqdc: neither an OpenVDB CMake config (OpenVDBConfig.cmake) nor FindOpenVDB.cmake was found; install "
        "libopenvdb-dev (scripts/install-deps.sh), add OpenVDB's prefix to CMAKE_PREFIX_PATH, or set "
        "PQDC_OPENVDB_MODULE_DIR to the folder holding FindOpenVDB.cmake")
  else()
    list(APPEND CMAKE_MODULE_PATH ${PQDC_OPENVDB_MODULE_DIR})
    find_package(OpenVDB COMPONENTS openvdb)
    if(NOT OpenVDB_FOUND)
      set(_pqdc_openvdb_error "pqdc: OpenVDB was not found through ${PQDC_OPENVDB_MODULE_DIR}/FindOpenVDB.cmake")
    endif()
  endif()
  # The installed package's config (PQDC_OPENVDB_REPORT_ONLY) reports the
  # error as "pqdc not found", as find_dependency would; the build stops.
  if(_pqdc_openvdb_error AND PQDC_OPENVDB_REPORT_ONLY)
    set(PQDC_OPENVDB_ERROR "${_pqdc_openvdb_error}")
  elseif(_pqdc_openvdb_error)
    message(FATAL_ERROR "${_pqdc_openvdb_error}")
  endif()
  unset(_pqdc_openvdb_error)
endif()
if(NOT TARGET TBB::tbb)  # a second find_package(pqdc) has it
  find_package(TBB REQUIRED)
endif()
