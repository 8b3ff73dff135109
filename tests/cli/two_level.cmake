# Two-level scenes on the command line (docs/two-level.md): tsah optimize --structure, tsah info
# TREE SCENE, tsah trace of a version 3 tree (the same images as the flat tree's at the scene's
# frames), and the bad inputs of each.
set(W ${TSAH_CLI_WORK})
set(SCENE ${CMAKE_SOURCE_DIR}/samples/scenes/demo.json)
set(TL_TRACE --frames 21 --width 64 --height 48 --ao 2 --shadow 1)

# auto (the default for scene files) decides per object by cost (docs/two-level.md): demo.json's
# two bursts cross each other on their paths and are flattened into one animated source; the
# ground and the four pillars stay instanced (static objects are not merged into a moving source).
add_test(NAME cli.two_level.optimize.auto COMMAND tsah optimize ${SCENE} -o ${W}/tl_auto.tbvh --frames 3)
set_tests_properties(cli.two_level.optimize.auto PROPERTIES FIXTURES_SETUP tl_tree PASS_REGULAR_EXPRESSION
  "two-level scene \\(auto: 1 of 3 objects flattened by the cost estimate\\).*object 0 +'ground' +1 instance\\(s\\), static: instanced: moving objects are flattened.*object 2 +'burst' +2 instance\\(s\\), moving: flattened: flattened cost [0-9.]+ against [0-9.]+ instanced.*3 BLAS \\(2 static, 1 animated\\), 6 instances, 1 poses\nflattened +objects 'burst': one source, shown by one instance.*TLAS .*T-SAH cost.*memory .*BLAS .*MiB.*build ")
add_test(NAME cli.two_level.optimize.auto_json COMMAND tsah optimize ${SCENE} -o ${W}/tl_auto_json.tbvh --frames 3 --json)
set_tests_properties(cli.two_level.optimize.auto_json PROPERTIES PASS_REGULAR_EXPRESSION
  "\"flattened_objects\":\\[\"burst\"\\].*\"structure_choice\":\\{\"flattened_objects\":\\[2\\],\"objects\":\\[.*\"cost\":\\{\"flattened\":[0-9.]+,\"instanced\":[0-9.]+\\},\"flatten\":true,.*\"structure\":\"two-level\"")
# The decision alone (nothing built), and auto choosing a flat tree: every object of a scene of
# static one-instance objects is flattened, and the flat tree's printout states the decision.
add_test(NAME cli.two_level.info.structure COMMAND tsah info ${SCENE} --structure)
set_tests_properties(cli.two_level.info.structure PROPERTIES PASS_REGULAR_EXPRESSION
  "^auto +two-level: 1 of 3 objects flattened \\(cost estimate over 4 frames, [0-9.]+ s\\)\nobject 0 +'ground'.*object 1 +'pillars' +4 instance\\(s\\), static: instanced.*object 2 +'burst' +2 instance\\(s\\), moving: flattened")
