# tsah trace --shutter: motion-blurred frames (refit at the shutter's keys, per-pixel times) and the
# usage errors of the option.
set(W ${TSAH_CLI_WORK})

# 4 frames of a 6-keyframe animation (the CPU's default layout): a centered shutter of 0.9 of the frame interval (1.5 keyframe
# intervals) holds two keyframes in the middle frames (4 keys), one at the clamped ends (2 keys).
add_test(NAME cli.trace.shutter.json
         COMMAND tsah trace ${W}/trace_explode.tanim ${W}/trace_explode.tbvh --frames 4 --width 32 --height 24
                 --no-images --shutter 0.9 --json)
set_tests_properties(cli.trace.shutter.json PROPERTIES FIXTURES_REQUIRED trace_tree
  PASS_REGULAR_EXPRESSION "\"keys\":2.*\"keys\":4.*\"layout\":\"bvh[248]\".*\"shutter\":\\{\"fraction\":0.9,\"mode\":\"centered\"\\}")
add_test(NAME cli.trace.shutter.summary
         COMMAND tsah trace ${W}/trace_explode.tanim ${W}/trace_explode.tbvh --frames 3 --width 32 --height 24
                 --no-images --shutter 0.5 --shutter-mode open)
set_tests_properties(cli.trace.shutter.summary PROPERTIES FIXTURES_REQUIRED trace_tree
  PASS_REGULAR_EXPRESSION "refit, shutter 0.5 open")

# The same frames on the GPU where this machine has one (the key counts are the CPU's); without a GPU
# the one-line error.
if(TSAH_HAVE_CUDA)
  add_test(NAME cli.trace.shutter.cuda
           COMMAND tsah trace ${W}/trace_explode.tanim ${W}/trace_explode.tbvh --device cuda --frames 4 --width 32
                   --height 24 --no-images --shutter 0.9 --json)
  set_tests_properties(cli.trace.shutter.cuda PROPERTIES FIXTURES_REQUIRED trace_tree
    PASS_REGULAR_EXPRESSION "^tsah: no CUDA device found[^\n]*\n$|\"keys\":2.*\"keys\":4.*\"layout\":\"bvh2\".*\"shutter\":\\{\"fraction\":0.9,\"mode\":\"centered\"\\}")
endif()

# Every CPU layout traces blurred frames: bvh4 and bvh8 draw the bvh2 image (the same hits at each
# pixel's time; the images compared byte for byte).
foreach(layout bvh2 bvh4 bvh8)
  add_test(NAME cli.trace.shutter.image.${layout}
           COMMAND tsah trace ${W}/trace_explode.tanim ${W}/trace_explode.tbvh --frames 3 --range 1:2 --width 48
                   --height 32 --shutter 0.9 --layout ${layout} --out ${W}/trace_shutter_${layout})
  set_tests_properties(cli.trace.shutter.image.${layout} PROPERTIES FIXTURES_REQUIRED trace_tree
    FIXTURES_SETUP trace_shutter_${layout} PASS_REGULAR_EXPRESSION "${layout}.*shutter 0.9 centered")
endforeach()
foreach(layout bvh4 bvh8)
  add_test(NAME cli.trace.shutter.image.${layout}.equal
           COMMAND ${CMAKE_COMMAND} -E compare_files ${W}/trace_shutter_bvh2/frame_0001.png
                   ${W}/trace_shutter_${layout}/frame_0001.png)
  set_tests_properties(cli.trace.shutter.image.${layout}.equal PROPERTIES
    FIXTURES_REQUIRED "trace_shutter_bvh2;trace_shutter_${layout}")
endforeach()

# Usage errors: exit 2, one line naming the option (tsah_expect_error: tests/cli/hardening.cmake).
set(T trace ${W}/trace_explode.tanim ${W}/trace_explode.tbvh --no-images --width 8 --height 8)
tsah_expect_error(cli.trace.shutter.error.range 2 "--shutter must be between 0 and 1" ${T} --shutter 1.5)
tsah_expect_error(cli.trace.shutter.error.rebuild 2 "does not go with --rebuild" ${T} --shutter 0.5 --rebuild binned)
tsah_expect_error(cli.trace.shutter.error.frames 2 "--shutter needs at least two frames" ${T} --shutter 0.5 --frames 1)
tsah_expect_error(cli.trace.shutter.error.mode 2 "--shutter-mode requires --shutter" ${T} --shutter-mode open)
tsah_expect_error(cli.trace.shutter.error.modename 2 "--shutter-mode" ${T} --shutter 0.5 --shutter-mode closed)
# With --device cuda the option is checked before the device is looked for, so these run without a
# GPU too: motion blur traces the bvh2 layout and refits the given tree on the GPU as well.
tsah_expect_error(cli.trace.shutter.error.gpulayout 2 "--shutter traces the bvh2 layout" ${T} --device cuda --shutter 0.5
                  --layout cwbvh)
tsah_expect_error(cli.trace.shutter.error.gpurebuild 2 "does not go with --rebuild" ${T} --device cuda --shutter 0.5
                  --rebuild lbvh)
foreach(name range rebuild frames mode modename gpulayout gpurebuild)
  set_tests_properties(cli.trace.shutter.error.${name} PROPERTIES FIXTURES_REQUIRED trace_tree)
endforeach()

# tsah export --shutter: the key files as a renderer reads them (tests/support/check_export_motion.py:
# the header compiles as C11, sizes, key times, the first and last keys equal plain exports at the
# shutter's open and close), in every layout; and its usage errors.
foreach(layout bvh2 bvh4 bvh8)
  add_test(NAME cli.export.shutter.${layout}
           COMMAND ${Python3_EXECUTABLE} ${PROJECT_SOURCE_DIR}/tests/support/check_export_motion.py $<TARGET_FILE:tsah>
                   ${W}/trace_explode.tbvh ${W}/trace_explode.tanim ${W} ${layout} ${CMAKE_C_COMPILER})
  set_tests_properties(cli.export.shutter.${layout} PROPERTIES FIXTURES_REQUIRED trace_tree
    PASS_REGULAR_EXPRESSION "export --shutter ${layout}: [0-9]+ keys.*: ok")
endforeach()
set(E export ${W}/trace_explode.tbvh ${W}/trace_explode.tanim -o ${W}/export_shutter_bad)
tsah_expect_error(cli.export.shutter.error.range 2 "--shutter must be between 0 and 1" ${E} --shutter 1.5)
tsah_expect_error(cli.export.shutter.error.interval 2 "--frame-interval must be a positive time" ${E} --shutter 0.5
                  --frame-interval 0)
tsah_expect_error(cli.export.shutter.error.mode 2 "--shutter-mode requires --shutter" ${E} --shutter-mode open)
tsah_expect_error(cli.export.shutter.error.boxes 2 "--shutter excludes --boxes" ${E} --shutter 0.5 --boxes)
foreach(name range interval mode boxes)
  set_tests_properties(cli.export.shutter.error.${name} PROPERTIES FIXTURES_REQUIRED trace_tree)
endforeach()
