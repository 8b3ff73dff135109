# Steps shared by the -P scripts that check the installed package from a scratch folder
# (examples/install-consumer.cmake, python/standalone-build.cmake).

# Fails naming `script` unless every variable listed after it is set.
function(tsah_require_script_variables script)
  foreach(var ${ARGN})
    if(NOT ${var})
      message(FATAL_ERROR "${script}: ${var} is not set")
    endif()
  endforeach()
endfunction()

# Empties work_dir and installs build_dir into work_dir/prefix; sets prefix_var to that folder.
function(tsah_install_into_scratch build_dir work_dir prefix_var)
  file(REMOVE_RECURSE ${work_dir})
  file(MAKE_DIRECTORY ${work_dir})
  execute_process(COMMAND ${CMAKE_COMMAND} --install ${build_dir} --prefix ${work_dir}/prefix
                  OUTPUT_QUIET COMMAND_ERROR_IS_FATAL ANY)
  set(${prefix_var} ${work_dir}/prefix PARENT_SCOPE)
endfunction()

# Appends to list_var the compiler and compiler launcher given to the script (CXX_COMPILER,
# CXX_LAUNCHER), for the projects it configures.
function(tsah_append_compiler_args list_var)
  set(args ${${list_var}})
  if(CXX_COMPILER)
    list(APPEND args -DCMAKE_CXX_COMPILER=${CXX_COMPILER})
  endif()
  if(CXX_LAUNCHER)
    list(APPEND args -DCMAKE_CXX_COMPILER_LAUNCHER=${CXX_LAUNCHER})
  endif()
  set(${list_var} ${args} PARENT_SCOPE)
endfunction()
