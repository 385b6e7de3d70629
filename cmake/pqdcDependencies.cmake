# The build's dependencies: an OpenVDB CMake config when one is installed,
# otherwise OpenVDB's Find module (pqdcFindOpenVDB.cmake), as the installed
# pqdcConfig.cmake does.
if(NOT TARGET OpenVDB::openvdb)
  find_package(OpenVDB CONFIG QUIET)
endif()
include(${CMAKE_CURRENT_LIST_DIR}/pqdcFindOpenVDB.cmake)
find_package(Threads REQUIRED)
# Header-only, private to the library (its to_json), and the apps' JSON.
find_package(nlohmann_json 3 CONFIG REQUIRED)
# Header-only (XXH_INLINE_ALL), private to the library: the checksums of a
# brick store's files (src/bricks/file_digest.cpp). Nothing to link.
find_path(PQDC_XXHASH_INCLUDE_DIR xxhash.h)
if(NOT PQDC_XXHASH_INCLUDE_DIR)
  message(FATAL_ERROR "pqdc needs xxhash.h (Debian: libxxhash-dev; scripts/install-deps.sh installs it)")
endif()
