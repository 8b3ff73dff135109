# tsah bench and tsah optimize --segments: CLI smoke tests on a small generated scene (no real data
# needed), and the link of the bench module's unit tests (tests/test_bench*.cpp) to it.
set(W ${TSAH_CLI_WORK})

foreach(source ${TSAH_TEST_SOURCES})
  get_filename_component(name ${source} NAME_WE)
  if(name MATCHES "^test_bench")
    target_link_libraries(${name} PRIVATE tsah_bench)
  endif()
endforeach()

add_test(NAME cli.bench.input
         COMMAND tsah generate explode -o ${W}/bench_explode.tanim --triangles 300 --frames 6 --seed 3)
set_tests_properties(cli.bench.input PROPERTIES FIXTURES_SETUP bench_input)

# The whole bench on an explicit input, --quick and tiny images: every part runs, both files hold
# the expected keys (checked by the script below), plots are made or skipped with a reason.
add_test(NAME cli.bench.quick
         COMMAND tsah bench ${W}/bench_explode.tanim --quick --width 48 --height 36 --eval-frames 6 --trace-frames 2
                 --threads 2 --seed 9 --out ${W}/bench_out --note "CLI smoke test")
set_tests_properties(cli.bench.quick PROPERTIES FIXTURES_REQUIRED bench_input FIXTURES_SETUP bench_results
  PASS_REGULAR_EXPRESSION "bench_out/results.md\n.*bench_out/results.json\n")

file(WRITE ${W}/bench_check.cmake [=[
foreach(f results.json results.md)
  if(NOT EXISTS ${OUT}/${f})
    message(FATAL_ERROR "${OUT}/${f} is missing")
  endif()
endforeach()
file(READ ${OUT}/results.json json)
macro(expect_key)
  string(JSON value ERROR_VARIABLE error GET "${json}" ${ARGN})
  if(error)
    message(FATAL_ERROR "results.json: ${ARGN}: ${error}")
  endif()
endmacro()
foreach(key command started finished machine versions options seed scenes plots notes paper_source)
  expect_key(${key})
endforeach()
expect_key(machine cpu)
expect_key(machine logical_cores)
expect_key(versions tsah)
expect_key(versions compiler)
expect_key(versions embree)
expect_key(options seed)
expect_key(plots status)
string(JSON seed GET "${json}" options seed)
if(NOT seed EQUAL 9)
  message(FATAL_ERROR "results.json: options.seed is ${seed}, not 9")
endif()
string(JSON scenes LENGTH "${json}" scenes)
if(NOT scenes EQUAL 1)
  message(FATAL_ERROR "results.json: ${scenes} scenes, expected 1")
endif()
string(JSON name GET "${json}" scenes 0 name)
if(NOT name STREQUAL "bench_explode")
  message(FATAL_ERROR "results.json: scene named '${name}'")
endif()
foreach(key triangles keyframes table1 convergence segments runtime embree image wall_s)
  expect_key(scenes 0 ${key})
endforeach()
string(JSON methods LENGTH "${json}" scenes 0 table1 methods)
if(NOT methods EQUAL 6)
  message(FATAL_ERROR "Table 1 has ${methods} methods, expected 6")
endif()
foreach(i RANGE 5)
  foreach(key name label build_s average maximum per_frame)
    expect_key(scenes 0 table1 methods ${i} ${key})
  endforeach()
  string(JSON frames LENGTH "${json}" scenes 0 table1 methods ${i} per_frame)
  if(NOT frames EQUAL 6)
    message(FATAL_ERROR "Table 1 method ${i}: ${frames} frames, expected 6")
  endif()
endforeach()
string(JSON selections LENGTH "${json}" scenes 0 convergence)
if(NOT selections EQUAL 3)
  message(FATAL_ERROR "convergence: ${selections} node selections, expected 3")
endif()
string(JSON methods LENGTH "${json}" scenes 0 runtime methods)
if(NOT methods EQUAL 8)
  message(FATAL_ERROR "Table 2 has ${methods} methods, expected 8 (SAH0, SAH*, T-SAH, T-SAH x3 equal-time, x3 count mode, budget mode, two rebuilds)")
endif()
foreach(key update_ms trace_ms total_ms mrays_per_s rays_per_frame)
  expect_key(scenes 0 runtime methods 2 average ${key})
endforeach()
expect_key(scenes 0 runtime methods 2 per_frame total_ms)
expect_key(scenes 0 segments k_trees average)
expect_key(scenes 0 segments count_mode split_times)
expect_key(scenes 0 segments budget_mode trees)
expect_key(scenes 0 segments budget_mode peak_ratio_to_rebuild)
string(JSON met GET "${json}" scenes 0 segments budget_mode met)
if(NOT met)
  message(FATAL_ERROR "results.json: the budget mode missed its budget")
endif()
string(JSON name5 GET "${json}" scenes 0 runtime methods 5 name)
if(NOT name5 STREQUAL "tsah0-budget")
  message(FATAL_ERROR "results.json: runtime method 5 is '${name5}', expected tsah0-budget")
endif()
expect_key(scenes 0 embree status)
file(READ ${OUT}/results.md md)
foreach(text "# tsah bench: results" "## bench_explode" "**Table 1**" "**Table 2**" "**Segments**" "| T-SAH k=0 |"
             "| SAH-rebuild |" "CLI smoke test" "Source of the paper's figures")
  string(FIND "${md}" "${text}" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "results.md lacks '${text}'")
  endif()
endforeach()
string(JSON plots GET "${json}" plots status)
if(plots MATCHES "^skipped" AND NOT plots MATCHES "gnuplot is not installed")
  message(FATAL_ERROR "plots skipped for another reason: ${plots}")
endif()
]=])
add_test(NAME cli.bench.files
         COMMAND ${CMAKE_COMMAND} -DOUT=${W}/bench_out -P ${W}/bench_check.cmake)
