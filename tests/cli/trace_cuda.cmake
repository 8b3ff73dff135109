# CLI smoke tests for `tsah trace --device cuda` that hold on any machine: the GPU rebuilds belong to
# --device cuda and the CPU rebuilds to --device cpu; without the GPU runtime built, or without a
# device (CUDA_VISIBLE_DEVICES=-1 hides every GPU, so a GPU machine sees the same), --device cuda is
# one line and exit status 1.
set(W ${TSAH_CLI_WORK})

add_test(NAME cli.trace_cuda.setup.generate
         COMMAND tsah generate explode -o ${W}/trace_cuda.tanim --triangles 800 --frames 4 --seed 3)
set_tests_properties(cli.trace_cuda.setup.generate PROPERTIES FIXTURES_SETUP trace_cuda_anim)
add_test(NAME cli.trace_cuda.setup.optimize
         COMMAND tsah optimize ${W}/trace_cuda.tanim -o ${W}/trace_cuda.tbvh --frames 2 --eval-frames 3)
set_tests_properties(cli.trace_cuda.setup.optimize PROPERTIES FIXTURES_REQUIRED trace_cuda_anim
  FIXTURES_SETUP trace_cuda_tree)

# add_trace_error_test(NAME REGEX ENV ARGS...): the output is one line matching REGEX and the status is a
# failure; ENV ("" for none) is set for both runs.
function(add_trace_error_test name regex env)
  add_test(NAME cli.trace_cuda.${name} COMMAND tsah trace ${W}/trace_cuda.tanim ${W}/trace_cuda.tbvh --frames 1
                                               --width 16 --height 12 --no-images ${ARGN})
  set_tests_properties(cli.trace_cuda.${name} PROPERTIES FIXTURES_REQUIRED trace_cuda_tree
    PASS_REGULAR_EXPRESSION "^tsah: ${regex}[^\n]*\n$")
  add_test(NAME cli.trace_cuda.${name}.status COMMAND tsah trace ${W}/trace_cuda.tanim ${W}/trace_cuda.tbvh
                                                      --frames 1 --width 16 --height 12 --no-images ${ARGN})
  set_tests_properties(cli.trace_cuda.${name}.status PROPERTIES FIXTURES_REQUIRED trace_cuda_tree WILL_FAIL TRUE)
  if(env)
    set_tests_properties(cli.trace_cuda.${name} cli.trace_cuda.${name}.status PROPERTIES ENVIRONMENT "${env}")
  endif()
endfunction()

# Rebuild and device must match, whatever is built.
add_trace_error_test(rebuild.gpu_on_cpu "--rebuild lbvh is a GPU rebuild: use it with --device cuda" "" --rebuild lbvh)
add_trace_error_test(rebuild.gpu_on_cpu.hlbvh "--rebuild hlbvh-sah is a GPU rebuild" "" --device cpu
                     --rebuild hlbvh-sah)
add_trace_error_test(rebuild.cpu_on_gpu "--rebuild binned is a CPU rebuild: use it with --device cpu" ""
                     --device cuda --rebuild binned)
# --layout names a layout of the chosen device: the CPU's (bvh2, bvh4, bvh8) or the GPU's (bvh2, cwbvh).
add_trace_error_test(layout.cwbvh_on_cpu "--layout cwbvh is not a layout of --device cpu \\(auto, bvh2, bvh4 or bvh8\\)" ""
                     --layout cwbvh)
add_trace_error_test(layout.bvh8_on_gpu "--layout bvh8 is not a layout of --device cuda \\(auto, bvh2 or cwbvh\\)" ""
                     --device cuda --layout bvh8)

if(TSAH_HAVE_CUDA)
  add_trace_error_test(no_device "no CUDA device found" "CUDA_VISIBLE_DEVICES=-1" --device cuda)
  add_trace_error_test(no_device.rebuild "no CUDA device found" "CUDA_VISIBLE_DEVICES=-1" --device cuda
                       --rebuild hlbvh-sah)
  # Whatever this machine has: a GPU traces (the JSON names it), no GPU is the one-line error.
  add_test(NAME cli.trace_cuda.any COMMAND tsah trace ${W}/trace_cuda.tanim ${W}/trace_cuda.tbvh --device cuda
                                           --frames 2 --width 32 --height 24 --no-images --json)
  set_tests_properties(cli.trace_cuda.any PROPERTIES FIXTURES_REQUIRED trace_cuda_tree
    PASS_REGULAR_EXPRESSION "^tsah: no CUDA device found[^\n]*\n$|\"gpu\":{.*\"name\":.*\"timer\":\"CUDA events")
else()
  add_trace_error_test(not_built "the GPU runtime is not built" "" --device cuda)
  add_trace_error_test(not_built.rebuild "the GPU runtime is not built" "" --device cuda --rebuild lbvh)
endif()
