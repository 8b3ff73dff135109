# CLI smoke tests for the runtime commands: optimize -> info -> export -> trace, and one-line errors.
set(W ${TSAH_CLI_WORK})

add_test(NAME cli.trace.setup.generate
         COMMAND tsah generate explode -o ${W}/trace_explode.tanim --triangles 1500 --frames 6 --seed 5)
set_tests_properties(cli.trace.setup.generate PROPERTIES FIXTURES_SETUP trace_anim)
add_test(NAME cli.trace.setup.other
         COMMAND tsah generate wave -o ${W}/trace_wave.tanim --triangles 1500 --frames 4 --seed 5)
set_tests_properties(cli.trace.setup.other PROPERTIES FIXTURES_SETUP trace_other)
add_test(NAME cli.trace.setup.optimize
         COMMAND tsah optimize ${W}/trace_explode.tanim -o ${W}/trace_explode.tbvh --frames 3 --eval-frames 5)
set_tests_properties(cli.trace.setup.optimize PROPERTIES FIXTURES_REQUIRED trace_anim FIXTURES_SETUP trace_tree)

# tsah info on a .tbvh file.
add_test(NAME cli.trace.info.json COMMAND tsah info ${W}/trace_explode.tbvh --json)
set_tests_properties(cli.trace.info.json PROPERTIES FIXTURES_REQUIRED trace_tree
  PASS_REGULAR_EXPRESSION "\"format\":\"tbvh\".*\"triangles\":[0-9]+")

# tsah export: renderer buffers and the C header.
add_test(NAME cli.trace.export COMMAND tsah export ${W}/trace_explode.tbvh ${W}/trace_explode.tanim --frame 2
                                       -o ${W}/trace_export)
set_tests_properties(cli.trace.export PROPERTIES FIXTURES_REQUIRED trace_tree FIXTURES_SETUP trace_exported
  PASS_REGULAR_EXPRESSION "wrote .*trace_export: [0-9]+ nodes, [0-9]+ Woop triangles")
add_test(NAME cli.trace.export.header COMMAND ${CMAKE_COMMAND} -E cat ${W}/trace_export/tsah_scene.h)
set_tests_properties(cli.trace.export.header PROPERTIES FIXTURES_REQUIRED trace_exported
  PASS_REGULAR_EXPRESSION "TSAH_NODE_COUNT [0-9]+u.*TSAH_ROOT_REF")
foreach(layout bvh4 bvh8)
  add_test(NAME cli.trace.export.${layout} COMMAND tsah export ${W}/trace_explode.tbvh ${W}/trace_explode.tanim --frame 2
                                                   --layout ${layout} -o ${W}/trace_export_${layout})
  set_tests_properties(cli.trace.export.${layout} PROPERTIES FIXTURES_REQUIRED trace_tree
                       FIXTURES_SETUP trace_exported_${layout}
    PASS_REGULAR_EXPRESSION "wrote .*trace_export_${layout}: [0-9]+ nodes, [0-9]+ Woop packets.*${layout} layout")
  string(SUBSTRING ${layout} 3 1 width)
  add_test(NAME cli.trace.export.${layout}.header COMMAND ${CMAKE_COMMAND} -E cat ${W}/trace_export_${layout}/tsah_scene.h)
  set_tests_properties(cli.trace.export.${layout}.header PROPERTIES FIXTURES_REQUIRED trace_exported_${layout}
    PASS_REGULAR_EXPRESSION "TSAH_WIDTH ${width}u.*TsahBvh${width}Node.*TSAH_PACKET_COUNT [0-9]+u.*TSAH_ROOT_REF")
endforeach()
add_test(NAME cli.trace.export.frame COMMAND tsah export ${W}/trace_explode.tbvh ${W}/trace_explode.tanim --frame 6
                                             -o ${W}/trace_export_bad)
set_tests_properties(cli.trace.export.frame PROPERTIES FIXTURES_REQUIRED trace_tree
  PASS_REGULAR_EXPRESSION "^tsah: --frame 6 is out of range")

# trace_on_tree(NAME REGEX ARG...): `tsah trace` of the explode animation and its tree with ARGs,
# passing when the output matches REGEX.
function(trace_on_tree name regex)
  add_test(NAME ${name} COMMAND tsah trace ${W}/trace_explode.tanim ${W}/trace_explode.tbvh ${ARGN})
  set_tests_properties(${name} PROPERTIES FIXTURES_REQUIRED trace_tree PASS_REGULAR_EXPRESSION "${regex}")
endfunction()

# tsah trace: PNG per frame and per-frame statistics.
add_test(NAME cli.trace.json COMMAND tsah trace ${W}/trace_explode.tanim ${W}/trace_explode.tbvh --frames 2
                                     --width 64 --height 48 --ao 4 --shadow 1 --out ${W}/trace_png --json)
set_tests_properties(cli.trace.json PROPERTIES FIXTURES_REQUIRED trace_tree FIXTURES_SETUP trace_png
  PASS_REGULAR_EXPRESSION
  "\"average\":{.*\"mrays_per_s\":{\"ao\":.*\"primary\":.*\"shadow\":.*\"total\":.*\"device\":\"cpu\".*\"frames\":\\[{.*\"update_ms\"")
