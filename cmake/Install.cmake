# Install rules and the CMake package (cmake --install BUILD --prefix P):
#   P/lib/libisotouch_*.a                 the libraries (position-independent: a Python
#                                         module or another shared object may link them)
#   P/include/isotouch/<folder>/*.h       the library folders' headers, in the form the
#                                         sources include them ("isotouch/<folder>/<file>.h")
#   P/include/isotouch/isotouch.h         the public API (api/), isotouch/version.h
#   P/bin/isotouch, isotouch-sculpt, isotouch-devemu
#   P/lib/cmake/isotouch/                 find_package(isotouch CONFIG): isotouch::<name>
#   P/lib/pkgconfig/isotouch.pc           for builds without CMake
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

# Library targets, installed and exported as isotouch::<EXPORT_NAME> (the names the build
# tree's aliases use): every static or interface isotouch_* library of the top directory and
# of the folders added (a new library in a folder is exported with no change here); apps/
# and tests/ are not installed.
set(_isotouch_libs "")
get_property(_dirs DIRECTORY ${PROJECT_SOURCE_DIR} PROPERTY SUBDIRECTORIES)
foreach(dir ${PROJECT_SOURCE_DIR} ${_dirs})
  get_filename_component(_folder ${dir} NAME)
  if(_folder STREQUAL "apps" OR _folder STREQUAL "tests")
    continue()
  endif()
  get_property(_targets DIRECTORY ${dir} PROPERTY BUILDSYSTEM_TARGETS)
  foreach(t IN LISTS _targets)
    get_target_property(_type ${t} TYPE)
    if(t MATCHES "^isotouch_" AND _type MATCHES "^(STATIC|INTERFACE)_LIBRARY$")
      list(APPEND _isotouch_libs ${t})
    endif()
  endforeach()
