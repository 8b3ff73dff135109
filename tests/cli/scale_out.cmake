# Scale-out (docs/scale-out.md): frame chunks merged by `tsah report`, and, when MPI is built and
# mpirun is found, `mpirun -n 2` against one process: the same PNGs, statistics and tree-set bytes.
set(W ${TSAH_CLI_WORK})
set(SO ${W}/scale_out)
file(MAKE_DIRECTORY ${SO})

add_test(NAME cli.scale.setup.generate
         COMMAND tsah generate wave -o ${SO}/wave.tanim --triangles 2000 --frames 6 --seed 3)
set_tests_properties(cli.scale.setup.generate PROPERTIES FIXTURES_SETUP scale_anim)
add_test(NAME cli.scale.setup.optimize
         COMMAND tsah optimize ${SO}/wave.tanim -o ${SO}/wave.tbvh --segments 2 --frames 3 --eval-frames 6)
set_tests_properties(cli.scale.setup.optimize PROPERTIES FIXTURES_REQUIRED scale_anim FIXTURES_SETUP scale_tree)

# scale_same(NAME MODE LAUNCH RANGES ARG...): tests/support/scale_out_same.cmake on the wave and its
# tree set (LAUNCH and RANGES as ;-lists in one argument, "-" for none; SCALE_SPLIT: the split run's
# own arguments).
set(SCALE_TRACE_ARGS --frames 6 --width 48 --height 32 --ao 2 --shadow 1 --threads 1)
function(scale_same name mode launch ranges)
  string(REPLACE ";" "@@" args "${ARGN}")
  string(REPLACE ";" "@@" launch "${launch}")
  string(REPLACE ";" "@@" split "${SCALE_SPLIT}")
  add_test(NAME ${name}
           COMMAND ${CMAKE_COMMAND} -DTSAH=$<TARGET_FILE:tsah> -DMODE=${mode} "-DLAUNCH=${launch}" "-DRANGES=${ranges}"
                   -DINPUT=${SO}/wave.tanim -DTREE=${SO}/wave.tbvh -DOUT=${SO}/${name} -DFRAMES=6 "-DARGS=${args}"
                   "-DSPLIT=${split}"
                   -P ${PROJECT_SOURCE_DIR}/tests/support/scale_out_same.cmake)
  set_tests_properties(${name} PROPERTIES FIXTURES_REQUIRED "scale_anim;scale_tree"
                       SKIP_REGULAR_EXPRESSION "no CUDA device found|GPU runtime is not built")
endfunction()

# Three chunks (given out of order) merged equal one run: PNG bytes and the statistics.
scale_same(cli.scale.chunks chunks - "5:6;0:2;2:5" ${SCALE_TRACE_ARGS})

# Chunks that do not make one run: one line each, exit 1.
string(REPLACE ";" " " trace_args "${SCALE_TRACE_ARGS}")
add_test(NAME cli.scale.setup.chunks
         COMMAND ${CMAKE_COMMAND} -E chdir ${SO} sh -c
                 "$<TARGET_FILE:tsah> trace wave.tanim wave.tbvh ${trace_args} --no-images --range 0:3 --stats c03.json >/dev/null && \
                  $<TARGET_FILE:tsah> trace wave.tanim wave.tbvh ${trace_args} --no-images --range 2:6 --stats c26.json >/dev/null && \
                  $<TARGET_FILE:tsah> trace wave.tanim wave.tbvh ${trace_args} --no-images --range 4:6 --stats c46.json >/dev/null && \
                  $<TARGET_FILE:tsah> trace wave.tanim wave.tbvh ${trace_args} --no-images --range 3:6 --seed 2 --stats s2.json >/dev/null && \
                  $<TARGET_FILE:tsah> trace wave.tanim wave.tbvh ${trace_args} --out other --range 3:6 --stats i36.json >/dev/null")