file(WRITE ${W}/tl_single.json "{\"fps\": 10, \"time\": [0, 1], \"objects\": [
  {\"name\": \"ground\", \"file\": \"${CMAKE_SOURCE_DIR}/samples/explode/explode_0001.obj\"},
  {\"name\": \"block\", \"file\": \"${CMAKE_SOURCE_DIR}/samples/explode/explode_0001.obj\", \"transform\": {\"translate\": [0, 3, 0]}}]}")
add_test(NAME cli.two_level.optimize.auto_flat COMMAND tsah optimize ${W}/tl_single.json -o ${W}/tl_single.tbvh --frames 3)
set_tests_properties(cli.two_level.optimize.auto_flat PROPERTIES PASS_REGULAR_EXPRESSION
  "auto +flat: 2 of 2 objects flattened.*object 0 +'ground' +1 instance\\(s\\), static: flattened: one instance without a keyed path.*tl_single.tbvh: tsah[0-9]* tree, [0-9]+ triangles")
# Rule 5: three overlapping bursts are flattened, and the two small blocks kept beside them cost
# more as a second level than in one tree with them: the whole scene is flattened (a flat tree).
file(WRITE ${W}/tl_whole.json "{\"fps\": 5, \"time\": [0, 2], \"objects\": [
 {\"name\": \"burst\", \"file\": \"${CMAKE_SOURCE_DIR}/samples/explode/explode_%04d.obj\", \"time\": {\"speed\": 4, \"outside\": \"loop\"},
  \"instances\": [{\"transform\": {\"scale\": [1, 1, -1]}},
   {\"offset\": 0.3, \"path\": [{\"time\": 0, \"translate\": [-3, 0, 0]}, {\"time\": 2, \"translate\": [3, 0, 0]}]},
   {\"offset\": 0.3, \"transform\": {\"translate\": [0, 3, 0], \"rotate\": [30, 0, 0]}}]},
 {\"name\": \"block\", \"file\": \"${CMAKE_SOURCE_DIR}/samples/explode/explode_0001.obj\", \"instances\": [
   {\"transform\": {\"translate\": [0, -2, 0], \"scale\": [4, 0.3, 4]}},
   {\"transform\": {\"translate\": [4, 0, 0], \"rotate\": [0, 30, 0]}}]}]}")
add_test(NAME cli.two_level.info.structure_whole COMMAND tsah info ${W}/tl_whole.json --structure)
set_tests_properties(cli.two_level.info.structure_whole PROPERTIES PASS_REGULAR_EXPRESSION
  "^auto +flat: 2 of 2 objects flattened.*object 0 +'burst' +3 instance\\(s\\), moving: flattened: flattened cost.*object 1 +'block' +2 instance\\(s\\), static: flattened with the whole scene: the whole scene flattened costs [0-9.]+ against [0-9.]+ for the two levels decided per object")
add_test(NAME cli.two_level.info.structure_whole_json COMMAND tsah info ${W}/tl_whole.json --structure --json)
set_tests_properties(cli.two_level.info.structure_whole_json PROPERTIES PASS_REGULAR_EXPRESSION
  "\"structure\":\"flat\",\"whole_scene_cost\":\\{\"decided\":[0-9.]+,\"flattened\":[0-9.]+\\}")
add_test(NAME cli.two_level.optimize.json
         COMMAND tsah optimize ${SCENE} -o ${W}/tl_asked.tbvh --frames 3 --structure two-level --json)
set_tests_properties(cli.two_level.optimize.json PROPERTIES FIXTURES_SETUP tl_asked PASS_REGULAR_EXPRESSION
  "\"blas\":\\{\"animated\":1,\"count\":3,\"static\":2\\}.*\"instances\":7,.*\"peak_rss_bytes\":[1-9][0-9]*(\\.[0-9]*)?,.*\"poses\":2,.*\"structure_rule\":\"asked for")
# The wall time of every phase, and --reproducible: build times written as 0, so two builds give
# the same bytes, on all cores and on one (--threads 1 holds every phase to one thread).
add_test(NAME cli.two_level.optimize.phases
         COMMAND tsah optimize ${SCENE} -o ${W}/tl_phases.tbvh --frames 3 --structure two-level --reproducible
                 --optimizer parallel)
set_tests_properties(cli.two_level.optimize.phases PROPERTIES FIXTURES_SETUP tl_phases PASS_REGULAR_EXPRESSION
  "BLAS 0 .* built in [0-9.]+ s.*\nphases +load [0-9.]+ s, blas [0-9.]+ s, check [0-9.]+ s, instances [0-9.]+ s, tlas [0-9.]+ s, costs [0-9.]+ s, save [0-9.]+ s\n")
add_test(NAME cli.two_level.optimize.phases_json
         COMMAND tsah optimize ${SCENE} -o ${W}/tl_phases_2.tbvh --frames 3 --structure two-level --reproducible
                 --optimizer parallel --threads 1 --json)
set_tests_properties(cli.two_level.optimize.phases_json PROPERTIES FIXTURES_SETUP tl_phases PASS_REGULAR_EXPRESSION
  "\"build_s\":[0-9.e-]+,.*\"phases\":\\[\\{\"name\":\"load\",\"seconds\":[0-9.e-]+\\},\\{\"name\":\"blas\",")
add_test(NAME cli.two_level.optimize.reproducible
         COMMAND ${CMAKE_COMMAND} -E compare_files ${W}/tl_phases.tbvh ${W}/tl_phases_2.tbvh)
set_tests_properties(cli.two_level.optimize.reproducible PROPERTIES FIXTURES_REQUIRED tl_phases)
add_test(NAME cli.two_level.optimize.flat COMMAND tsah optimize ${SCENE} -o ${W}/tl_flat.tbvh --frames 3 --structure flat)
set_tests_properties(cli.two_level.optimize.flat PROPERTIES FIXTURES_SETUP tl_flat
  PASS_REGULAR_EXPRESSION "tl_flat.tbvh: tsah0 tree, 12240 triangles")

add_test(NAME cli.two_level.info COMMAND tsah info ${W}/tl_auto.tbvh ${SCENE})
set_tests_properties(cli.two_level.info PROPERTIES FIXTURES_REQUIRED tl_tree PASS_REGULAR_EXPRESSION
  "\\.tbvh version 3.*3 BLAS \\(2 static, 1 animated\\), 6 instances, 1 poses\nflattened +objects 'burst': one source, shown by one instance.*TLAS .*over 21 scene frames.*BLAS 2 +animated.*memory ")
add_test(NAME cli.two_level.info.json COMMAND tsah info ${W}/tl_auto.tbvh ${SCENE} --json)
set_tests_properties(cli.two_level.info.json PROPERTIES FIXTURES_REQUIRED tl_tree PASS_REGULAR_EXPRESSION
  "\"bytes\":\\{\"blas\":[1-9][0-9]*,\"tlas\":[1-9][0-9]*,\"total\".*\"scene_frames\":21,.*\"version\":3")

# The two-level trace (TLAS refitted, and rebuilt every frame) gives the flat tree's images, byte for
# byte, at the scene's 21 frames (the library allows ties between coincident surfaces; this scene
# has none). So do the other triangle forms (--triangles): the flat tree as vertex packets, the
# two-level poses as Woop packets.
add_test(NAME cli.two_level.trace.flat COMMAND tsah trace ${SCENE} ${W}/tl_flat.tbvh ${TL_TRACE} --out ${W}/tl_img_flat)
set_tests_properties(cli.two_level.trace.flat PROPERTIES FIXTURES_REQUIRED tl_flat FIXTURES_SETUP tl_img_flat)
foreach(tlas refit rebuild)
  add_test(NAME cli.two_level.trace.${tlas}
           COMMAND tsah trace ${SCENE} ${W}/tl_auto.tbvh ${TL_TRACE} --tlas ${tlas} --out ${W}/tl_img_${tlas} --json)
  set_tests_properties(cli.two_level.trace.${tlas} PROPERTIES FIXTURES_REQUIRED tl_tree FIXTURES_SETUP tl_img_${tlas}
    PASS_REGULAR_EXPRESSION "\"structure\":\"two-level\".*\"tlas_update\":\"${tlas}\"")
endforeach()
add_test(NAME cli.two_level.trace.flat_vertices
         COMMAND tsah trace ${SCENE} ${W}/tl_flat.tbvh ${TL_TRACE} --triangles vertices --out ${W}/tl_img_flat_vertices --json)
set_tests_properties(cli.two_level.trace.flat_vertices PROPERTIES FIXTURES_REQUIRED tl_flat
  FIXTURES_SETUP tl_img_flat_vertices PASS_REGULAR_EXPRESSION "\"triangle_form\":\"vertices\"")
add_test(NAME cli.two_level.trace.poses_woop
         COMMAND tsah trace ${SCENE} ${W}/tl_auto.tbvh ${TL_TRACE} --triangles woop --out ${W}/tl_img_poses_woop --json)
set_tests_properties(cli.two_level.trace.poses_woop PROPERTIES FIXTURES_REQUIRED tl_tree
  FIXTURES_SETUP tl_img_poses_woop PASS_REGULAR_EXPRESSION "\"pose_triangle_form\":\"woop\"")
foreach(run refit rebuild flat_vertices poses_woop)
  foreach(frame 0000 0007 0013 0020)
    add_test(NAME cli.two_level.trace.${run}.same_image.${frame}
             COMMAND ${CMAKE_COMMAND} -E compare_files ${W}/tl_img_flat/frame_${frame}.png ${W}/tl_img_${run}/frame_${frame}.png)
    set_tests_properties(cli.two_level.trace.${run}.same_image.${frame} PROPERTIES
      FIXTURES_REQUIRED "tl_img_flat;tl_img_${run}")
  endforeach()
endforeach()

# Motion blur on the CPU (docs/motion-blur.md, "Two-level scenes"): --shutter renders blurred frames
# (the keys in the JSON); frames 7 and 13 differ from the instant's (the burst moves), and
# --shutter 0 is the instant, byte for byte.
add_test(NAME cli.two_level.trace.shutter
         COMMAND tsah trace ${SCENE} ${W}/tl_auto.tbvh ${TL_TRACE} --shutter 0.5 --out ${W}/tl_img_shutter --json)
set_tests_properties(cli.two_level.trace.shutter PROPERTIES FIXTURES_REQUIRED tl_tree FIXTURES_SETUP tl_img_shutter
  PASS_REGULAR_EXPRESSION "\"keys\":[2-9].*\"shutter\":\\{\"fraction\":0.5,\"mode\":\"centered\"\\}.*\"structure\":\"two-level\"")
add_test(NAME cli.two_level.trace.shutter_zero
         COMMAND tsah trace ${SCENE} ${W}/tl_auto.tbvh ${TL_TRACE} --shutter 0 --out ${W}/tl_img_shutter_zero)
set_tests_properties(cli.two_level.trace.shutter_zero PROPERTIES FIXTURES_REQUIRED tl_tree FIXTURES_SETUP tl_img_shutter_zero)
foreach(frame 0007 0013)
  add_test(NAME cli.two_level.trace.shutter.blurred_image.${frame}
           COMMAND ${CMAKE_COMMAND} -E compare_files ${W}/tl_img_refit/frame_${frame}.png ${W}/tl_img_shutter/frame_${frame}.png)
  set_tests_properties(cli.two_level.trace.shutter.blurred_image.${frame} PROPERTIES WILL_FAIL TRUE
    FIXTURES_REQUIRED "tl_img_refit;tl_img_shutter")
  add_test(NAME cli.two_level.trace.shutter_zero.same_image.${frame}
           COMMAND ${CMAKE_COMMAND} -E compare_files ${W}/tl_img_refit/frame_${frame}.png ${W}/tl_img_shutter_zero/frame_${frame}.png)
  set_tests_properties(cli.two_level.trace.shutter_zero.same_image.${frame} PROPERTIES
    FIXTURES_REQUIRED "tl_img_refit;tl_img_shutter_zero")
endforeach()

# Bad inputs: one line naming the file or option, exit 1 (data) or 2 (usage)
# (tsah_expect_error: tests/cli/hardening.cmake).
function(tl_error name code regex)
  tsah_expect_error(${name} ${code} "${regex}" ${ARGN})
  set_tests_properties(${name} PROPERTIES FIXTURES_REQUIRED "tl_tree;tl_flat")
endfunction()
file(READ ${SCENE} tl_other)
string(REPLACE "../explode" "${CMAKE_SOURCE_DIR}/samples/explode" tl_other "${tl_other}")
string(REPLACE "\"offset\": 0.5" "\"offset\": 0.25" tl_other "${tl_other}")
file(WRITE ${W}/tl_other_scene.json "${tl_other}")
tl_error(cli.two_level.error.wrong_scene 1 "[^\n]*tl_auto.tbvh was not built for [^\n]*tl_other_scene.json"
         trace ${W}/tl_other_scene.json ${W}/tl_auto.tbvh --frames 1 --no-images)
tl_error(cli.two_level.error.info_without_scene 2 "[^\n]*tl_auto.tbvh holds a two-level scene \\(.tbvh version 3\\): give its scene too"
         info ${W}/tl_auto.tbvh)
tl_error(cli.two_level.error.tlas_flat 2 "--tlas goes with a two-level tree[^\n]*tl_flat.tbvh is a flat tree"
         trace ${SCENE} ${W}/tl_flat.tbvh --tlas rebuild --frames 1 --no-images)
tl_error(cli.two_level.error.trace_rebuild 2 "[^\n]*tl_auto.tbvh holds a two-level scene: it is traced without --devices, --rebuild"
         trace ${SCENE} ${W}/tl_auto.tbvh --rebuild sweep --frames 1 --no-images)
tl_error(cli.two_level.error.not_a_scene 2 "--structure two-level needs a scene file[^\n]*explode is one animation"
         optimize ${CMAKE_SOURCE_DIR}/samples/explode -o ${W}/tl_bad.tbvh --structure two-level)
tl_error(cli.two_level.error.info_structure 2 "--structure goes with a scene file alone: tsah info SCENE --structure"
         info ${CMAKE_SOURCE_DIR}/samples/explode --structure)
tl_error(cli.two_level.error.segments 2 "--structure two-level builds one T-SAH tree per source and the top level: it does not go with --segments"
         optimize ${SCENE} -o ${W}/tl_bad.tbvh --structure two-level --segments 2)

tl_error(cli.two_level.error.tlas_trees 2 "--tlas-trees expects a number of trees \\(1..4096\\) or auto, got 'many'"
         optimize ${SCENE} -o ${W}/tl_bad.tbvh --tlas-trees many)
tl_error(cli.two_level.error.tlas_trees_flat 2 "--tlas-trees and --tlas-budget shape the top level of two levels: not with --structure flat"
         optimize ${SCENE} -o ${W}/tl_bad.tbvh --structure flat --tlas-trees 2)
tl_error(cli.two_level.error.tlas_budget 2 "--tlas-budget goes with --tlas-trees auto"
         optimize ${SCENE} -o ${W}/tl_bad.tbvh --tlas-trees 2 --tlas-budget 1.2)
tl_error(cli.two_level.error.tlas_trees_animation 2 "--tlas-trees and --tlas-budget shape the top level of two levels: [^\n]*explode is one animation, not a scene file"
         optimize ${CMAKE_SOURCE_DIR}/samples/explode -o ${W}/tl_bad.tbvh --tlas-trees 3)
tl_error(cli.two_level.error.tlas_trees_segments 2 "--tlas-trees and --tlas-budget shape the top level of two levels: not with --segments"
         optimize ${SCENE} -o ${W}/tl_bad.tbvh --segments 2 --tlas-budget 1.2)
# TLAS trees per part of the scene's time: 4 parts of demo.json's 21 frames, written, described by
# tsah info and traced to the flat tree's images (the TLAS switches at frames 5, 10 and 15).
add_test(NAME cli.two_level.optimize.tlas_trees
         COMMAND tsah optimize ${SCENE} -o ${W}/tl_parts.tbvh --frames 3 --structure two-level --tlas-trees 4 --json)
set_tests_properties(cli.two_level.optimize.tlas_trees PROPERTIES FIXTURES_SETUP tl_parts PASS_REGULAR_EXPRESSION
  "\"tlas\":\\{\"cost\":[0-9.]+,\"frame_cost\":\\{[^}]*\\},\"nodes\":[0-9]+,\"ranges\":\\[\\[0\\.0,0\\.5\\],\\[0\\.5,1\\.0\\],\\[1\\.0,1\\.5\\],\\[1\\.5,2\\.0\\]\\],\"trees\":4\\}")
add_test(NAME cli.two_level.info.tlas_trees COMMAND tsah info ${W}/tl_parts.tbvh ${SCENE})
set_tests_properties(cli.two_level.info.tlas_trees PROPERTIES FIXTURES_REQUIRED tl_parts PASS_REGULAR_EXPRESSION
  "TLAS +4 trees \\(one per part of the scene's time\\), [0-9]+ nodes; T-SAH cost")
add_test(NAME cli.two_level.trace.tlas_trees
         COMMAND tsah trace ${SCENE} ${W}/tl_parts.tbvh ${TL_TRACE} --out ${W}/tl_img_parts)
set_tests_properties(cli.two_level.trace.tlas_trees PROPERTIES FIXTURES_REQUIRED tl_parts FIXTURES_SETUP tl_parts_images)
foreach(frame 0000 0005 0013 0020)
  add_test(NAME cli.two_level.trace.tlas_trees.same_image.${frame}
           COMMAND ${CMAKE_COMMAND} -E compare_files ${W}/tl_img_flat/frame_${frame}.png ${W}/tl_img_parts/frame_${frame}.png)
  set_tests_properties(cli.two_level.trace.tlas_trees.same_image.${frame} PROPERTIES
    FIXTURES_REQUIRED "tl_img_flat;tl_parts_images")
endforeach()

# --device cuda: the GPU two-level runtime and renderer (docs/two-level.md). What it does not serve
# is refused before the device is looked for, so the message is the same on every machine: the
# TLAS rebuilt every frame by the CPU's sweep SAH (a CPU reference).
tl_error(cli.two_level.error.cuda_tlas_rebuild 2 "--tlas rebuild builds a sweep-SAH TLAS on the CPU: with --device cuda use --tlas lbvh or hlbvh-sah"
         trace ${SCENE} ${W}/tl_auto.tbvh --device cuda --tlas rebuild --frames 1 --no-images)
# The BLAS in the compressed layout on the GPU.
add_test(NAME cli.two_level.trace.cuda_cwbvh
         COMMAND tsah trace ${SCENE} ${W}/tl_auto.tbvh ${TL_TRACE} --device cuda --layout cwbvh --out ${W}/tl_img_cuda_cwbvh --json)
set_tests_properties(cli.two_level.trace.cuda_cwbvh PROPERTIES FIXTURES_REQUIRED tl_tree
  PASS_REGULAR_EXPRESSION "\"layout\":\"cwbvh\""
  SKIP_REGULAR_EXPRESSION "no CUDA device found|GPU runtime is not built")
# End to end on the GPU: demo.json's frames traced and rendered on the device (skipped on a machine
# without a GPU or a tsah without the GPU runtime).
add_test(NAME cli.two_level.trace.cuda
         COMMAND tsah trace ${SCENE} ${W}/tl_auto.tbvh ${TL_TRACE} --device cuda --out ${W}/tl_img_cuda --json)
set_tests_properties(cli.two_level.trace.cuda PROPERTIES FIXTURES_REQUIRED tl_tree
  PASS_REGULAR_EXPRESSION "\"structure\":\"two-level\".*\"timer\":\"CUDA events.*\"tlas_update\":\"refit\""
  SKIP_REGULAR_EXPRESSION "no CUDA device found|GPU runtime is not built")
# Motion blur on the GPU: blurred frames (keys per frame) rendered on the device.
add_test(NAME cli.two_level.trace.cuda_shutter
         COMMAND tsah trace ${SCENE} ${W}/tl_auto.tbvh ${TL_TRACE} --device cuda --shutter 0.5 --out ${W}/tl_img_cuda_shutter --json)
set_tests_properties(cli.two_level.trace.cuda_shutter PROPERTIES FIXTURES_REQUIRED tl_tree
  PASS_REGULAR_EXPRESSION "\"keys\":[2-9].*\"shutter\":\\{\"fraction\":0.5,\"mode\":\"centered\"\\}.*\"structure\":\"two-level\".*\"timer\":\"CUDA events \\(device time\\); updates: host wall time\""
  SKIP_REGULAR_EXPRESSION "no CUDA device found|GPU runtime is not built")
# Blurred frames with the BLAS in the compressed layout (the held poses and static BLAS traced in it).
add_test(NAME cli.two_level.trace.cuda_cwbvh_shutter
         COMMAND tsah trace ${SCENE} ${W}/tl_auto.tbvh ${TL_TRACE} --device cuda --layout cwbvh --shutter 0.5 --no-images --json)
set_tests_properties(cli.two_level.trace.cuda_cwbvh_shutter PROPERTIES FIXTURES_REQUIRED tl_tree
  PASS_REGULAR_EXPRESSION "\"keys\":[2-9].*\"layout\":\"cwbvh\".*\"shutter\":\\{\"fraction\":0.5,"
  SKIP_REGULAR_EXPRESSION "no CUDA device found|GPU runtime is not built")
# The TLAS built every frame on the GPU (LBVH), traced and rendered on the device; refused on the CPU.
add_test(NAME cli.two_level.trace.cuda_tlas_lbvh
         COMMAND tsah trace ${SCENE} ${W}/tl_auto.tbvh ${TL_TRACE} --device cuda --tlas lbvh --no-images --json)
set_tests_properties(cli.two_level.trace.cuda_tlas_lbvh PROPERTIES FIXTURES_REQUIRED tl_tree
  PASS_REGULAR_EXPRESSION "\"structure\":\"two-level\".*\"tlas_update\":\"lbvh\""
  SKIP_REGULAR_EXPRESSION "no CUDA device found|GPU runtime is not built")
tl_error(cli.two_level.error.cpu_tlas_lbvh 2 "--tlas lbvh rebuilds the TLAS on the GPU: use it with --device cuda"
         trace ${SCENE} ${W}/tl_auto.tbvh --tlas lbvh --frames 1 --no-images)