endforeach()
foreach(t IN LISTS _isotouch_libs)
  string(REGEX REPLACE "^isotouch_" "" _name ${t})
  get_target_property(_export_name ${t} EXPORT_NAME)
  if(NOT _export_name)
    set_target_properties(${t} PROPERTIES EXPORT_NAME ${_name})
  endif()
  # Installed, the headers' root is PREFIX/include (in the build tree: ISOTOUCH_INCLUDE_ROOT).
  target_include_directories(${t} INTERFACE $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  get_target_property(_type ${t} TYPE)
  if(_type STREQUAL "STATIC_LIBRARY")
    set_target_properties(${t} PROPERTIES POSITION_INDEPENDENT_CODE ON)
  endif()
endforeach()

install(TARGETS ${_isotouch_libs} EXPORT isotouchTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
foreach(p isotouch isotouch-sculpt isotouch-devemu)
  if(TARGET ${p})
    install(TARGETS ${p} RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
  endif()
endforeach()

# Headers: every *.h of each library folder, under include/isotouch/<folder>/.
foreach(folder core servo sim engine io materials session eval run service bench shaders)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${folder}/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/isotouch/${folder}
    FILES_MATCHING PATTERN "*.h")
endforeach()
install(FILES ${PROJECT_SOURCE_DIR}/api/isotouch.h ${CMAKE_BINARY_DIR}/generated/isotouch/version.h
  DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/isotouch)

# The CMake package: targets, their dependencies found again for the consumer, the version.
set(_cmake_dir ${CMAKE_INSTALL_LIBDIR}/cmake/isotouch)
install(EXPORT isotouchTargets NAMESPACE isotouch:: DESTINATION ${_cmake_dir})
# Debian's FindOpenVDB.cmake (the config file adds it to the module path when OpenVDB is needed).
set(ISOTOUCH_OPENVDB_MODULE_PATH /usr/lib/x86_64-linux-gnu/cmake/OpenVDB)
# Which packages each exported target needs found for a consumer, its isotouch dependencies'
# included, read from the link lists (so the table follows the build): the config file finds
# only those of the components asked for (find_package(isotouch COMPONENTS servo): Threads).
function(isotouch_packages_of target out)
  set(packages "")
  set(seen "")
  set(todo ${target})
  while(todo)
    list(POP_FRONT todo t)
    if(t IN_LIST seen)
      continue()
    endif()
    list(APPEND seen ${t})
    get_target_property(type ${t} TYPE)
    if(type STREQUAL "INTERFACE_LIBRARY")
      get_target_property(links ${t} INTERFACE_LINK_LIBRARIES)
    else()
      get_target_property(links ${t} LINK_LIBRARIES)
    endif()
    foreach(l IN LISTS links)
      if(l MATCHES "^isotouch::")
        get_target_property(real ${l} ALIASED_TARGET)
        list(APPEND todo ${real})
      elseif(l MATCHES "^isotouch_")
        list(APPEND todo ${l})
      elseif(l MATCHES "^(Threads|nlohmann_json|ZLIB|Vulkan|PNG|OpenVDB|assimp)::")
        list(APPEND packages ${CMAKE_MATCH_1})
      elseif(l STREQUAL "PkgConfig::HIDAPI")
        list(APPEND packages hidapi)
      elseif(l MATCHES "^(ITK|itk)")
        list(APPEND packages ITK)
      elseif(l MATCHES "libOpenIGTLink")  # service/: the library's path (Debian's config names no target)
        list(APPEND packages OpenIGTLink)
      endif()
    endforeach()
  endwhile()
  list(REMOVE_DUPLICATES packages)
  set(${out} "${packages}" PARENT_SCOPE)
endfunction()
set(ISOTOUCH_PACKAGE_TABLE "")
set(ISOTOUCH_COMPONENTS "")
foreach(t IN LISTS _isotouch_libs)
  get_target_property(_name ${t} EXPORT_NAME)
  isotouch_packages_of(${t} _packages)
  string(APPEND ISOTOUCH_PACKAGE_TABLE "set(_isotouch_packages_${_name} \"${_packages}\")\n")
  list(APPEND ISOTOUCH_COMPONENTS ${_name})
endforeach()
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/isotouchConfig.cmake.in
  ${CMAKE_BINARY_DIR}/isotouchConfig.cmake INSTALL_DESTINATION ${_cmake_dir})
write_basic_package_version_file(${CMAKE_BINARY_DIR}/isotouchConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/isotouchConfig.cmake ${CMAKE_BINARY_DIR}/isotouchConfigVersion.cmake
  DESTINATION ${_cmake_dir})

# pkg-config: the libraries in link order (each before what it needs). A static library
# exported above but missing here stops the configuration, so the .pc cannot fall behind.
set(ISOTOUCH_PC_LIBS "")
set(_pc_order bench serve run plus_peer igtl_device service eval materials seg_nrrd vdb_io volume_io live record session_gpu session scene io engine
    engine_cpu sim hid servo)
foreach(l ${_pc_order})
  if(TARGET isotouch_${l})
    string(APPEND ISOTOUCH_PC_LIBS " -lisotouch_${l}")
  endif()
endforeach()
foreach(t IN LISTS _isotouch_libs)
  get_target_property(_type ${t} TYPE)
  string(REGEX REPLACE "^isotouch_" "" _name ${t})
  if(_type STREQUAL "STATIC_LIBRARY" AND NOT _name IN_LIST _pc_order)
    message(FATAL_ERROR "cmake/Install.cmake: ${t} is exported but not in isotouch.pc's link order (_pc_order)")
  endif()
endforeach()
# Relocatable: the prefix is found from where the .pc file lies (${pcfiledir}).
file(RELATIVE_PATH ISOTOUCH_PC_UP /p/${CMAKE_INSTALL_LIBDIR}/pkgconfig /p)
configure_file(${PROJECT_SOURCE_DIR}/cmake/isotouch.pc.in ${CMAKE_BINARY_DIR}/isotouch.pc @ONLY)
install(FILES ${CMAKE_BINARY_DIR}/isotouch.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)
