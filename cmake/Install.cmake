# Install layout and the DEB package (docs/deploy.md).
#
#   cmake --install BUILD --prefix /usr        # (DESTDIR=... for a staging tree)
#   cpack --config BUILD/CPackConfig.cmake -G DEB
#
# With the prefix /usr (the package's):
#   /usr/sbin/scaled                   the daemon. Debian keeps system daemons
#                                      that users do not run by hand in sbin
#                                      (chronyd, gpsd, sshd); its clients go to bin
#   /usr/bin/scalectl, field-log       clients any user in the group scaled runs
#   /etc/scaled/scaled.toml, priors.toml   configuration (conffiles)
#   /lib/systemd/system/scaled.{service,socket}   pkg-config systemd's systemdsystemunitdir
#   /usr/lib/sysusers.d/scaled.conf    the user and group scaled (systemd/scaled.sysusers)
#   /usr/share/doc/scaled/             README.md and docs/*.md
# Another prefix P gives P/etc/scaled, P/lib/systemd/system and P/lib/sysusers.d
# (systemd searches /usr/local/lib/... too).
#
# /etc, the unit and sysusers directories and the paths inside the units depend
# on the prefix *at install time* (`cmake --install --prefix`, CPack's /usr), so
# they are worked out by the install script, not here: a tree configured with
# the default /usr/local still installs and packages a consistent /usr layout.
# The daemon's own default for its configuration file is compiled in from the
# configure-time prefix; the unit passes --config explicitly, and DEB builds
# should configure with -DCMAKE_INSTALL_PREFIX=/usr anyway.

# ---- binaries -----------------------------------------------------------------
install(TARGETS scaled RUNTIME DESTINATION ${CMAKE_INSTALL_SBINDIR})
install(TARGETS scalectl RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
# The field-log reader is written in parallel; installed once it exists.
if(TARGET field-log)
  install(TARGETS field-log RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
endif()

# ---- documentation ------------------------------------------------------------
install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR}
  FILES_MATCHING PATTERN "*.md")

# ---- configuration, units, sysusers (paths from the install-time prefix) ------
# Configuration files present in the source tree (config/scaled.toml is written
# in parallel; priors-redkitchen.toml is a dataset's, not the default).
set(SCALED_CONFIG_FILES "")
foreach(name scaled.toml priors.toml)
  if(EXISTS ${PROJECT_SOURCE_DIR}/config/${name})
    list(APPEND SCALED_CONFIG_FILES ${PROJECT_SOURCE_DIR}/config/${name})
  endif()
endforeach()

# pkg-config's systemd directories, used when the install prefix is /usr.
set(SCALED_SYSTEMD_UNIT_DIR "/lib/systemd/system")
set(SCALED_SYSUSERS_DIR "/usr/lib/sysusers.d")
find_package(PkgConfig QUIET)
if(PKG_CONFIG_FOUND)
  pkg_get_variable(_scaled_unitdir systemd systemdsystemunitdir)
  pkg_get_variable(_scaled_sysusersdir systemd sysusersdir)
  if(_scaled_unitdir)
    set(SCALED_SYSTEMD_UNIT_DIR ${_scaled_unitdir})
  endif()
  if(_scaled_sysusersdir)
    set(SCALED_SYSUSERS_DIR ${_scaled_sysusersdir})
  endif()
endif()

# The units configured with the configure-time paths, for reading and for
# tests/cli/systemd_units_cli.sh (the installed ones are configured again below).
set(SCALED_UNITS scaled.service scaled.socket)
foreach(unit ${SCALED_UNITS})
  configure_file(${PROJECT_SOURCE_DIR}/systemd/${unit}.in
                 ${PROJECT_BINARY_DIR}/systemd/${unit} @ONLY)
endforeach()

