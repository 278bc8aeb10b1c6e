# Deployment of the full build: sd_notify support, the systemd template unit and the Debian
# packages (docs/DEPLOY.md).
#   - libsystemd (Debian libsystemd-dev) is optional: found -> POISE_HAVE_SYSTEMD, `poise run`
#     tells systemd READY=1 / STOPPING=1 (components/runtime/.../service.h) and the unit is
#     Type=notify; absent -> the unit is Type=exec (systemd only knows the process started).
#   - poise_package(): installs the unit and configures CPack DEB: `poise` (runtime component:
#     the executable, share/poise, the unit) and `poise-dev` (dev component: the cores' headers,
#     static libraries, CMake package, pkg-config file). Runtime dependencies are computed by
#     dpkg-shlibdeps (CPACK_DEBIAN_PACKAGE_SHLIBDEPS).
option(POISE_WITH_SYSTEMD "sd_notify readiness for systemd services when libsystemd is found" ON)
set(POISE_HAVE_SYSTEMD OFF)
if(POISE_WITH_SYSTEMD)
  find_package(PkgConfig QUIET)
  if(PkgConfig_FOUND)
    pkg_check_modules(SYSTEMD QUIET IMPORTED_TARGET libsystemd)
  endif()
  if(SYSTEMD_FOUND)
    set(POISE_HAVE_SYSTEMD ON)
  else()
    message(STATUS "poise: libsystemd not found (Debian libsystemd-dev): no sd_notify, "
                   "poise@.service will be Type=exec")
  endif()
endif()

function(poise_package)
  # The build tree laid out as an installed one for the shipped configuration: build/share/poise is
  # a link to the source tree's config/, so build/bin/poise finds it where an installed poise finds
  # <prefix>/share/poise (poise/runtime/shipped.h: host files copied elsewhere, messages that name
  # shipped files by their real paths).
  file(MAKE_DIRECTORY ${PROJECT_BINARY_DIR}/share)
  file(CREATE_LINK ${PROJECT_SOURCE_DIR}/config ${PROJECT_BINARY_DIR}/share/poise SYMBOLIC)
  if(POISE_HAVE_SYSTEMD)
    set(POISE_UNIT_TYPE notify)
    set(POISE_UNIT_TYPE_NOTE "poise run tells systemd READY=1 once every component has started")
    # poise run sends WATCHDOG=1 every WatchdogSec/2 while every component keeps producing
    # (runtime::ServiceWatchdog); a host where one stops is killed and restarted (Restart=).
    set(POISE_UNIT_WATCHDOG "# fed only while every component produces (a health check, not a timer)\nWatchdogSec=10")
  else()
    set(POISE_UNIT_TYPE exec)
    set(POISE_UNIT_TYPE_NOTE "built without libsystemd: no readiness notification, so Type=exec")
    set(POISE_UNIT_WATCHDOG "# no WatchdogSec=: built without libsystemd, poise run cannot feed a watchdog")
  endif()
  # The unit names the installed executable: its path is filled in at install time, when the
  # prefix is known (/usr in the package, PREFIX with cmake --install --prefix PREFIX).
  set(POISE_UNIT_BINDIR "@POISE_UNIT_BINDIR@")
  configure_file(${PROJECT_SOURCE_DIR}/packaging/poise@.service.in
                 ${PROJECT_BINARY_DIR}/packaging/poise@.service.in @ONLY)
  install(CODE "set(POISE_UNIT_BINDIR \"\${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_BINDIR}\")
    configure_file(\"${PROJECT_BINARY_DIR}/packaging/poise@.service.in\"
                   \"${PROJECT_BINARY_DIR}/packaging/poise@.service\" @ONLY)" COMPONENT runtime)
  install(FILES ${PROJECT_BINARY_DIR}/packaging/poise@.service
          DESTINATION lib/systemd/system COMPONENT runtime)

  set(CPACK_GENERATOR DEB)
  set(CPACK_PACKAGE_NAME poise)
  set(CPACK_PACKAGE_VENDOR "poise developers")
  set(CPACK_PACKAGE_CONTACT "poise developers <poise@localhost>")
  set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
  set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "real-time attitude and pose estimation over DDS")
  set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
  # The packages and cpack's work tree (_CPack_Packages) go to BUILD/packages, wherever cpack is
  # run from (`cpack --config build/CPackConfig.cmake` in the source tree wrote them into it);
  # `cpack -B DIR` still chooses another directory.
  set(CPACK_PACKAGE_DIRECTORY ${CMAKE_BINARY_DIR}/packages)
  set(CPACK_DEB_COMPONENT_INSTALL ON)
  set(CPACK_COMPONENTS_ALL runtime dev dds)
  set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
  set(CPACK_STRIP_FILES ON)
  set(CPACK_DEBIAN_PACKAGE_SECTION science)
  set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
  set(CPACK_DEBIAN_RUNTIME_PACKAGE_NAME poise)
  set(CPACK_DEBIAN_RUNTIME_DESCRIPTION
      "real-time attitude and pose estimation over DDS\n The poise executable, the shipped host, filter, driver and QoS files under\n /usr/share/poise and the systemd template unit poise@.service (poise run\n /etc/poise/INSTANCE.yaml).")
  # adduser: the postinst creates the system user the unit runs as (not a shared library, so
  # dpkg-shlibdeps cannot see it).
  set(CPACK_DEBIAN_RUNTIME_PACKAGE_DEPENDS adduser)
  set(CPACK_DEBIAN_RUNTIME_PACKAGE_CONTROL_EXTRA
      ${PROJECT_SOURCE_DIR}/packaging/postinst ${PROJECT_SOURCE_DIR}/packaging/prerm
      ${PROJECT_SOURCE_DIR}/packaging/postrm)
  set(CPACK_DEBIAN_RUNTIME_PACKAGE_CONTROL_STRICT_PERMISSION ON)
  set(CPACK_DEBIAN_DEV_PACKAGE_NAME poise-dev)
  set(CPACK_DEBIAN_DEV_PACKAGE_SECTION libdevel)
  set(CPACK_DEBIAN_DEV_DESCRIPTION
      "poise estimator cores: headers, static libraries, CMake package\n find_package(poise) gives poise::core, poise::tilt_kf, poise::parallel_kf,\n poise::gauss_newton, poise::selective_ekf, poise::altitude, poise::vehicle;\n pkg-config poise-cores.")
  # The static libraries have no shared-library dependencies for dpkg-shlibdeps to find: what
  # poise-dev needs are the development packages its CMake package looks for
  # (find_dependency(Eigen3), find_dependency(yaml-cpp) in cmake/poiseConfig.cmake.in).
  set(CPACK_DEBIAN_DEV_PACKAGE_DEPENDS "libeigen3-dev (>= 3.3), libyaml-cpp-dev")
  set(CPACK_DEBIAN_DDS_PACKAGE_NAME poise-dds-dev)
  set(CPACK_DEBIAN_DDS_PACKAGE_SECTION libdevel)
  set(CPACK_DEBIAN_DDS_DESCRIPTION
      "poise DDS layer: type support and participant helpers\n find_package(poise) then gives poise::idl (the topic types) and poise::dds\n (participants from poise's QoS profiles, writers/readers, conversions).")
  # As for poise-dev: what the CMake package's find_dependency looks for (Fast DDS, Fast CDR), and
  # the cores poise::dds links.
  set(CPACK_DEBIAN_DDS_PACKAGE_DEPENDS
      "poise-dev (= ${PROJECT_VERSION}), libfastrtps-dev (>= 2.9), libfastcdr-dev, libssl-dev")
  include(CPack)
endfunction()
