# tsah bench --two-level-only: the two-level part of scene files (docs/bench.md) on small scenes:
# demo.json given by name and a scene of the folder given with --scene-dir (mirrored, rotated,
# looping instances of an animated source with offsets, a keyed path, two static instances), a few
# frames at a tiny resolution; results.json has every field, the two-level runtime and Embree
# instancing agree with the flat tree on at least 99.9% of the rays; bad --scene-dir and option
# mixes give one line.
set(W ${TSAH_CLI_WORK})
set(EXPLODE ${CMAKE_SOURCE_DIR}/samples/explode)
file(MAKE_DIRECTORY ${W}/tl_bench_scenes ${W}/tl_bench_no_scenes)
file(WRITE ${W}/tl_bench_scenes/paths.json "{\"fps\": 5, \"time\": [0, 2], \"objects\": [
 {\"name\": \"burst\", \"file\": \"${EXPLODE}/explode_%04d.obj\", \"time\": {\"speed\": 4, \"outside\": \"loop\"},
  \"instances\": [
   {\"transform\": {\"scale\": [1, 1, -1]}},
   {\"offset\": 0.3, \"path\": [{\"time\": 0, \"translate\": [-3, 0, 0]}, {\"time\": 2, \"translate\": [3, 0, 0], \"rotate\": [0, 90, 0]}]},
   {\"offset\": 0.3, \"transform\": {\"translate\": [0, 3, 0], \"rotate\": [30, 0, 0]}}]},
 {\"name\": \"block\", \"file\": \"${EXPLODE}/explode_0001.obj\", \"instances\": [
   {\"transform\": {\"translate\": [0, -2, 0], \"scale\": [4, 0.3, 4]}},
   {\"transform\": {\"translate\": [4, 0, 0], \"rotate\": [0, 30, 0]}}]}]}\n")
file(WRITE ${W}/tl_bench_scenes/notes.json "{\"not\": \"a scene\"}\n")
file(WRITE ${W}/tl_bench_no_scenes/notes.json "{\"not\": \"a scene\"}\n")

add_test(NAME cli.bench.two_level
         COMMAND tsah bench ${CMAKE_SOURCE_DIR}/samples/scenes/demo.json --scene-dir ${W}/tl_bench_scenes
                 --two-level-only --quick --width 48 --height 36 --trace-frames 4 --ao 2 --threads 2
                 --out ${W}/tl_bench_out)
set_tests_properties(cli.bench.two_level PROPERTIES FIXTURES_SETUP tl_bench_results
  PASS_REGULAR_EXPRESSION "tl_bench_out/results.md\n.*tl_bench_out/results.json\n")

file(WRITE ${W}/tl_bench_check.cmake [=[
file(READ ${OUT}/results.json json)
macro(expect_key)
  string(JSON value ERROR_VARIABLE error GET "${json}" ${ARGN})
  if(error)
    message(FATAL_ERROR "results.json: ${ARGN}: ${error}")
  endif()
endmacro()
string(JSON scenes LENGTH "${json}" scenes)
if(NOT scenes EQUAL 2)
  message(FATAL_ERROR "results.json: ${scenes} scenes, expected demo and paths")
endif()
string(JSON embree GET "${json}" versions embree)
foreach(s 0 1)
  foreach(key table1 runtime embree)
    string(JSON value ERROR_VARIABLE error GET "${json}" scenes ${s} ${key})
    if(NOT error)
      message(FATAL_ERROR "results.json: scene ${s} has ${key}: --two-level-only runs the two-level part alone")
    endif()
  endforeach()
  foreach(key scene_file instances sources static_sources poses triangles structure_bytes frames frame_times width
              height ao_rays shadow_rays layout threads embree_status two_level_runtime_bytes ratios methods wall_s)
    expect_key(scenes ${s} two_level ${key})
  endforeach()
  foreach(structure flat two_level)
    foreach(key tree wall_s build_s cpu_s peak_rss_bytes peak_source)
      expect_key(scenes ${s} two_level optimize ${structure} ${key})
    endforeach()
    string(JSON peak GET "${json}" scenes ${s} two_level optimize ${structure} peak_rss_bytes)
    string(JSON tree GET "${json}" scenes ${s} two_level optimize ${structure} tree)
    string(JSON kind GET "${json}" scenes ${s} two_level optimize ${structure} structure)
    string(REPLACE "_" "-" expected_kind "${structure}")
    if(NOT kind STREQUAL expected_kind)
      message(FATAL_ERROR "scene ${s}: optimize ${structure} built a ${kind} structure")
    endif()
    # The command's own high-water mark: a child's ru_maxrss would count the bench process too.
    string(JSON source GET "${json}" scenes ${s} two_level optimize ${structure} peak_source)
    if(NOT source STREQUAL "VmHWM of tsah optimize")
      message(FATAL_ERROR "scene ${s}: optimize ${structure}: peak memory from ${source}")
    endif()
    if(NOT peak GREATER 1000000 OR NOT EXISTS "${tree}")
      message(FATAL_ERROR "scene ${s}: optimize ${structure}: peak ${peak} bytes, tree ${tree}")
    endif()
  endforeach()
  string(JSON frames GET "${json}" scenes ${s} two_level frames)
  if(NOT frames EQUAL 4)
    message(FATAL_ERROR "scene ${s}: ${frames} traced frames, expected 4")
  endif()
  expect_key(scenes ${s} two_level ratios two_level_rate_over_flat_rate)
  expect_key(scenes ${s} two_level ratios two_level_total_over_flat_total)
  string(JSON methods LENGTH "${json}" scenes ${s} two_level methods)
  set(expected 2)
  set(names flat two-level)
  if(embree MATCHES "^[0-9]")  # built with Embree: its instancing is the third method
    set(expected 3)
    list(APPEND names embree-instanced)
    expect_key(scenes ${s} two_level ratios two_level_total_over_embree_total)
    expect_key(scenes ${s} two_level embree_build ms)
    expect_key(scenes ${s} two_level methods 2 extra agreement_with_two_level fraction)
    expect_key(scenes ${s} two_level methods 2 extra pose_refits_per_frame)
  endif()
  if(NOT methods EQUAL expected)
    message(FATAL_ERROR "scene ${s}: ${methods} methods, expected ${expected}")
  endif()
  math(EXPR last "${methods} - 1")
  foreach(m RANGE ${last})
    list(GET names ${m} name)
    string(JSON got GET "${json}" scenes ${s} two_level methods ${m} name)
    if(NOT got STREQUAL name)
      message(FATAL_ERROR "scene ${s}: method ${m} is ${got}, expected ${name}")
    endif()
    foreach(key update_ms trace_ms total_ms mrays_per_s rays_per_frame)
      expect_key(scenes ${s} two_level methods ${m} average ${key})
    endforeach()
    string(JSON rate GET "${json}" scenes ${s} two_level methods ${m} average mrays_per_s total)
    if(NOT rate GREATER 0)
      message(FATAL_ERROR "scene ${s}: method ${name} traced at ${rate} MRays/s")
    endif()
    if(m GREATER 0)
      string(JSON fraction GET "${json}" scenes ${s} two_level methods ${m} extra agreement_with_flat fraction)
      string(JSON rays GET "${json}" scenes ${s} two_level methods ${m} extra agreement_with_flat rays)
      if(fraction LESS 0.999 OR NOT rays GREATER 1000)
        message(FATAL_ERROR "scene ${s}: ${name} agrees with the flat tree on ${fraction} of ${rays} rays")
      endif()
    endif()
  endforeach()
  expect_key(scenes ${s} two_level methods 1 extra blas_refits_per_frame)
  expect_key(scenes ${s} two_level methods 1 extra tlas_rebuild_ms_per_frame)
endforeach()
string(JSON only GET "${json}" options two_level_only)
if(NOT only)
  message(FATAL_ERROR "results.json: options.two_level_only is ${only}")
endif()
file(READ ${OUT}/results.md md)
# auto's structure (docs/two-level.md): demo's two bursts are flattened into one source; paths'
# three bursts (two of them overlapping) too, and its two small blocks with them (the whole scene
# flattened: a flat tree), so the bench keeps every object as instances there (5).
string(JSON chose ERROR_VARIABLE error GET "${json}" scenes 1 two_level optimize two_level auto_chose)
if(NOT chose STREQUAL "flat")
  message(FATAL_ERROR "results.json: paths: auto_chose is '${chose}' (${error}), expected flat")
endif()
foreach(text "## demo" "## paths" "**Two-level part** (6 instances of 3 sources (2 static), 1 poses"
             "## Two-level scenes: flat, two-level and Embree instancing" "| paths | 5 |")
  string(FIND "${md}" "${text}" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "results.md lacks '${text}'")
  endif()
endforeach()
]=])
add_test(NAME cli.bench.two_level_files COMMAND ${CMAKE_COMMAND} -DOUT=${W}/tl_bench_out -P ${W}/tl_bench_check.cmake)
set_tests_properties(cli.bench.two_level_files PROPERTIES FIXTURES_REQUIRED tl_bench_results)

# A scene whose objects auto all flattens (two animated objects shown once, without paths: a flat
# tree): the two-level part keeps every object instanced instead, and says so.
file(MAKE_DIRECTORY ${W}/tl_bench_single)
file(WRITE ${W}/tl_bench_single/single.json "{\"fps\": 5, \"time\": [0, 1], \"objects\": [
 {\"name\": \"burst\", \"file\": \"${EXPLODE}/explode_%04d.obj\"},
 {\"name\": \"echo\", \"file\": \"${EXPLODE}/explode_%04d.obj\", \"offset\": 0.5, \"transform\": {\"translate\": [0, -4, 0]}}]}\n")
add_test(NAME cli.bench.two_level_auto_flat
         COMMAND tsah bench ${W}/tl_bench_single/single.json --two-level-only --quick --width 32 --height 24
                 --trace-frames 1 --ao 1 --threads 2 --out ${W}/tl_bench_single_out)
set_tests_properties(cli.bench.two_level_auto_flat PROPERTIES FIXTURES_SETUP tl_bench_single)
add_test(NAME cli.bench.two_level_auto_flat_files COMMAND ${CMAKE_COMMAND} -E cat ${W}/tl_bench_single_out/results.json)
set_tests_properties(cli.bench.two_level_auto_flat_files PROPERTIES FIXTURES_REQUIRED tl_bench_single
  PASS_REGULAR_EXPRESSION "\"auto_chose\": *\"flat\"")

# Bad --scene-dir and option mixes: one line naming the folder or the options, usage error (exit 2);
# tests/support/expect_error.cmake checks the exit status and the single line.
function(tl_bench_error name regex)
  string(REPLACE ";" "@@" args "${ARGN}")
  add_test(NAME ${name} COMMAND ${CMAKE_COMMAND} -DTSAH=$<TARGET_FILE:tsah> -DEXPECT_CODE=2 "-DEXPECT=${regex}"
           "-DARGS=${args}" -DWORKDIR=${W} -P ${PROJECT_SOURCE_DIR}/tests/support/expect_error.cmake)
endfunction()
tl_bench_error(cli.bench.scene_dir_missing
  "^tsah: [^\n]*tl_no_such_folder: cannot read the scene folder \\([^\n]+\\)\n$"
  bench --scene-dir ${W}/tl_no_such_folder --two-level-only --out ${W}/tl_bench_none)
tl_bench_error(cli.bench.scene_dir_without_scenes
  "^tsah: [^\n]*tl_bench_no_scenes: no scene files \\(\\*\\.json with \"objects\", docs/scenes\\.md\\) in the scene folder\n$"
  bench --data ${W}/tl_bench_no_scenes --scene-dir ${W}/tl_bench_no_scenes --out ${W}/tl_bench_none)
tl_bench_error(cli.bench.two_level_only_no_scene_files
  "^tsah: --two-level-only benches scene files \\(docs/scenes\\.md\\): give --scene-dir DIR or scene files\n$"
  bench ${EXPLODE}/explode_0001.obj --two-level-only --out ${W}/tl_bench_none)
tl_bench_error(cli.bench.two_level_only_cuda
  "^tsah: --two-level-only runs the two-level part alone, on the CPU: not with --embree-only, --motion-blur-only or --device cuda\n$"
  bench --scene-dir ${W}/tl_bench_scenes --two-level-only --device cuda --out ${W}/tl_bench_none)
# --two-level-gpu: the GPU two-level bench needs a CUDA build and a device (checked before any scene).
tl_bench_error(cli.bench.two_level_gpu_no_gpu
  "^tsah: --two-level-gpu: (this tsah was built without the CUDA runtime|no CUDA device is available on this machine)\n$"
  bench --scene-dir ${W}/tl_bench_scenes --two-level-only --two-level-gpu --out ${W}/tl_bench_none)
set_tests_properties(cli.bench.two_level_gpu_no_gpu PROPERTIES ENVIRONMENT "CUDA_VISIBLE_DEVICES=-1")

# Without --two-level-only a scene file gets the rest of the bench and the two-level part.
add_test(NAME cli.bench.two_level_with_the_rest
         COMMAND tsah bench ${CMAKE_SOURCE_DIR}/samples/scenes/demo.json --quick --width 32 --height 24 --eval-frames 4
                 --trace-frames 2 --threads 2 --no-convergence --segments 1 --budget 0 --out ${W}/tl_bench_all)
set_tests_properties(cli.bench.two_level_with_the_rest PROPERTIES FIXTURES_SETUP tl_bench_all
  PASS_REGULAR_EXPRESSION "tl_bench_all/results.md\n")
file(WRITE ${W}/tl_bench_all_check.cmake [=[
file(READ ${OUT}/results.json json)
foreach(key table1 runtime embree "two_level;methods;1;average;total_ms")
  string(JSON value ERROR_VARIABLE error GET "${json}" scenes 0 ${key})
  if(error)
    message(FATAL_ERROR "results.json: scenes 0 ${key}: ${error}")
  endif()
endforeach()
]=])
add_test(NAME cli.bench.two_level_with_the_rest_files
         COMMAND ${CMAKE_COMMAND} -DOUT=${W}/tl_bench_all -P ${W}/tl_bench_all_check.cmake)
set_tests_properties(cli.bench.two_level_with_the_rest_files PROPERTIES FIXTURES_REQUIRED tl_bench_all)
