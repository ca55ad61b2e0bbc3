# Install rules, the exported CMake package and the Debian package (CPack). Included at the end of the top-level
# CMakeLists.txt, once every module's target exists.
#
#   cmake --install build --prefix /opt/octocut      # libraries, headers, package config, bin/octocut
#   cd build && cpack -G DEB                         # octocut_<version>_<arch>.deb, installing under /usr
#
# A consumer: find_package(octocut CONFIG REQUIRED) and target_link_libraries(app PRIVATE octocut::engine).
include(CMakePackageConfigHelpers)

set(OCTOCUT_INSTALL_CMAKEDIR "${CMAKE_INSTALL_LIBDIR}/cmake/octocut"
    CACHE STRING "Where the octocut package config goes, relative to the prefix")

# The exported names: octocut::sim, octocut::cutting, octocut::engine (as the in-tree aliases), octocut::cholmod
# (the CHOLMOD libraries found at configure time; the static libraries link it privately, so the export names it
# and it must travel with them) and octocut::octocut, the command-line tool.
set_target_properties(octocut_sim PROPERTIES EXPORT_NAME sim)
set_target_properties(octocut_cutting PROPERTIES EXPORT_NAME cutting)
set_target_properties(octocut_engine PROPERTIES EXPORT_NAME engine)
set_target_properties(octocut_cholmod PROPERTIES EXPORT_NAME cholmod)

# A sanitizer build's static libraries need the sanitizer runtimes at the consumer's link.
if(OCTOCUT_SANITIZE)
  target_link_options(octocut_sim INTERFACE $<INSTALL_INTERFACE:-fsanitize=address,undefined>)
endif()

install(TARGETS octocut_sim octocut_cutting octocut_engine octocut_cholmod octocut
        EXPORT octocutTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
        RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})

# Public headers: whole trees (files move between subfolders; no list to keep), and the generated version.hpp.
foreach(module sim cutting engine)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${module}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
          FILES_MATCHING PATTERN "*.hpp" PATTERN "*.h")
endforeach()
install(FILES ${OCTOCUT_GENERATED_INCLUDE_DIR}/octocut/version.hpp DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/octocut)

install(EXPORT octocutTargets NAMESPACE octocut:: DESTINATION ${OCTOCUT_INSTALL_CMAKEDIR})
configure_package_config_file(${CMAKE_CURRENT_LIST_DIR}/octocutConfig.cmake.in
                              ${CMAKE_CURRENT_BINARY_DIR}/octocutConfig.cmake
                              INSTALL_DESTINATION ${OCTOCUT_INSTALL_CMAKEDIR})
# 0.x: a new minor version may break the API, so only the same major.minor is compatible.
write_basic_package_version_file(${CMAKE_CURRENT_BINARY_DIR}/octocutConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/octocutConfig.cmake ${CMAKE_CURRENT_BINARY_DIR}/octocutConfigVersion.cmake
        DESTINATION ${OCTOCUT_INSTALL_CMAKEDIR})

# ---- Debian package ---------------------------------------------------------------------------------------------------
if(PROJECT_IS_TOP_LEVEL)
  set(CPACK_GENERATOR DEB)
  set(CPACK_PACKAGE_NAME octocut)
  set(CPACK_PACKAGE_VENDOR "octocut")
  set(CPACK_PACKAGE_CONTACT "octocut developers")
  set(CPACK_DEBIAN_PACKAGE_MAINTAINER "octocut developers")
  set(CPACK_PACKAGE_DESCRIPTION_SUMMARY
      "Surgical cutting simulation on an adaptive octree: C++ libraries, headers, CMake package and CLI")
  set(CPACK_PACKAGE_DESCRIPTION
      "Static libraries octocut::sim, octocut::cutting and octocut::engine with their headers and CMake package \
(find_package(octocut CONFIG)), and the octocut command-line tool.")
  set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)  # octocut_<version>_<arch>.deb
  set(CPACK_DEBIAN_PACKAGE_SECTION devel)
  # What a consumer's find_package(octocut) and link need (scripts/setup names the same packages); their runtime
  # libraries come with them, and so cover bin/octocut.
  set(_octocut_deb_depends
      cmake libeigen3-dev libcgal-dev libgmp-dev libmpfr-dev libsuitesparse-dev libtbb-dev libassimp-dev
      libpng-dev nlohmann-json3-dev pkg-config libbullet-dev)
  if(OCTOCUT_HAVE_EGL)
    list(APPEND _octocut_deb_depends pkg-config libepoxy-dev)
    set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "libegl-mesa0, libgl1-mesa-dri, libopenblas0-pthread")
  else()
    set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "libopenblas0-pthread")
  endif()
  # bin/octocut's viewer (`octocut view`) loads GLFW and stb at run time (Dear ImGui is linked statically).
  if(OCTOCUT_HAVE_VIEWER)
    list(APPEND _octocut_deb_depends libglfw3 libstb0)
  endif()
  list(JOIN _octocut_deb_depends ", " CPACK_DEBIAN_PACKAGE_DEPENDS)
  include(CPack)
endif()