set(_scaled_install_code [=[
  # scaled: directories from the install-time prefix (cmake/Install.cmake).
  if(CMAKE_INSTALL_PREFIX STREQUAL "/usr")
    set(_scaled_etc "/etc")
    set(_scaled_unitdir "@SCALED_SYSTEMD_UNIT_DIR@")
    set(_scaled_sysusersdir "@SCALED_SYSUSERS_DIR@")
  else()
    set(_scaled_etc "${CMAKE_INSTALL_PREFIX}/etc")
    set(_scaled_unitdir "${CMAKE_INSTALL_PREFIX}/lib/systemd/system")
    set(_scaled_sysusersdir "${CMAKE_INSTALL_PREFIX}/lib/sysusers.d")
  endif()
  set(_scaled_config_files "@SCALED_CONFIG_FILES@")
  if(_scaled_config_files)
    file(INSTALL DESTINATION "${_scaled_etc}/scaled" TYPE FILE PERMISSIONS
         OWNER_READ OWNER_WRITE GROUP_READ WORLD_READ FILES ${_scaled_config_files})
  endif()
  # The names the unit templates use, for this prefix.
  set(CMAKE_INSTALL_FULL_SBINDIR "${CMAKE_INSTALL_PREFIX}/@CMAKE_INSTALL_SBINDIR@")
  set(CMAKE_INSTALL_FULL_BINDIR "${CMAKE_INSTALL_PREFIX}/@CMAKE_INSTALL_BINDIR@")
  set(CMAKE_INSTALL_FULL_DOCDIR "${CMAKE_INSTALL_PREFIX}/@CMAKE_INSTALL_DOCDIR@")
  set(CMAKE_INSTALL_FULL_SYSCONFDIR "${_scaled_etc}")
  set(_scaled_units "")
  foreach(unit @SCALED_UNITS@)
    file(READ "@PROJECT_SOURCE_DIR@/systemd/${unit}.in" _scaled_text)
    string(CONFIGURE "${_scaled_text}" _scaled_text @ONLY)
    file(WRITE "@PROJECT_BINARY_DIR@/systemd-install/${unit}" "${_scaled_text}")
    list(APPEND _scaled_units "@PROJECT_BINARY_DIR@/systemd-install/${unit}")
  endforeach()
  file(INSTALL DESTINATION "${_scaled_unitdir}" TYPE FILE PERMISSIONS
       OWNER_READ OWNER_WRITE GROUP_READ WORLD_READ FILES ${_scaled_units})
  file(INSTALL DESTINATION "${_scaled_sysusersdir}" TYPE FILE PERMISSIONS
       OWNER_READ OWNER_WRITE GROUP_READ WORLD_READ
       FILES "@PROJECT_SOURCE_DIR@/systemd/scaled.sysusers" RENAME scaled.conf)
]=])
string(CONFIGURE "${_scaled_install_code}" _scaled_install_code @ONLY)
install(CODE "${_scaled_install_code}")

if(NOT CMAKE_INSTALL_PREFIX STREQUAL "/usr")
  message(STATUS "scaled: CMAKE_INSTALL_PREFIX is ${CMAKE_INSTALL_PREFIX}; the daemon's "
                 "default configuration file is ${CMAKE_INSTALL_FULL_SYSCONFDIR}/scaled/"
                 "scaled.toml (DEB builds: -DCMAKE_INSTALL_PREFIX=/usr)")
endif()

# ---- the DEB package ------------------------------------------------------------
set(CPACK_PACKAGE_NAME scaled)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_VENDOR "scaled")
set(CPACK_PACKAGE_CONTACT "scaled maintainers <scaled-maintainers@example.invalid>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "metric scale for monocular SLAM from everyday objects")
string(CONCAT CPACK_PACKAGE_DESCRIPTION
  "scaled tracks a camera with monocular EKF SLAM, detects everyday objects with a YOLO "
  "detector and estimates the metric scale of the map (metres per SLAM unit) as a Bayesian "
  "posterior from the objects' known height distributions. Other programs query the "
  "scale over a UNIX socket (scalectl). Runs under systemd with a hardened unit.")
set(CPACK_GENERATOR DEB)
# Install with DESTDIR and the prefix /usr, so the install script above sees
# /usr and picks /etc and the system unit directories.
set(CPACK_SET_DESTDIR ON)
set(CPACK_INSTALL_PREFIX /usr)
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_STRIP_FILES ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_NAME scaled)
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "${CPACK_PACKAGE_CONTACT}")
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
set(CPACK_DEBIAN_PACKAGE_HOMEPAGE "https://example.invalid/scaled")
# Library dependencies from dpkg-shlibdeps (dpkg-dev) on the binaries, plus
# what the maintainer scripts and units use.
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_DEPENDS "systemd (>= 247), init-system-helpers (>= 1.54)")
# Maintainer scripts and the conffiles list (control files, mode 0755/0644).
set(_scaled_deb_dir ${PROJECT_BINARY_DIR}/deb)
set(_scaled_conffiles "")
foreach(file ${SCALED_CONFIG_FILES})
  get_filename_component(name ${file} NAME)
  string(APPEND _scaled_conffiles "/etc/scaled/${name}\n")
endforeach()
file(WRITE ${_scaled_deb_dir}/conffiles "${_scaled_conffiles}")
foreach(script postinst prerm postrm)
  configure_file(${PROJECT_SOURCE_DIR}/cmake/deb/${script} ${_scaled_deb_dir}/${script}
                 @ONLY FILE_PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ
                 GROUP_EXECUTE WORLD_READ WORLD_EXECUTE)
endforeach()
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
    ${_scaled_deb_dir}/conffiles ${_scaled_deb_dir}/postinst ${_scaled_deb_dir}/prerm
    ${_scaled_deb_dir}/postrm)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
include(CPack)
