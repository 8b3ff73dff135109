# cmake -DBUILD_DIR=... -DWORK_DIR=... -DCONSUMER_DIR=... -DINPUT=... [-DCXX_COMPILER=...]
#       [-DCXX_LAUNCHER=...] -P install-consumer.cmake
# Installs the build tree into WORK_DIR/prefix, builds the consumer example against it (its own
# CMake project, find_package(tsah) only) and runs it on INPUT; fails unless every step succeeds
# and the program prints the tree and at least one ray hit.
include(${CMAKE_CURRENT_LIST_DIR}/../cmake/ScratchInstall.cmake)
tsah_require_script_variables(install-consumer.cmake BUILD_DIR WORK_DIR CONSUMER_DIR INPUT)
tsah_install_into_scratch(${BUILD_DIR} ${WORK_DIR} prefix)
foreach(installed bin/tsah include/tsah/pipeline.hpp include/anim/animation.hpp lib/cmake/tsah/tsahConfig.cmake
                  lib/cmake/tsah/tsahConfigVersion.cmake lib/cmake/tsah/tsahTargets.cmake)
  if(NOT EXISTS ${prefix}/${installed})
    message(FATAL_ERROR "cmake --install did not install ${installed}")
  endif()
endforeach()
# Private headers (src/) must not be installed.
file(GLOB_RECURSE private_headers ${prefix}/include/*/random.hpp ${prefix}/include/*/bart_scene.hpp)
if(private_headers)
  message(FATAL_ERROR "private headers were installed: ${private_headers}")
endif()

# The package names no development package of tsah's private dependencies (they are linked as the
# runtime packages' library files) and no CUDA outside the cuda component.
file(READ ${prefix}/lib/cmake/tsah/tsahTargets.cmake targets)
file(STRINGS ${prefix}/lib/cmake/tsah/tsahConfig.cmake config REGEX "^[^#]")  # code, not comments
foreach(pattern "assimp::" "TBB::" "PkgConfig::" "nlohmann_json::" "draco::" "CUDA::" "[;\"]OpenMesh(Core|Tools)[;\"]"
                "find_dependency\\((assimp|OpenMesh|TBB|nlohmann_json|PkgConfig|CUDAToolkit)\\)")
  string(REGEX MATCH "${pattern}" found "${targets}${config}")
  if(found AND NOT (found MATCHES "CUDAToolkit" AND config MATCHES "IN_LIST tsah_FIND_COMPONENTS"))
    message(FATAL_ERROR "the installed tsah package names ${found} outside the cuda component")
  endif()
endforeach()

# Three consumers: CPU only, with the dependencies' CMake packages and the CUDA toolkit hidden (what a
# machine without their development packages sees) and no build type given (the example's default:
# Release); the full example (OPTIONAL_COMPONENTS cuda) where the CUDA toolkit is missing, which
# must still find the CPU part; then the full example (the GPU part when tsah has it).
set(hidden)
foreach(package assimp OpenMesh TBB nlohmann_json PkgConfig CUDAToolkit draco)
  list(APPEND hidden -DCMAKE_DISABLE_FIND_PACKAGE_${package}=ON)
endforeach()
set(variants cpu no-toolkit full)
set(cpu_args -DCONSUMER_CPU_ONLY=ON ${hidden})
set(no-toolkit_args -DCMAKE_BUILD_TYPE=Release -DCMAKE_DISABLE_FIND_PACKAGE_CUDAToolkit=ON)
set(full_args -DCMAKE_BUILD_TYPE=Release)
foreach(variant IN LISTS variants)
  set(configure_args -S ${CONSUMER_DIR} -B ${WORK_DIR}/build-${variant} -DCMAKE_PREFIX_PATH=${prefix} ${${variant}_args})
  tsah_append_compiler_args(configure_args)
  execute_process(COMMAND ${CMAKE_COMMAND} ${configure_args} OUTPUT_VARIABLE configure_output
                  ERROR_VARIABLE configure_output RESULT_VARIABLE configure_result)
  if(NOT configure_result EQUAL 0)
    message(FATAL_ERROR "the ${variant} consumer did not configure:\n${configure_output}")
  endif()
  execute_process(COMMAND ${CMAKE_COMMAND} --build ${WORK_DIR}/build-${variant} OUTPUT_QUIET COMMAND_ERROR_IS_FATAL ANY)
  file(STRINGS ${WORK_DIR}/build-${variant}/CMakeCache.txt build_type REGEX "^CMAKE_BUILD_TYPE:")
  if(NOT build_type MATCHES "=Release$")
    message(FATAL_ERROR "the ${variant} consumer was not built as Release: ${build_type}")
  endif()

  execute_process(COMMAND ${WORK_DIR}/build-${variant}/tsah_consumer ${INPUT} ${WORK_DIR}/out.tbvh
                  OUTPUT_VARIABLE output COMMAND_ERROR_IS_FATAL ANY)
  message("${variant}: ${output}")
  if(NOT output MATCHES "out.tbvh: [0-9]+ triangles, [0-9]+ nodes, 5 frames, average cost [0-9.]+")
    message(FATAL_ERROR "the ${variant} consumer did not describe its tree")
  endif()
  if(NOT output MATCHES "ray [0-9]: triangle [0-9]+ at t = ")
    message(FATAL_ERROR "the ${variant} consumer's rays hit nothing")
  endif()
endforeach()

# The installed program reads the tree the library wrote.
execute_process(COMMAND ${prefix}/bin/tsah info ${WORK_DIR}/out.tbvh OUTPUT_VARIABLE info COMMAND_ERROR_IS_FATAL ANY)
if(NOT info MATCHES "tsah")
  message(FATAL_ERROR "installed tsah info did not describe the tree: ${info}")
endif()

# The installed Python package imports from the prefix (when the module was built).
file(GLOB python_package ${prefix}/lib/python3*/dist-packages/tsah)
if(python_package AND EXISTS /usr/bin/python3)
  get_filename_component(site ${python_package} DIRECTORY)
  execute_process(COMMAND ${CMAKE_COMMAND} -E env PYTHONPATH=${site} /usr/bin/python3 -c
                          "import tsah; print('python:', tsah.__version__, tsah.load('${INPUT}'))"
                  OUTPUT_VARIABLE python_output COMMAND_ERROR_IS_FATAL ANY)
  message("${python_output}")
endif()
