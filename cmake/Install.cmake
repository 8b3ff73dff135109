# `cmake --install`: the public headers, the static libraries, the `tsah` program and a CMake package
# (tsahConfig.cmake, tsahConfigVersion.cmake) exporting tsah::base, tsah::anim, tsah::tsah and, when the CUDA
# runtime was built, the component cuda (tsah::cuda). The public API is listed in docs/api.md. Included at the end of the
# top-level CMakeLists.txt, after every target exists.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(TSAH_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/tsah CACHE STRING "Where tsahConfig.cmake is installed")

# Installed names (namespace tsah::) and in-tree aliases with the same names, so code written against
# the package also builds inside this tree. The older in-tree names (anim::anim, tsah::core) stay.
# Position-independent code: the static libraries can be linked into shared libraries (the Python module).
set_target_properties(tsah_base PROPERTIES EXPORT_NAME base POSITION_INDEPENDENT_CODE ON)
set_target_properties(anim PROPERTIES EXPORT_NAME anim POSITION_INDEPENDENT_CODE ON)
set_target_properties(tsah_core PROPERTIES EXPORT_NAME tsah POSITION_INDEPENDENT_CODE ON)
# The public headers use C++20 (std::span): consumers compile with at least that.
target_compile_features(tsah_base PUBLIC cxx_std_20)
target_compile_features(anim PUBLIC cxx_std_20)
target_compile_features(tsah_core PUBLIC cxx_std_20)
add_library(tsah::anim ALIAS anim)
add_library(tsah::tsah ALIAS tsah_core)
set(TSAH_EXPORTED_TARGETS tsah_base anim tsah_core)
set(TSAH_PUBLIC_INCLUDE_DIRS ${PROJECT_SOURCE_DIR}/libanim/include/ ${PROJECT_SOURCE_DIR}/libtsah/include/)
if(TSAH_HAVE_CUDA)
  set_target_properties(tsah_cuda PROPERTIES EXPORT_NAME cuda)
  list(APPEND TSAH_PUBLIC_INCLUDE_DIRS ${PROJECT_SOURCE_DIR}/cuda_kernels/include/)
endif()

install(TARGETS ${TSAH_EXPORTED_TARGETS} EXPORT tsahTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(TARGETS tsah RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
# Only the include/ folders are public; every other header (src/) stays private to its library.
install(DIRECTORY ${TSAH_PUBLIC_INCLUDE_DIRS} DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
        FILES_MATCHING PATTERN "*.hpp" PATTERN "*.h")
install(EXPORT tsahTargets NAMESPACE tsah:: DESTINATION ${TSAH_INSTALL_CMAKEDIR})
# tsah::cuda in its own file, loaded only for find_package(tsah COMPONENTS cuda): a CPU-only
# consumer never looks for the CUDA toolkit.
if(TSAH_HAVE_CUDA)
  install(TARGETS tsah_cuda EXPORT tsahCudaTargets ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
          INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
  install(EXPORT tsahCudaTargets NAMESPACE tsah:: DESTINATION ${TSAH_INSTALL_CMAKEDIR})
endif()

configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/tsahConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/tsahConfig.cmake
                              INSTALL_DESTINATION ${TSAH_INSTALL_CMAKEDIR})
# 0.x: a minor release may change the API, so only the same minor version is compatible.
write_basic_package_version_file(${PROJECT_BINARY_DIR}/tsahConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/tsahConfig.cmake ${PROJECT_BINARY_DIR}/tsahConfigVersion.cmake
        DESTINATION ${TSAH_INSTALL_CMAKEDIR})