set_tests_properties(cli.bench.files PROPERTIES FIXTURES_REQUIRED bench_results)

# The report alone, again from results.json, with a note added after the run.
add_test(NAME cli.bench.report_only COMMAND tsah bench --report-only --out ${W}/bench_out --note "seen later")
set_tests_properties(cli.bench.report_only PROPERTIES FIXTURES_REQUIRED bench_results FIXTURES_SETUP bench_report
  PASS_REGULAR_EXPRESSION "bench_out/results.md\n")
file(WRITE ${W}/bench_note.cmake [=[
file(READ ${OUT}/results.md md)
string(FIND "${md}" "- (added after the run with --report-only) seen later" at)
if(at EQUAL -1)
  message(FATAL_ERROR "results.md lacks the note added with --report-only")
endif()
]=])
add_test(NAME cli.bench.report_note COMMAND ${CMAKE_COMMAND} -DOUT=${W}/bench_out -P ${W}/bench_note.cmake)
set_tests_properties(cli.bench.report_note PROPERTIES FIXTURES_REQUIRED bench_report)

# Errors: one line, non-zero.
file(MAKE_DIRECTORY ${W}/bench_empty_data)
add_test(NAME cli.bench.no_scenes COMMAND tsah bench --data ${W}/bench_empty_data --out ${W}/bench_none)
set_tests_properties(cli.bench.no_scenes PROPERTIES WILL_FAIL TRUE)
add_test(NAME cli.bench.no_scenes_message COMMAND tsah bench --data ${W}/bench_empty_data --out ${W}/bench_none)
set_tests_properties(cli.bench.no_scenes_message PROPERTIES
  PASS_REGULAR_EXPRESSION "tsah: .*bench_empty_data: no animations found\n$")
add_test(NAME cli.bench.unknown_scene COMMAND tsah bench no-such-scene --data ${W}/bench_empty_data --out ${W}/bench_none)
set_tests_properties(cli.bench.unknown_scene PROPERTIES
  PASS_REGULAR_EXPRESSION "tsah: no scene 'no-such-scene': not a file or folder, and not a scene of .*bench_empty_data \\(none found\\)")
add_test(NAME cli.bench.report_only_missing COMMAND tsah bench --report-only --out ${W}/bench_none_here)
set_tests_properties(cli.bench.report_only_missing PROPERTIES PASS_REGULAR_EXPRESSION "^tsah: .*results.json")
# --layout names a layout of the chosen device (checked before any scene is read or device sought).
add_test(NAME cli.bench.layout_cwbvh_on_cpu COMMAND tsah bench --data ${W}/bench_empty_data --layout cwbvh
                                                   --out ${W}/bench_none)
