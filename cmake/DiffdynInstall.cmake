# Install rules and the package config: another project can
#   find_package(diffdyn REQUIRED)
#   target_link_libraries(app PRIVATE diffdyn::physics_models diffdyn::solvers)
# Nothing exported carries a warning or -march flag.
include(CMakePackageConfigHelpers)
set(DIFFDYN_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/diffdyn)

install(TARGETS
    diffdyn_autodiff_ode diffdyn_models diffdyn_physics_models diffdyn_pusher diffdyn_solvers
  EXPORT diffdynTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(EXPORT diffdynTargets NAMESPACE diffdyn:: DESTINATION ${DIFFDYN_CMAKE_DIR})

configure_package_config_file(${CMAKE_CURRENT_LIST_DIR}/diffdynConfig.cmake.in
  ${CMAKE_CURRENT_BINARY_DIR}/diffdynConfig.cmake
  INSTALL_DESTINATION ${DIFFDYN_CMAKE_DIR})
write_basic_package_version_file(${CMAKE_CURRENT_BINARY_DIR}/diffdynConfigVersion.cmake
  COMPATIBILITY SameMinorVersion)
install(FILES
    ${CMAKE_CURRENT_BINARY_DIR}/diffdynConfig.cmake
    ${CMAKE_CURRENT_BINARY_DIR}/diffdynConfigVersion.cmake
  DESTINATION ${DIFFDYN_CMAKE_DIR})
