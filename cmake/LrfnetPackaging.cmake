# Debian packages (CPack DEB, Debian 12), one per component:
#   lrfnet-tracker  (component tracker)  the gateway program, its unit lrfnet-tracker@.service
#   lrfnetd         (component daemon)   the daemon, its unit lrfnetd.service
#   lrfnet          (component tools)    the tools and the shipped scenarios
# A tracker-only cross build (cmake/aarch64-linux-gnu.cmake) makes lrfnet-tracker for arm64.
# `cpack` in a build tree writes the packages; scripts/package.sh builds the trees and runs it.
# Depends: from dpkg-shlibdeps (against the target architecture's multiarch libraries).
include(GNUInstallDirs)

set(LRFNET_SYSTEMD_UNIT_DIR /lib/systemd/system)
set(LRFNET_SYSUSERS_DIR /usr/lib/sysusers.d)
set(LRFNET_CONFIG_DIR /etc/lrfnet)
set(LRFNET_DEB_DIR ${PROJECT_SOURCE_DIR}/cmake/deb)

# Man pages from --help (help2man). Without help2man the packages have none and the package test
# says so.
find_program(LRFNET_HELP2MAN help2man)
function(lrfnet_man_page target component description)
  if(NOT LRFNET_HELP2MAN OR NOT TARGET ${target})
    return()
  endif()
  set(page ${CMAKE_BINARY_DIR}/man/${target}.1)
  set(program $<TARGET_FILE:${target}>)
  if(CMAKE_CROSSCOMPILING AND CMAKE_CROSSCOMPILING_EMULATOR)
    # help2man runs the program: through the emulator, under the program's own name.
    list(JOIN CMAKE_CROSSCOMPILING_EMULATOR " " emulator)
    file(GENERATE OUTPUT ${CMAKE_BINARY_DIR}/man/run/${target}
         CONTENT "#!/bin/sh\nexec ${emulator} $<TARGET_FILE:${target}> \"$@\"\n"
         FILE_PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE)
    set(program ${CMAKE_BINARY_DIR}/man/run/${target})
  endif()
  add_custom_command(
    OUTPUT ${page}.gz
    COMMAND ${LRFNET_HELP2MAN} --no-info --no-discard-stderr --section 1 --source lrfnet
            --version-string ${PROJECT_VERSION} --name ${description} --output ${page} ${program}
    COMMAND gzip -9nf ${page}
    DEPENDS ${target}
    COMMENT "man page of ${target}"
    VERBATIM)
  add_custom_target(${target}_man_page ALL DEPENDS ${page}.gz)
  install(FILES ${page}.gz DESTINATION ${CMAKE_INSTALL_MANDIR}/man1 COMPONENT ${component})
endfunction()

# ---- lrfnet-tracker
lrfnet_man_page(lrfnet-tracker tracker "tracker of one SICK laser range finder: CoLa-B in, tracks over UDP out")
install(FILES ${PROJECT_SOURCE_DIR}/firmware_tracker/config/lrfnet-tracker.yaml
        DESTINATION ${LRFNET_CONFIG_DIR} COMPONENT tracker)
install(FILES ${PROJECT_SOURCE_DIR}/firmware_tracker/systemd/lrfnet-tracker@.service
        DESTINATION ${LRFNET_SYSTEMD_UNIT_DIR} COMPONENT tracker)
install(FILES ${PROJECT_SOURCE_DIR}/firmware_tracker/systemd/lrfnet-tracker.sysusers.conf
        DESTINATION ${LRFNET_SYSUSERS_DIR} RENAME lrfnet-tracker.conf COMPONENT tracker)
set(lrfnet_components tracker)

if(TARGET lrfnetd)
  # ---- lrfnetd
  lrfnet_man_page(lrfnetd daemon "daemon of the lrfnet sensor network: collect, calibrate, fuse")
  install(FILES ${PROJECT_SOURCE_DIR}/central_daemon/config/lrfnetd.yaml
          DESTINATION ${LRFNET_CONFIG_DIR} COMPONENT daemon)
  install(FILES ${PROJECT_SOURCE_DIR}/central_daemon/systemd/lrfnetd.service
          DESTINATION ${LRFNET_SYSTEMD_UNIT_DIR} COMPONENT daemon)
  install(FILES ${PROJECT_SOURCE_DIR}/central_daemon/systemd/lrfnetd.sysusers.conf
          DESTINATION ${LRFNET_SYSUSERS_DIR} RENAME lrfnetd.conf COMPONENT daemon)
  list(APPEND lrfnet_components daemon)
