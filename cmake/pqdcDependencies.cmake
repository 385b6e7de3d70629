include(${CMAKE_CURRENT_LIST_DIR}/pqdcFindOpenVDB.cmake)
find_package(Threads REQUIRED)
