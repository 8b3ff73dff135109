# cmake -DBUILD_DIR=... -DWORK_DIR=... -DPYTHON_DIR=... -DPYTHON=... [-DCXX_COMPILER=...]
#       [-DCXX_LAUNCHER=...] -P standalone-build.cmake
# Installs the build tree into WORK_DIR/prefix, configures python/ as its own project against that
# prefix (find_package(tsah), pybind11 from the interpreter's machine), builds the module and imports
# it with PYTHON: what a user with their own Python does. Fails unless every step succeeds.
include(${CMAKE_CURRENT_LIST_DIR}/../cmake/ScratchInstall.cmake)
tsah_require_script_variables(standalone-build.cmake BUILD_DIR WORK_DIR PYTHON_DIR PYTHON)
tsah_install_into_scratch(${BUILD_DIR} ${WORK_DIR} prefix)

set(configure_args -S ${PYTHON_DIR} -B ${WORK_DIR}/build -DCMAKE_PREFIX_PATH=${prefix} -DPython3_EXECUTABLE=${PYTHON})
tsah_append_compiler_args(configure_args)
execute_process(COMMAND ${CMAKE_COMMAND} ${configure_args} OUTPUT_VARIABLE output ERROR_VARIABLE output
                RESULT_VARIABLE result)
if(NOT result EQUAL 0)
  message(FATAL_ERROR "python/ did not configure against the installed tsah:\n${output}")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${WORK_DIR}/build -j2 OUTPUT_VARIABLE output ERROR_VARIABLE output
                RESULT_VARIABLE result)
if(NOT result EQUAL 0)
  message(FATAL_ERROR "python/ did not build against the installed tsah:\n${output}")
endif()

# The module made there is the one imported (not the build tree's), and it works.
execute_process(COMMAND ${CMAKE_COMMAND} -E env PYTHONPATH=${WORK_DIR}/build ${PYTHON} -c
  "import numpy as np, tsah; a = tsah.generate('wave', triangles=200, frames=3, seed=1); r = tsah.CpuRuntime(tsah.optimize(a, seed=1), a); print('standalone:', tsah.__file__, tsah.__version__, r.occluded(np.array([0, 0, -10.0]), np.array([0, 0, 1.0])).shape)"
  WORKING_DIRECTORY ${WORK_DIR}  # python -c puts the working directory first on sys.path
  OUTPUT_VARIABLE output ERROR_VARIABLE output RESULT_VARIABLE result)
message("${output}")
if(NOT result EQUAL 0 OR NOT output MATCHES "standalone: ${WORK_DIR}/build/tsah/__init__.py [0-9.]+ \\(\\)")
  message(FATAL_ERROR "the standalone module did not import and trace")
endif()