set_tests_properties(cli.bench.layout_cwbvh_on_cpu PROPERTIES
  PASS_REGULAR_EXPRESSION "^tsah: --layout cwbvh is not a layout of --device cpu \\(auto, bvh2, bvh4 or bvh8\\)\n$")
add_test(NAME cli.bench.layout_bvh8_on_gpu COMMAND tsah bench --data ${W}/bench_empty_data --device cuda
                                                  --layout bvh8 --out ${W}/bench_none)
set_tests_properties(cli.bench.layout_bvh8_on_gpu PROPERTIES
  PASS_REGULAR_EXPRESSION "^tsah: --layout bvh8 is not a layout of --device cuda \\(auto, bvh2 or cwbvh\\)\n$")
add_test(NAME cli.bench.no_gpu
         COMMAND tsah bench ${W}/bench_explode.tanim --device cuda --quick --out ${W}/bench_gpu_none)
set_tests_properties(cli.bench.no_gpu PROPERTIES FIXTURES_REQUIRED bench_input
  PASS_REGULAR_EXPRESSION "^tsah: --device cuda: (this tsah was built without the CUDA runtime|no CUDA device is available on this machine)\n$")
# The GPU optimizer for the bench's trees: the same one line without CUDA or without a device.
add_test(NAME cli.bench.optimizer_cuda_no_gpu
         COMMAND tsah bench ${W}/bench_explode.tanim --optimizer cuda --quick --out ${W}/bench_gpu_optimizer_none)
set_tests_properties(cli.bench.optimizer_cuda_no_gpu PROPERTIES FIXTURES_REQUIRED bench_input
  ENVIRONMENT "CUDA_VISIBLE_DEVICES=-1"
  PASS_REGULAR_EXPRESSION "^tsah: --optimizer cuda: (this tsah was built without the CUDA runtime|no CUDA device is available on this machine)\n$")

# tsah optimize --segments K|auto: one tree-set file (.tbvh version 2); info, trace and export
# switch through it; corrupt sets are refused with one line.
add_test(NAME cli.segments.json
         COMMAND tsah optimize ${W}/bench_explode.tanim -o ${W}/seg.tbvh --segments 3 --eval-frames 12 --json)
set_tests_properties(cli.segments.json PROPERTIES FIXTURES_REQUIRED bench_input FIXTURES_SETUP bench_segments
  PASS_REGULAR_EXPRESSION "\"parts\":\\[\\{.*\"index\":0,.*\"time_start\":0\\.0\\},\\{.*\"index\":1,.*\\{.*\"index\":2,.*\"time_end\":5\\.0,.*\"segmentation\":\"count\".*\"trees\":3")
add_test(NAME cli.segments.info COMMAND tsah info ${W}/seg.tbvh)
set_tests_properties(cli.segments.info PROPERTIES FIXTURES_REQUIRED bench_segments
  PASS_REGULAR_EXPRESSION "v2 tree set.*\nset           3 trees, count segmentation, time 0 \\.\\. 5, overlap 0\n\ntree 0        used for t 0 \\.\\. [0-9.]+ .*\ntree 2        used for t [0-9.]+ \\.\\. 5 ")
add_test(NAME cli.segments.trace
         COMMAND tsah trace ${W}/bench_explode.tanim ${W}/seg.tbvh --frames 2 --width 16 --height 12 --no-images --json)
set_tests_properties(cli.segments.trace PROPERTIES FIXTURES_REQUIRED bench_segments
  PASS_REGULAR_EXPRESSION "\"time\":0\\.0,\"total_ms\":[-0-9.e]+,\"trace_ms\":[-0-9.e]+,\"trace_ms_by_type\":\\{[^}]*\\},\"tree\":0,.*\"time\":5\\.0,\"total_ms\":[-0-9.e]+,\"trace_ms\":[-0-9.e]+,\"trace_ms_by_type\":\\{[^}]*\\},\"tree\":2,.*\"trees\":3")