endif()
if(TARGET lrfnet)
  # ---- lrfnet (tools; the scenarios are installed by tools/sim)
  lrfnet_man_page(lrfnet tools "lrfnet tools: simulator, device emulator, dump, replay, calibrate, eval")
  list(APPEND lrfnet_components tools)
endif()

# ---- CPack
if(CMAKE_CROSSCOMPILING AND CMAKE_SYSTEM_PROCESSOR MATCHES "^(aarch64|arm64)$")
  set(lrfnet_deb_arch arm64)
else()
  find_program(LRFNET_DPKG dpkg)
  if(LRFNET_DPKG)
    execute_process(COMMAND ${LRFNET_DPKG} --print-architecture OUTPUT_VARIABLE lrfnet_deb_arch
                    OUTPUT_STRIP_TRAILING_WHITESPACE)
  else()
    set(lrfnet_deb_arch amd64)
  endif()
endif()

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME lrfnet)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_CONTACT "lrfnet maintainers <maintainers@lrfnet.invalid>")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_PACKAGE_DIRECTORY ${CMAKE_BINARY_DIR}/cpack)
set(CPACK_COMPONENTS_ALL ${lrfnet_components})
set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE ${lrfnet_deb_arch})
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
set(CPACK_DEBIAN_COMPRESSION_TYPE xz)
# Debian strips its binaries (debug info would make lrfnetd 180 MB instead of a few).
set(CPACK_STRIP_FILES ON)

set(CPACK_DEBIAN_TRACKER_PACKAGE_NAME lrfnet-tracker)
set(CPACK_DEBIAN_TRACKER_PACKAGE_RECOMMENDS chrony)
set(CPACK_COMPONENT_TRACKER_DESCRIPTION
    "tracker of one SICK laser range finder for the lrfnet sensor network
lrfnet-tracker runs on the gateway next to a SICK LMS1xx/LMS5xx/TiM5xx/TiM7xx scanner: it reads
the scans over CoLa-B (TCP), learns the background, tracks the moving objects and sends track
frames, background snapshots and health as datagrams over UDP to lrfnetd.

The service lrfnet-tracker@ID.service runs one tracker per scanner (instance = sensor id) with
/etc/lrfnet/tracker-ID.yaml. Scan times come from the gateway's clock: keep it synchronised to
the PC running lrfnetd (chrony).")
set(CPACK_DEBIAN_TRACKER_PACKAGE_CONTROL_EXTRA
    "${LRFNET_DEB_DIR}/lrfnet-tracker/conffiles;${LRFNET_DEB_DIR}/lrfnet-tracker/postinst;${LRFNET_DEB_DIR}/lrfnet-tracker/prerm;${LRFNET_DEB_DIR}/lrfnet-tracker/postrm")

set(CPACK_DEBIAN_DAEMON_PACKAGE_NAME lrfnetd)
set(CPACK_DEBIAN_DAEMON_PACKAGE_RECOMMENDS chrony)
set(CPACK_DEBIAN_DAEMON_PACKAGE_SUGGESTS lrfnet)
set(CPACK_COMPONENT_DAEMON_DESCRIPTION
    "daemon of the lrfnet laser range finder network: collect, calibrate, fuse
lrfnetd collects the track datagrams of every lrfnet-tracker on the LAN, records them, finds
every scanner's pose from people walking through the scene (Quenzel et al.) and fuses all tracks
in one world frame (JSON over UDP, JSON lines, a live view in the browser).

The service lrfnetd.service reads /etc/lrfnet/lrfnetd.yaml and writes into /var/lib/lrfnet.")
set(CPACK_DEBIAN_DAEMON_PACKAGE_CONTROL_EXTRA
    "${LRFNET_DEB_DIR}/lrfnetd/conffiles;${LRFNET_DEB_DIR}/lrfnetd/postinst;${LRFNET_DEB_DIR}/lrfnetd/prerm;${LRFNET_DEB_DIR}/lrfnetd/postrm")

set(CPACK_DEBIAN_TOOLS_PACKAGE_NAME lrfnet)
set(CPACK_COMPONENT_TOOLS_DESCRIPTION
    "tools of the lrfnet laser range finder network
lrfnet sim (ray-cast simulator of SICK scanners with ground truth, shipped scenarios in
/usr/share/lrfnet/scenarios), emulate (a SICK device on TCP from a capture or a scenario), dump
(scans and datagrams as JSON lines), replay, calibrate and eval.")

include(CPack)
