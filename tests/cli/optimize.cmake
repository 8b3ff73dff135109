# CLI smoke tests for `tsah optimize` and `tsah evaluate`: JSON fields, methods, determinism,
# static input, and one-line errors without half-written output.
set(W ${TSAH_CLI_WORK})

add_test(NAME cli.optimize.input
         COMMAND tsah generate swap -o ${W}/opt_swap.tanim --triangles 600 --frames 10 --seed 5)
set_tests_properties(cli.optimize.input PROPERTIES FIXTURES_SETUP opt_input)

# A small static OBJ (one frame): two separated quads.
file(WRITE ${W}/opt_static.obj
"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 5 0 1\nv 6 0 1\nv 6 1 1\nv 5 1 1\n\
f 1 2 3\nf 1 3 4\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 3 4 8\n")

# T-SAH: the issue's JSON fields and the optimizer's report.
add_test(NAME cli.optimize.tsah
         COMMAND tsah optimize ${W}/opt_swap.tanim -o ${W}/opt_tsah.tbvh --k 2 --seed 7 --json)
set_tests_properties(cli.optimize.tsah PROPERTIES FIXTURES_REQUIRED opt_input
  PASS_REGULAR_EXPRESSION "^\\{\"build_s\":[0-9.e-]+,\"cost\":\\{\"average\":[0-9.]+,\"maximum\":[0-9.]+,\"per_frame\":\\[[0-9.]+(,[0-9.]+)*\\]\\}.*\"k\":2,\"leaves\":[0-9]+,.*\"method\":\"tsah\",\"nodes\":[0-9]+,\"optimization\":\\{.*\"history\":\\[\\{.*\"selection\":\"mh\".*\"triangles\":[0-9]+\\}\n$")

# Two runs that must give the same tree: for each of RUN_A and RUN_B, `tsah optimize INPUT -o
# OUT_<run>.tbvh ARGS` with %RUN% in ARGS (separated by @@) replaced by the run's name; everything in
# the two reports but the timings, the memory and the output path agrees.
file(WRITE ${W}/opt_same_report.cmake [=[
string(REPLACE "@@" ";" args "${ARGS}")
foreach(run ${RUN_A} ${RUN_B})
  string(REPLACE "%RUN%" "${run}" run_args "${args}")
  execute_process(COMMAND ${TSAH} optimize ${INPUT} -o ${OUT}_${run}.tbvh ${run_args}
                  OUTPUT_VARIABLE json_${run} RESULT_VARIABLE status)
  if(NOT status EQUAL 0)
    message(FATAL_ERROR "tsah optimize failed: ${status}")
  endif()
  string(REGEX REPLACE "\"(build_s|elapsed_s|seconds|peak_rss_bytes)\":[0-9.e+-]+" "" json_${run} "${json_${run}}")
  string(REGEX REPLACE "\"output\":\"[^\"]*\"" "" json_${run} "${json_${run}}")
endforeach()
if(NOT json_${RUN_A} STREQUAL json_${RUN_B})
  message(FATAL_ERROR "${WHAT}, different results:\n${json_${RUN_A}}\n${json_${RUN_B}}")
endif()
]=])
# opt_same_report(NAME OUT WHAT RUN_A RUN_B ARG...): the script above on opt_swap.tanim.
function(opt_same_report name out what run_a run_b)
  string(REPLACE ";" "@@" args "${ARGN}")
  add_test(NAME ${name}
           COMMAND ${CMAKE_COMMAND} -DTSAH=$<TARGET_FILE:tsah> -DINPUT=${W}/opt_swap.tanim -DOUT=${W}/${out}
                   -DRUN_A=${run_a} -DRUN_B=${run_b} "-DWHAT=${what}" "-DARGS=${args}" -P ${W}/opt_same_report.cmake)
  set_tests_properties(${name} PROPERTIES FIXTURES_REQUIRED opt_input)
endfunction()

# The same seed gives the same tree.
opt_same_report(cli.optimize.deterministic opt_seed "same seed" a b --k 2 --seed 7 --json)

# SAH0 with one triangle per leaf: as many leaves as triangles; selection recorded as none.
add_test(NAME cli.optimize.sah0
         COMMAND tsah optimize ${W}/opt_swap.tanim -o ${W}/opt_sah0.tbvh --method sah0 --max-leaf 1 --json)
set_tests_properties(cli.optimize.sah0 PROPERTIES FIXTURES_REQUIRED opt_input
  PASS_REGULAR_EXPRESSION "\"leaves\":([0-9]+),.*\"method\":\"sah0\",\"nodes\":[0-9]+,.*\"selection\":\"none\"")

