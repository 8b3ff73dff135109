# tsah_link_private(LIB DEP...): DEP is a private dependency of the static library LIB.
#
# Inside this build LIB links the target DEP. A static library's private dependencies still reach
# whoever links it, so the installed package names them too, but as the SHARED LIBRARY FILES the
# targets point to, resolved to the versioned files of Debian's runtime packages
# (/usr/lib/x86_64-linux-gnu/libassimp.so.5.2.4 of libassimp5, not assimp::assimp of libassimp-dev):
# a program built against the installed tsah needs neither the dependencies' development packages
# nor their CMake configs. Header-only dependencies (no library file) are left out of the package.
function(tsah_link_private lib)
  foreach(dep IN LISTS ARGN)
    target_link_libraries(${lib} PRIVATE $<BUILD_INTERFACE:${dep}>)
    set(files "")
    get_target_property(type ${dep} TYPE)
    if(type STREQUAL "INTERFACE_LIBRARY")
      # pkg-config targets (PkgConfig::STB) list their library files here.
      get_target_property(linked ${dep} INTERFACE_LINK_LIBRARIES)
      foreach(item IN LISTS linked)
        if(IS_ABSOLUTE "${item}" AND EXISTS "${item}")
          list(APPEND files "${item}")
        endif()
      endforeach()
    else()
      foreach(config _RELEASE _NONE _NOCONFIG "")
        get_target_property(location ${dep} IMPORTED_LOCATION${config})
        if(location)
          list(APPEND files "${location}")
          break()
        endif()
      endforeach()
      if(NOT files)
        message(FATAL_ERROR "tsah_link_private: no library file for ${dep} (type ${type})")
      endif()
    endif()
    foreach(file IN LISTS files)
      file(REAL_PATH "${file}" real)
      target_link_libraries(${lib} PRIVATE "$<INSTALL_INTERFACE:${real}>")
    endforeach()
  endforeach()
endfunction()
