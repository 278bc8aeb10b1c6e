# Install rules and the exported CMake package of the estimator cores:
#   find_package(poise) -> poise::core, poise::tilt_kf, poise::parallel_kf, poise::gauss_newton,
#   poise::selective_ekf, poise::altitude, poise::vehicle (static libraries, headers, version file),
# plus a pkg-config file (poise-cores.pc). The DDS side installs the `poise` executable and the
# shipped configuration under share/poise.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

# The cores, in link order (a library before what it needs) and their source directories (layers 0
# and 1 of docs/DEVELOPING.md: components/core and components/estimators/*).
set(POISE_CORE_TARGETS poise_selective_ekf poise_gauss_newton poise_parallel_kf poise_altitude
    poise_tilt_kf poise_vehicle poise_core)
set(POISE_CORE_DIRS components/core components/estimators/parallel_kf components/estimators/gauss_newton
    components/estimators/selective_ekf components/estimators/altitude components/estimators/vehicle)

function(poise_install_cores)
  foreach(t IN LISTS POISE_CORE_TARGETS)
    string(REPLACE "poise_" "" export_name ${t})
    set_target_properties(${t} PROPERTIES EXPORT_NAME ${export_name})
    add_library(poise::${export_name} ALIAS ${t})
  endforeach()
  install(TARGETS ${POISE_CORE_TARGETS} EXPORT poiseTargets
          ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT dev
          INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
  foreach(d IN LISTS POISE_CORE_DIRS)
    install(DIRECTORY ${PROJECT_SOURCE_DIR}/${d}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
            COMPONENT dev)
  endforeach()
  set(cmake_dir ${CMAKE_INSTALL_LIBDIR}/cmake/poise)
  install(EXPORT poiseTargets NAMESPACE poise:: DESTINATION ${cmake_dir} COMPONENT dev)
  configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/poiseConfig.cmake.in
                                ${PROJECT_BINARY_DIR}/poiseConfig.cmake INSTALL_DESTINATION ${cmake_dir})
  write_basic_package_version_file(${PROJECT_BINARY_DIR}/poiseConfigVersion.cmake
                                   VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
  install(FILES ${PROJECT_BINARY_DIR}/poiseConfig.cmake ${PROJECT_BINARY_DIR}/poiseConfigVersion.cmake
          DESTINATION ${cmake_dir} COMPONENT dev)
  set(libs "")
  foreach(t IN LISTS POISE_CORE_TARGETS)
    string(APPEND libs " -l${t}")
  endforeach()
  set(POISE_PC_LIBS "${libs}")
  # The prefix relative to the .pc file, so the same file serves any install prefix (cmake
  # --install --prefix P, the /usr of the Debian package).
  file(RELATIVE_PATH POISE_PC_PREFIX /p/${CMAKE_INSTALL_LIBDIR}/pkgconfig /p)
  string(REGEX REPLACE "/$" "" POISE_PC_PREFIX "${POISE_PC_PREFIX}")
  configure_file(${PROJECT_SOURCE_DIR}/cmake/poise-cores.pc.in ${PROJECT_BINARY_DIR}/poise-cores.pc @ONLY)
  install(FILES ${PROJECT_BINARY_DIR}/poise-cores.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig COMPONENT dev)
endfunction()

# The DDS side of a full build, exported beside the cores (package poise-dds-dev): poise::idl
# (the fastddsgen type support of idl/*.idl; headers in include/poise/msg) and poise::dds
# (participants from the XML profiles, writers/readers, conversions; include/poise/dds). The
# config file loads them when present (poiseDdsTargets.cmake) after finding Fast DDS and Fast CDR
# (and OpenSSL). A target poise_dds or poise_idl links publicly must be exported too (or be an
# imported target that cmake/poiseConfig.cmake.in finds), else configuring fails at install(EXPORT).
function(poise_install_dds)
  set_target_properties(poise_idl PROPERTIES EXPORT_NAME idl)
  set_target_properties(poise_dds PROPERTIES EXPORT_NAME dds)
  add_library(poise::idl ALIAS poise_idl)
  add_library(poise::dds ALIAS poise_dds)
  install(TARGETS poise_idl poise_dds EXPORT poiseDdsTargets
          ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT dds
          INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
  install(DIRECTORY ${PROJECT_BINARY_DIR}/gen/poise/msg/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/poise/msg
          COMPONENT dds FILES_MATCHING PATTERN "*.h")
  install(DIRECTORY ${PROJECT_BINARY_DIR}/gen/poise/ros2/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/poise/ros2
          COMPONENT dds FILES_MATCHING PATTERN "*.h")
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/components/dds/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
          COMPONENT dds)
  install(EXPORT poiseDdsTargets NAMESPACE poise:: DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/poise
          COMPONENT dds)
endfunction()