# Blurred frames of the set (shutter 1: every switch lies strictly inside one frame's shutter): that
# frame is traced in two parts, each pixel by the tree of its time, and counts both parts' keys (the
# switch in each): 4 or 5 where a one-tree frame has 2 or 3.
add_test(NAME cli.segments.trace_shutter
         COMMAND tsah trace ${W}/bench_explode.tanim ${W}/seg.tbvh --frames 6 --width 16 --height 12 --no-images
                 --shutter 1 --json)
set_tests_properties(cli.segments.trace_shutter PROPERTIES FIXTURES_REQUIRED bench_segments
  PASS_REGULAR_EXPRESSION "\"keys\":[45],.*\"trees\":3")
add_test(NAME cli.segments.export COMMAND tsah export ${W}/seg.tbvh ${W}/bench_explode.tanim --time 5 -o ${W}/seg_export)
set_tests_properties(cli.segments.export PROPERTIES FIXTURES_REQUIRED bench_segments
  PASS_REGULAR_EXPRESSION "tree 2 of the set's 3: the tree of this time's part \\(t [0-9.]+ \\.\\. 5\\)\n")
add_test(NAME cli.segments.corrupt
         COMMAND sh -c "head -c 400 '${W}/seg.tbvh' > '${W}/seg_bad.tbvh' && '$<TARGET_FILE:tsah>' info '${W}/seg_bad.tbvh'")
set_tests_properties(cli.segments.corrupt PROPERTIES FIXTURES_REQUIRED bench_segments
  PASS_REGULAR_EXPRESSION "^tsah: [^\n]*seg_bad.tbvh: [^\n]+\n$")
add_test(NAME cli.segments.corrupt_fails
         COMMAND sh -c "head -c 400 '${W}/seg.tbvh' > '${W}/seg_bad2.tbvh' && '$<TARGET_FILE:tsah>' trace '${W}/bench_explode.tanim' '${W}/seg_bad2.tbvh' --no-images")
set_tests_properties(cli.segments.corrupt_fails PROPERTIES FIXTURES_REQUIRED bench_segments WILL_FAIL TRUE)
add_test(NAME cli.segments.budget
         COMMAND tsah optimize ${W}/bench_explode.tanim -o ${W}/seg_budget.tbvh --segments auto --budget 1.2
                 --eval-frames 8 --reference-frames 0 --overlap 0.1)
set_tests_properties(cli.segments.budget PROPERTIES FIXTURES_REQUIRED bench_input
  PASS_REGULAR_EXPRESSION "seg_budget.tbvh: a set of [0-9]+ trees \\(budget segmentation, tsah0\\).*\nbudget 1\\.2x the per-frame optimized cost: met on every evaluation frame; peak ratio [01]\\.[0-9]+")
add_test(NAME cli.segments.text
         COMMAND tsah optimize ${W}/bench_explode.tanim -o ${W}/segtext.tbvh --segments 2 --method sah0)
set_tests_properties(cli.segments.text PROPERTIES FIXTURES_REQUIRED bench_input
  PASS_REGULAR_EXPRESSION "segtext.tbvh: a set of 2 trees \\(count segmentation, sah0\\).*\n  tree 0: t 0 \\.\\. [0-9.]+ \\(sah0\\),.*\n  tree 1: t [0-9.]+ \\.\\. 5 \\(sah0\\),.*\ncost over 50 evaluation frames, each with the tree of its part: average [0-9.]+, maximum [0-9.]+\n")
add_test(NAME cli.segments.bad_count COMMAND tsah optimize ${W}/bench_explode.tanim -o ${W}/x.tbvh --segments three)
set_tests_properties(cli.segments.bad_count PROPERTIES FIXTURES_REQUIRED bench_input
  PASS_REGULAR_EXPRESSION "^tsah: --segments expects a number of trees \\(1\\.\\.1000\\) or auto, got 'three'\n$")
add_test(NAME cli.segments.budget_needs_auto COMMAND tsah optimize ${W}/bench_explode.tanim -o ${W}/x.tbvh --budget 1.1)
set_tests_properties(cli.segments.budget_needs_auto PROPERTIES FIXTURES_REQUIRED bench_input
  PASS_REGULAR_EXPRESSION "^tsah: --budget and --budget-cost go with --segments auto\n$")
