# Debian's libopenvdb-dev ships no CMake package config, only FindOpenVDB.cmake
# (next to its FindTBB/FindBlosc helpers). Put that folder on the module path
# and find OpenVDB through it. Shared by the build and the installed package.
if(NOT TARGET OpenVDB::openvdb)
  find_path(PQDC_OPENVDB_MODULE_DIR FindOpenVDB.cmake
    PATHS /usr/lib/${CMAKE_LIBRARY_ARCHITECTURE}/cmake/OpenVDB
          /usr/lib/x86_64-linux-gnu/cmake/OpenVDB
          /usr/lib/aarch64-linux-gnu/cmake/OpenVDB
          /usr/local/lib/cmake/OpenVDB
          /usr/lib/cmake/OpenVDB
          /usr/local/share/cmake/OpenVDB
    NO_DEFAULT_PATH)
  if(NOT PQDC_OPENVDB_MODULE_DIR)
    message(FATAL_ERROR "pqdc: FindOpenVDB.cmake not found; install libopenvdb-dev (scripts/install-deps.sh) "
                        "or set PQDC_OPENVDB_MODULE_DIR to the folder holding it")
  endif()
  list(APPEND CMAKE_MODULE_PATH ${PQDC_OPENVDB_MODULE_DIR})
  find_package(OpenVDB REQUIRED COMPONENTS openvdb)
endif()
find_package(TBB REQUIRED)