# total_ms = update_ms + frame_ms (the whole frame, not the sum of passes that overlap on the GPU).
add_test(NAME cli.trace.totals.run COMMAND tsah trace ${W}/trace_explode.tanim ${W}/trace_explode.tbvh --frames 2
                                           --width 32 --height 24 --no-images --stats ${W}/trace_totals.json)
set_tests_properties(cli.trace.totals.run PROPERTIES FIXTURES_REQUIRED trace_tree FIXTURES_SETUP trace_totals)
add_test(NAME cli.trace.totals COMMAND ${Python3_EXECUTABLE} ${PROJECT_SOURCE_DIR}/tests/support/check_trace_totals.py
                                       ${W}/trace_totals.json)
set_tests_properties(cli.trace.totals PROPERTIES FIXTURES_REQUIRED trace_totals)
add_test(NAME cli.trace.png COMMAND ${CMAKE_COMMAND} -E md5sum ${W}/trace_png/frame_0001.png)
set_tests_properties(cli.trace.png PROPERTIES FIXTURES_REQUIRED trace_png PASS_REGULAR_EXPRESSION "frame_0001.png")
trace_on_tree(cli.trace.text "update_ms +trace_ms +total_ms.*avg +- +[0-9.]+"
              --frames 2 --width 32 --height 24 --no-images --no-ground)
foreach(method binned sweep)
  trace_on_tree(cli.trace.rebuild.${method} "\"build_ms\":[0-9.e+-]+.*\"rebuild\":\"${method}\""
                --frames 2 --width 32 --height 24 --no-images --rebuild ${method} --json)
endforeach()
foreach(layout bvh2 bvh4)
  trace_on_tree(cli.trace.layout.${layout} "\"layout\":\"${layout}\".*\"tree\":{.*\"tsah_cost\""
                --frames 1 --width 32 --height 24 --no-images --layout ${layout} --json)
endforeach()
trace_on_tree(cli.trace.layout.default "CPU threads, bvh[248]" --frames 1 --width 32 --height 24 --no-images)
# --triangles: the wide trees' triangle form, in the first line and the JSON.
trace_on_tree(cli.trace.triangles.vertices "bvh[48] \\([a-z0-9]+\\), triangles as vertex packets"
              --frames 2 --width 32 --height 24 --no-images --triangles vertices)
foreach(form woop vertices)
  trace_on_tree(cli.trace.triangles.${form}.json "\"layout\":\"bvh4\".*\"triangle_form\":\"${form}\""
                --frames 1 --width 32 --height 24 --no-images --layout bvh4 --triangles ${form} --json)
endforeach()
file(WRITE ${W}/trace_camera.json
  "{\"keys\": [{\"time\": 0, \"eye\": [0, 1, 6], \"look_at\": [0, 0, 0], \"fov\": 50},\n"
  "           {\"time\": 5, \"eye\": [6, 1, 0], \"look_at\": [0, 0, 0], \"up\": [0, 1, 0]}]}\n")
trace_on_tree(cli.trace.camera.file "camera .*trace_camera.json"
              --frames 2 --width 32 --height 24 --no-images --camera ${W}/trace_camera.json)
trace_on_tree(cli.trace.camera.args "camera command line"
              --frames 1 --width 32 --height 24 --no-images --eye 0,2,8 --look-at 0,0,0 --fov 40)

# Errors: one line, non-zero exit.
# --device cuda (built or not, with or without a GPU): trace_cuda.cmake.
add_test(NAME cli.trace.error.mismatch COMMAND tsah trace ${W}/trace_wave.tanim ${W}/trace_explode.tbvh --frames 1)
set_tests_properties(cli.trace.error.mismatch PROPERTIES FIXTURES_REQUIRED "trace_tree;trace_other"
  PASS_REGULAR_EXPRESSION "^tsah: .*trace_explode.tbvh was not built for .*trace_wave.tanim: ")
add_test(NAME cli.trace.error.mismatch.status COMMAND tsah trace ${W}/trace_wave.tanim ${W}/trace_explode.tbvh)
set_tests_properties(cli.trace.error.mismatch.status PROPERTIES FIXTURES_REQUIRED "trace_tree;trace_other"
  WILL_FAIL TRUE)
file(WRITE ${W}/trace_garbage.tbvh "TSAHBVH-this is not a tree")
add_test(NAME cli.trace.error.corrupt COMMAND tsah trace ${W}/trace_explode.tanim ${W}/trace_garbage.tbvh)
set_tests_properties(cli.trace.error.corrupt PROPERTIES FIXTURES_REQUIRED trace_anim
  PASS_REGULAR_EXPRESSION "^tsah: .*trace_garbage.tbvh: .*(bad magic|truncated)[^\n]*\n$")
trace_on_tree(cli.trace.error.eye "^tsah: --eye and --look-at go together" --eye 1,2)
file(WRITE ${W}/trace_badcamera.json "{\"eye\": [0, 0, 1], \"look_at\": [0, 0, 1]}")
trace_on_tree(cli.trace.error.camera "^tsah: .*trace_badcamera.json: camera: eye and look-at point coincide"
              --camera ${W}/trace_badcamera.json)