file(WRITE ${W}/seg_static.obj "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
add_test(NAME cli.segments.static COMMAND tsah optimize ${W}/seg_static.obj -o ${W}/seg_static.tbvh --segments 2)
set_tests_properties(cli.segments.static PROPERTIES
  PASS_REGULAR_EXPRESSION "^tsah: .*seg_static.obj: --segments needs an animation \\(this input has one frame\\)\n$")

# --embree-only: no Table 1, no segments; only the T-SAH tree traced in every layout (and Embree
# when it was found). A crash here once came from the segment experiment reading Table 1's rows.
add_test(NAME cli.bench.embree-only
         COMMAND tsah bench ${W}/bench_explode.tanim --embree-only --quick --width 48 --height 36 --trace-frames 2
                 --out ${W}/bench_embree_only)
set_tests_properties(cli.bench.embree-only PROPERTIES FIXTURES_REQUIRED bench_input
  PASS_REGULAR_EXPRESSION "bench_embree_only/results.json")

# --scaling: two generated sizes plus the explicit input, both optimizers; every row has its
# figures, the peak memory is the child's own (VmHWM, positive), the report and plots are listed.
add_test(NAME cli.bench.scaling
         COMMAND tsah bench --scaling --scaling-sizes 300,1200 ${W}/bench_explode.tanim --threads 2 --eval-frames 2
                 --out ${W}/scaling_out)
set_tests_properties(cli.bench.scaling PROPERTIES FIXTURES_REQUIRED bench_input FIXTURES_SETUP scaling_results
  PASS_REGULAR_EXPRESSION "scaling_out/scaling.md\n.*scaling_out/scaling.json\n")
file(WRITE ${W}/scaling_check.cmake [=[
file(READ ${OUT}/scaling.json json)
string(JSON rows LENGTH "${json}" rows)
if(NOT rows EQUAL 6)
  message(FATAL_ERROR "scaling.json: ${rows} rows, expected 3 inputs x 2 optimizers")
endif()
math(EXPR last "${rows} - 1")
foreach(i RANGE ${last})
  foreach(key triangles optimize_s command_s cpu_s peak_rss_bytes bytes_per_triangle initial_cost final_cost eval_average)
    string(JSON value GET "${json}" rows ${i} ${key})
    if(NOT value GREATER 0)
      message(FATAL_ERROR "scaling.json: rows ${i} ${key} is ${value}")
    endif()
  endforeach()
  string(JSON initial GET "${json}" rows ${i} initial_cost)
  string(JSON final GET "${json}" rows ${i} final_cost)
  if(final GREATER initial)
    message(FATAL_ERROR "scaling.json: rows ${i} ends above its start (${initial} -> ${final})")
  endif()
endforeach()
string(JSON kind GET "${json}" rows 4 kind)
string(JSON optimizer GET "${json}" rows 5 optimizer)
if(NOT kind STREQUAL "scene" OR NOT optimizer STREQUAL "parallel")
  message(FATAL_ERROR "scaling.json: row order (${kind}, ${optimizer})")
endif()
file(READ ${OUT}/scaling.md md)
if(NOT md MATCHES "\\| bench_explode \\| [0-9]+ \\| parallel \\|")
  message(FATAL_ERROR "scaling.md has no row of the explicit input")
endif()
]=])
add_test(NAME cli.bench.scaling_check COMMAND ${CMAKE_COMMAND} -DOUT=${W}/scaling_out -P ${W}/scaling_check.cmake)
set_tests_properties(cli.bench.scaling_check PROPERTIES FIXTURES_REQUIRED scaling_results)

# --segments 1 with the default --budget: a segments section without K trees; the report and the
# plots are still made (they used to end the run with json type_error 305).
add_test(NAME cli.bench.one_segment
         COMMAND tsah bench ${W}/bench_explode.tanim --quick --width 48 --height 36 --eval-frames 6 --trace-frames 2
                 --threads 2 --segments 1 --no-embree --out ${W}/bench_one_segment)
set_tests_properties(cli.bench.one_segment PROPERTIES FIXTURES_REQUIRED bench_input
  PASS_REGULAR_EXPRESSION "bench_one_segment/results.md\n" FAIL_REGULAR_EXPRESSION "type_error;tsah: ")