add_test(NAME cli.optimize.sahstar
         COMMAND tsah optimize ${W}/opt_swap.tanim -o ${W}/opt_star.tbvh --method sahstar --selection batch
                 --frames 3 --eval-frames 7 --ct 1 --ci 1 --max-leaf 4 --json)
set_tests_properties(cli.optimize.sahstar PROPERTIES FIXTURES_REQUIRED opt_input
  PASS_REGULAR_EXPRESSION "\"eval_frames\":7,\"frames\":3,.*\"max_leaf\":4,\"method\":\"sahstar\".*\"selection\":\"batch\"")

# Text output and a time limit.
add_test(NAME cli.optimize.text
         COMMAND tsah optimize ${W}/opt_swap.tanim -o ${W}/opt_text.tbvh --selection random --time-limit 30)
set_tests_properties(cli.optimize.text PROPERTIES FIXTURES_REQUIRED opt_input
  PASS_REGULAR_EXPRESSION "opt_text.tbvh: tsah0 tree, [0-9]+ triangles.*\noptimization: T-SAH cost [0-9.]+ -> [0-9.]+ over 5 frames.*\nbuild [0-9.]+ s; cost over 50 evaluation frames: average [0-9.]+, maximum [0-9.]+\n")

# A static mesh: one representative and one evaluation frame.
add_test(NAME cli.optimize.static
         COMMAND tsah optimize ${W}/opt_static.obj -o ${W}/opt_static.tbvh --max-leaf 1 --json)
set_tests_properties(cli.optimize.static PROPERTIES
  PASS_REGULAR_EXPRESSION "\"cost\":\\{\"average\":[0-9.]+,\"maximum\":[0-9.]+,\"per_frame\":\\[[0-9.]+\\]\\}.*\"eval_frames\":1,\"frames\":1,.*\"leaves\":6,.*\"nodes\":11,.*\"triangles\":6")

# The paper's Table 1: names as written in --methods, in that order.
add_test(NAME cli.evaluate.json
         COMMAND tsah evaluate ${W}/opt_swap.tanim --methods sah0,tsah,tsah4,sahstar,rebuild --eval-frames 12 --json)
set_tests_properties(cli.evaluate.json PROPERTIES FIXTURES_REQUIRED opt_input
  PASS_REGULAR_EXPRESSION "\"methods\":\\[\\{\"average\":[0-9.]+,\"build_s\":[0-9.e-]+,\"maximum\":[0-9.]+,\"name\":\"sah0\",\"per_frame\":\\[[0-9.]+(,[0-9.]+)*\\]\\},\\{[^}]*\"name\":\"tsah\"[^}]*\\},\\{[^}]*\"name\":\"tsah4\"[^}]*\\},\\{[^}]*\"name\":\"sahstar\"[^}]*\\},\\{[^}]*\"name\":\"rebuild\"[^}]*\\}\\]")
add_test(NAME cli.evaluate.text
         COMMAND tsah evaluate ${W}/opt_swap.tanim --eval-frames 5 --threads 1)
set_tests_properties(cli.evaluate.text PROPERTIES FIXTURES_REQUIRED opt_input
  PASS_REGULAR_EXPRESSION "method +build \\[s\\] +cost +max cost\nsah0 .*\nsahstar .*\ntsah0 .*\ntsah2 .*\ntsah4 .*\nrebuild .*\n")

# Errors: one line, non-zero exit, no output file left behind.
add_test(NAME cli.evaluate.error.method COMMAND tsah evaluate ${W}/opt_swap.tanim --methods sah0,foo)
set_tests_properties(cli.evaluate.error.method PROPERTIES FIXTURES_REQUIRED opt_input
  PASS_REGULAR_EXPRESSION "^tsah: --methods: unknown method 'foo'")
add_test(NAME cli.evaluate.error.method.status COMMAND tsah evaluate ${W}/opt_swap.tanim --methods foo)
set_tests_properties(cli.evaluate.error.method.status PROPERTIES FIXTURES_REQUIRED opt_input WILL_FAIL TRUE)
add_test(NAME cli.optimize.error.missing COMMAND tsah optimize ${W}/no-such-input.obj -o ${W}/never.tbvh)
set_tests_properties(cli.optimize.error.missing PROPERTIES WILL_FAIL TRUE)
add_test(NAME cli.optimize.error.method COMMAND tsah optimize ${W}/opt_swap.tanim -o ${W}/never.tbvh --method best)
set_tests_properties(cli.optimize.error.method PROPERTIES FIXTURES_REQUIRED opt_input WILL_FAIL TRUE)
add_test(NAME cli.optimize.error.k COMMAND tsah optimize ${W}/opt_swap.tanim -o ${W}/never.tbvh --k -1)
set_tests_properties(cli.optimize.error.k PROPERTIES FIXTURES_REQUIRED opt_input WILL_FAIL TRUE)
add_test(NAME cli.optimize.error.output
         COMMAND tsah optimize ${W}/opt_swap.tanim -o ${W}/no-such-folder/out.tbvh)