set_tests_properties(cli.scale.setup.chunks PROPERTIES FIXTURES_REQUIRED "scale_anim;scale_tree" FIXTURES_SETUP scale_chunks)
foreach(case "overlap;c03.json;c26.json;c26.json: frames 2..2 are also in another chunk"
             "gap;c46.json;c03.json;frames 3..3 of 6 are in no chunk \\(the next is .*c46.json\\)"
             "end;c03.json;frames 3..5 of 6 are in no chunk"
             "mismatch;c03.json;s2.json;s2.json: another run than .*c03.json \\(its seed differs\\)")
  list(GET case 0 what)
  list(GET case -1 regex)
  list(SUBLIST case 1 -1 files)
  list(REMOVE_AT files -1)
  set(paths)
  foreach(f ${files})
    list(APPEND paths ${SO}/${f})
  endforeach()
  tsah_expect_error(cli.scale.report.${what} 1 "${regex}" report ${paths})
  set_tests_properties(cli.scale.report.${what} PROPERTIES FIXTURES_REQUIRED scale_chunks)
endforeach()
# Chunks whose PNGs went to different folders (here: none, and other/) still make one run; the
# summary names no single folder.
add_test(NAME cli.scale.report.folders COMMAND tsah report ${SO}/i36.json ${SO}/c03.json)
set_tests_properties(cli.scale.report.folders PROPERTIES FIXTURES_REQUIRED scale_chunks
                     PASS_REGULAR_EXPRESSION "\n    5 .*\n  avg " FAIL_REGULAR_EXPRESSION "images in")
# Files that are not chunk statistics.
file(WRITE ${SO}/no_range.json "{\"frames\": []}")
file(WRITE ${SO}/bad_types.json "{\"range\": [0, 1], \"frames\": {}, \"run_frames\": 1}")
tsah_expect_error(cli.scale.report.not_stats 1 "no_range.json: not the statistics of `tsah trace --stats`" report
                  ${SO}/no_range.json)
tsah_expect_error(cli.scale.report.bad_types 1 "bad_types.json: frames must be a list, run_frames a count" report
                  ${SO}/bad_types.json)
# --range out of the run: a usage error.
tsah_expect_error(cli.scale.range.bounds 2 "--range 4:9: needs 0 <= START < END <= 6" trace ${SO}/wave.tanim
                  ${SO}/wave.tbvh --frames 6 --range 4:9 --no-images)
tsah_expect_error(cli.scale.range.text 2 "--range expects START:END" trace ${SO}/wave.tanim ${SO}/wave.tbvh
                  --range 3 --no-images)
set_tests_properties(cli.scale.range.bounds cli.scale.range.text PROPERTIES FIXTURES_REQUIRED "scale_anim;scale_tree")
# On a machine with GPUs (skipped elsewhere): every GPU against one, the same PNGs and statistics;
# with MPI, two ranks on the GPUs of their local ranks against one process.
set(SCALE_SPLIT --devices all)
scale_same(cli.scale.gpu.devices split - - ${SCALE_TRACE_ARGS} --device cuda)
set(SCALE_SPLIT)

# --devices without a GPU (CUDA_VISIBLE_DEVICES hides them all; or a build without CUDA): a usage error.
tsah_expect_error(cli.scale.devices.none 2 "--devices all: no CUDA device found" trace ${SO}/wave.tanim
                  ${SO}/wave.tbvh --device cuda --devices all --no-images)
set_tests_properties(cli.scale.devices.none PROPERTIES ENVIRONMENT "CUDA_VISIBLE_DEVICES=-1"
                     FIXTURES_REQUIRED "scale_anim;scale_tree")

# tsah resample --range: the keyframes START .. END-1 of the whole output, at their times.
add_test(NAME cli.scale.resample.range
         COMMAND ${CMAKE_COMMAND} -E chdir ${SO} sh -c
                 "$<TARGET_FILE:tsah> resample wave.tanim -o part.tanim --frames 11 --range 4:7 && $<TARGET_FILE:tsah> info part.tanim")
