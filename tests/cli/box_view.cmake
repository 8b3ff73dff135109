# CLI smoke tests for the views of a tree: tsah export --boxes and tsah info TREE ANIMATION
# (the tree and animation come from trace.cmake's fixtures).
set(W ${TSAH_CLI_WORK})
add_test(NAME cli.boxes.ply COMMAND tsah export ${W}/trace_explode.tbvh ${W}/trace_explode.tanim --frame 5 --boxes
                                    --color growth --min-depth 2 --max-depth 6 -o ${W}/boxes/explode.ply)
set_tests_properties(cli.boxes.ply PROPERTIES FIXTURES_REQUIRED trace_tree
  PASS_REGULAR_EXPRESSION "wrote .*explode.ply: [1-9][0-9]* boxes \\(depth 2\\.\\.6\\), coloured by growth")
add_test(NAME cli.boxes.obj COMMAND tsah export ${W}/trace_explode.tbvh ${W}/trace_explode.tanim --time 1.5 --boxes
                                    --style lines --min-share 0.5 --with-mesh -o ${W}/boxes/explode.obj)
set_tests_properties(cli.boxes.obj PROPERTIES FIXTURES_REQUIRED trace_tree
  PASS_REGULAR_EXPRESSION "wrote .*explode.obj: [1-9][0-9]* boxes .*coloured by depth")
add_test(NAME cli.boxes.bad_extension COMMAND tsah export ${W}/trace_explode.tbvh ${W}/trace_explode.tanim --boxes
                                              -o ${W}/boxes/explode.stl)
set_tests_properties(cli.boxes.bad_extension PROPERTIES FIXTURES_REQUIRED trace_tree
  PASS_REGULAR_EXPRESSION "^tsah: --boxes writes a mesh: -o must end in .ply or .obj.*\n$")
add_test(NAME cli.boxes.nothing_left COMMAND tsah export ${W}/trace_explode.tbvh ${W}/trace_explode.tanim --boxes
                                             --min-depth 900 -o ${W}/boxes/none.ply)
set_tests_properties(cli.boxes.nothing_left PROPERTIES FIXTURES_REQUIRED trace_tree WILL_FAIL TRUE)

add_test(NAME cli.info.tree_over_animation COMMAND tsah info ${W}/trace_explode.tbvh ${W}/trace_explode.tanim)
set_tests_properties(cli.info.tree_over_animation PROPERTIES FIXTURES_REQUIRED trace_tree
  PASS_REGULAR_EXPRESSION "frame +time +cost +inner +leaf.*\n +5 +5 .*average cost [0-9.]+, maximum")
add_test(NAME cli.info.tree_over_animation.json
         COMMAND tsah info ${W}/trace_explode.tbvh ${W}/trace_explode.tanim --frames 3 --json)
set_tests_properties(cli.info.tree_over_animation.json PROPERTIES FIXTURES_REQUIRED trace_tree
  PASS_REGULAR_EXPRESSION "\"average_cost\":[0-9.]+.*\"frames\":\\[\\{\"cost\".*\"root_child_growth\":\\[1\\.0,1\\.0\\]")
add_test(NAME cli.info.tree_over_other_animation COMMAND tsah info ${W}/trace_explode.tbvh ${W}/trace_wave.tanim)
set_tests_properties(cli.info.tree_over_other_animation PROPERTIES FIXTURES_REQUIRED "trace_tree;trace_other"
  PASS_REGULAR_EXPRESSION "^tsah: .*was not built for .*trace_wave.tanim.*\n$")
add_test(NAME cli.info.frames_without_animation COMMAND tsah info ${W}/trace_explode.tbvh --frames 3)
set_tests_properties(cli.info.frames_without_animation PROPERTIES FIXTURES_REQUIRED trace_tree
  PASS_REGULAR_EXPRESSION "^tsah: --frames needs a tree and its animation.*\n$")
