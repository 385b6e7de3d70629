# Fallback when no OpenVDB CMake config was found: OpenVDB's own
# FindOpenVDB.cmake (Debian's libopenvdb-dev ships it, next to its
# FindTBB/FindBlosc helpers, but no package config). Put its folder on the
# module path and find OpenVDB through it. PQDC_OPENVDB_MODULE_DIR may name
# the folder; otherwise it is searched under the prefixes CMake knows
# (CMAKE_PREFIX_PATH, /usr, /usr/local...). Shared by the build and the
# installed package.
if(NOT TARGET OpenVDB::openvdb)
  find_path(PQDC_OPENVDB_MODULE_DIR FindOpenVDB.cmake
    PATH_SUFFIXES lib/${CMAKE_LIBRARY_ARCHITECTURE}/cmake/OpenVDB lib/cmake/OpenVDB share/cmake/OpenVDB
                  lib64/cmake/OpenVDB
    PATHS /usr /usr/local)
  if(NOT PQDC_OPENVDB_MODULE_DIR)
    message(FATAL_ERROR "pqdc: neither an OpenVDB CMake config (OpenVDBConfig.cmake) nor FindOpenVDB.cmake was "
                        "found; install libopenvdb-dev (scripts/install-deps.sh), add OpenVDB's prefix to "
                        "CMAKE_PREFIX_PATH, or set PQDC_OPENVDB_MODULE_DIR to the folder holding FindOpenVDB.cmake")
  endif()
  list(APPEND CMAKE_MODULE_PATH ${PQDC_OPENVDB_MODULE_DIR})
  find_package(OpenVDB REQUIRED COMPONENTS openvdb)
endif()
find_package(TBB REQUIRED)