set_tests_properties(cli.scale.resample.range PROPERTIES FIXTURES_REQUIRED scale_anim
  PASS_REGULAR_EXPRESSION "part.tanim: 3 keyframes \\(from 6\\), 2048 triangles, time 2 .. 3\n")
tsah_expect_error(cli.scale.resample.bounds 2 "--range 9:12: needs 0 <= START < END <= 11" resample
                  ${SO}/wave.tanim -o ${SO}/bad.tanim --frames 11 --range 9:12)
set_tests_properties(cli.scale.resample.bounds PROPERTIES FIXTURES_REQUIRED scale_anim)

# MPI: two ranks on the CPU against one process.
# (Open MPI's mpirun: the flags below are its own.)
find_program(TSAH_MPIRUN NAMES mpirun mpiexec)
set(TSAH_MPIRUN_IS_OPEN_MPI OFF)
if(TSAH_MPIRUN)
  execute_process(COMMAND ${TSAH_MPIRUN} --version OUTPUT_VARIABLE mpirun_version ERROR_QUIET)
  if(mpirun_version MATCHES "Open MPI")
    set(TSAH_MPIRUN_IS_OPEN_MPI ON)
  endif()
endif()
if(TSAH_HAVE_MPI AND TSAH_MPIRUN_IS_OPEN_MPI)
  # Open MPI's plug-ins keep allocations until the process ends and are unloaded before the leak
  # check, which then cannot name them: a sanitizer build checks memory errors here, leaks in the
  # one-process runs of the same code.
  set(MPI2 ${CMAKE_COMMAND} -E env ASAN_OPTIONS=detect_leaks=0
           ${TSAH_MPIRUN} --oversubscribe --allow-run-as-root -n 2)
  scale_same(cli.scale.mpi.trace split "${MPI2}" - ${SCALE_TRACE_ARGS})
  scale_same(cli.scale.gpu.mpi split "${MPI2}" - ${SCALE_TRACE_ARGS} --device cuda)
  scale_same(cli.scale.mpi.optimize optimize "${MPI2}" - --segments auto --budget 1.01 --frames 3 --eval-frames 8
             --reference-frames 4 --threads 1 --reproducible)
  # A rank that cannot read its input (rank 1 is given a missing file): one line naming the rank,
  # the job ends with a non-zero exit.
  add_test(NAME cli.scale.mpi.rank_fails
           COMMAND ${CMAKE_COMMAND} -E env sh -c
                   "${TSAH_MPIRUN} --oversubscribe --allow-run-as-root --quiet -n 1 $<TARGET_FILE:tsah> trace ${SO}/wave.tanim ${SO}/wave.tbvh --no-images : -n 1 $<TARGET_FILE:tsah> trace ${SO}/missing.tanim ${SO}/wave.tbvh --no-images 2>&1 >/dev/null; echo exit=$?")
  set_tests_properties(cli.scale.mpi.rank_fails PROPERTIES FIXTURES_REQUIRED "scale_anim;scale_tree" TIMEOUT 60
    PASS_REGULAR_EXPRESSION "^tsah: rank 1: [^\n]*missing.tanim[^\n]*\n(.*\n)?exit=[1-9]")
endif()

# A process bound to one core (as mpirun binds each rank): the CPU runtime takes one thread, and
# TBB has nothing to warn about.
find_program(TSAH_TASKSET taskset)
if(TSAH_TASKSET)
  add_test(NAME cli.scale.bound_to_one_core
           COMMAND ${TSAH_TASKSET} -c 0 $<TARGET_FILE:tsah> trace ${SO}/wave.tanim ${SO}/wave.tbvh --frames 2
                   --width 32 --height 24 --no-images --json)
  set_tests_properties(cli.scale.bound_to_one_core PROPERTIES FIXTURES_REQUIRED "scale_anim;scale_tree"
                       PASS_REGULAR_EXPRESSION "\"threads\":1," FAIL_REGULAR_EXPRESSION "TBB Warning")
endif()