set_tests_properties(cli.optimize.error.output PROPERTIES FIXTURES_REQUIRED opt_input
  PASS_REGULAR_EXPRESSION "^tsah: .*no-such-folder/out.tbvh")
add_test(NAME cli.optimize.error.nothing-written
         COMMAND ${CMAKE_COMMAND} -E cat ${W}/never.tbvh)
set_tests_properties(cli.optimize.error.nothing-written PROPERTIES WILL_FAIL TRUE
  DEPENDS "cli.optimize.error.missing;cli.optimize.error.method;cli.optimize.error.k")

# The parallel optimizer: recorded in the report and the file, the same tree for 1 and 2 threads.
add_test(NAME cli.optimize.parallel
         COMMAND tsah optimize ${W}/opt_swap.tanim -o ${W}/opt_par.tbvh --optimizer parallel --threads 2 --json)
set_tests_properties(cli.optimize.parallel PROPERTIES FIXTURES_REQUIRED opt_input
  PASS_REGULAR_EXPRESSION "\"optimizer\":\"parallel\".*\"selection\":\"parallel\"")
opt_same_report(cli.optimize.parallel.threads opt_par "1 and 2 threads" 1 2
                --optimizer parallel --k 2 --threads %RUN% --json)
add_test(NAME cli.evaluate.parallel
         COMMAND tsah evaluate ${W}/opt_swap.tanim --methods sahstar,tsah0,rebuild --optimizer parallel --eval-frames 4 --json)
set_tests_properties(cli.evaluate.parallel PROPERTIES FIXTURES_REQUIRED opt_input
  PASS_REGULAR_EXPRESSION "\"name\":\"sahstar\".*\"name\":\"tsah0\".*\"name\":\"rebuild\"")

# --device cuda: the GPU optimizer. Without it built, or without a device (CUDA_VISIBLE_DEVICES=-1
# hides every GPU), one line and a failure status, no output file; with a device, the report says so.
if(TSAH_HAVE_CUDA)
  set(opt_cuda_missing "--device cuda: no CUDA device found")
  set(opt_cuda_env "CUDA_VISIBLE_DEVICES=-1")
else()
  set(opt_cuda_missing "--device cuda: the GPU optimizer is not built")
  set(opt_cuda_env "")
endif()
foreach(command optimize evaluate)
  if(command STREQUAL optimize)
    set(opt_cuda_args optimize ${W}/opt_swap.tanim -o ${W}/opt_cuda_missing.tbvh --device cuda)
  else()
    set(opt_cuda_args evaluate ${W}/opt_swap.tanim --methods tsah0 --device cuda)
  endif()
  add_test(NAME cli.${command}.cuda.unavailable COMMAND tsah ${opt_cuda_args})
  add_test(NAME cli.${command}.cuda.unavailable.status COMMAND tsah ${opt_cuda_args})
  set_tests_properties(cli.${command}.cuda.unavailable PROPERTIES FIXTURES_REQUIRED opt_input
    PASS_REGULAR_EXPRESSION "^tsah: ${opt_cuda_missing}[^\n]*\n$")
  set_tests_properties(cli.${command}.cuda.unavailable.status PROPERTIES FIXTURES_REQUIRED opt_input WILL_FAIL TRUE)
  if(opt_cuda_env)
    set_tests_properties(cli.${command}.cuda.unavailable cli.${command}.cuda.unavailable.status
      PROPERTIES ENVIRONMENT "${opt_cuda_env}")
  endif()
endforeach()
# ... and the refused run left no file behind (cat fails on a missing file).
add_test(NAME cli.optimize.cuda.no_output COMMAND ${CMAKE_COMMAND} -E cat ${W}/opt_cuda_missing.tbvh)
set_tests_properties(cli.optimize.cuda.no_output PROPERTIES WILL_FAIL TRUE
  DEPENDS "cli.optimize.cuda.unavailable;cli.optimize.cuda.unavailable.status")
if(TSAH_HAVE_CUDA)
  # Whatever this machine has: a GPU optimizes (the report names the device), no GPU is the one-line error.
  add_test(NAME cli.optimize.cuda.any
           COMMAND tsah optimize ${W}/opt_swap.tanim -o ${W}/opt_cuda.tbvh --device cuda --k 2 --json)
  set_tests_properties(cli.optimize.cuda.any PROPERTIES FIXTURES_REQUIRED opt_input
    PASS_REGULAR_EXPRESSION "^tsah: --device cuda: no CUDA device found[^\n]*\n$|\"device\":\"cuda\".*\"selection\":\"parallel-cuda\"")
endif()
