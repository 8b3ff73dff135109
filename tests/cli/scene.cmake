# CLI smoke tests for scene files (docs/scenes.md): info lists objects, resample writes .tanim,
# optimize / evaluate / trace run on the composed sample scene, and bad scenes fail in one line.
set(W ${TSAH_CLI_WORK})
set(SCENE ${CMAKE_SOURCE_DIR}/samples/scenes/demo.json)

add_test(NAME cli.scene.info COMMAND tsah info ${SCENE})
set_tests_properties(cli.scene.info PROPERTIES
  PASS_REGULAR_EXPRESSION "scene +3 objects, 3 distinct sources.*ground +1 +1 +4896 .*pillars +4 +0 +4896 .*burst +2 +0 +2448 .*statement")
add_test(NAME cli.scene.info.json COMMAND tsah info ${SCENE} --json)
set_tests_properties(cli.scene.info.json PROPERTIES
  PASS_REGULAR_EXPRESSION "\"frames\":21,.*\"moving_vertices\":[1-9][0-9]*,.*\"triangles\":12240")

add_test(NAME cli.scene.resample COMMAND tsah resample ${SCENE} -o ${W}/scene_demo.tanim)
set_tests_properties(cli.scene.resample PROPERTIES FIXTURES_SETUP scene_tanim
  PASS_REGULAR_EXPRESSION "21 keyframes \\(from 21\\), 12240 triangles")
add_test(NAME cli.scene.resample.info COMMAND tsah info ${W}/scene_demo.tanim --json)
set_tests_properties(cli.scene.resample.info PROPERTIES FIXTURES_REQUIRED scene_tanim
  PASS_REGULAR_EXPRESSION "\"frames\":21,.*\"moving_vertices\":[1-9][0-9]*,.*\"triangles\":12240")

add_test(NAME cli.scene.optimize COMMAND tsah optimize ${SCENE} -o ${W}/scene_demo.tbvh --frames 3 --structure flat)
set_tests_properties(cli.scene.optimize PROPERTIES FIXTURES_SETUP scene_tree)
add_test(NAME cli.scene.evaluate COMMAND tsah evaluate ${SCENE} --methods sah0,tsah --eval-frames 5 --json)
set_tests_properties(cli.scene.evaluate PROPERTIES PASS_REGULAR_EXPRESSION "\"tsah")
add_test(NAME cli.scene.trace
         COMMAND tsah trace ${SCENE} ${W}/scene_demo.tbvh --frames 3 --width 64 --height 48 --ao 1 --shadow 1
                 --out ${W}/scene_trace --json)
set_tests_properties(cli.scene.trace PROPERTIES FIXTURES_REQUIRED scene_tree PASS_REGULAR_EXPRESSION "\"frames\"")

# Bad scenes: one line naming the scene file and the object, exit 1.
file(WRITE ${W}/scene_bad_missing.json "{\"objects\": [{\"name\": \"ghost\", \"file\": \"nowhere.obj\"}]}")
add_test(NAME cli.scene.error.missing COMMAND tsah info ${W}/scene_bad_missing.json)
set_tests_properties(cli.scene.error.missing PROPERTIES
  PASS_REGULAR_EXPRESSION "^tsah: [^\n]*scene_bad_missing.json: object 'ghost': [^\n]*nowhere.obj: no such file or directory\n$")
add_test(NAME cli.scene.error.missing.status COMMAND tsah info ${W}/scene_bad_missing.json)
set_tests_properties(cli.scene.error.missing.status PROPERTIES WILL_FAIL TRUE)
file(WRITE ${W}/scene_bad_cycle.json "{\"objects\": [{\"name\": \"me\", \"file\": \"scene_bad_cycle.json\"}]}")
add_test(NAME cli.scene.error.cycle COMMAND tsah optimize ${W}/scene_bad_cycle.json -o ${W}/scene_bad.tbvh)
set_tests_properties(cli.scene.error.cycle PROPERTIES
  PASS_REGULAR_EXPRESSION "^tsah: [^\n]*scene_bad_cycle.json: object 'me': scene files include each other[^\n]*\n$")
file(WRITE ${W}/scene_bad_speed.json
  "{\"objects\": [{\"name\": \"back\", \"file\": \"${CMAKE_SOURCE_DIR}/samples/explode/explode_0001.obj\", \"time\": {\"speed\": -2}}]}")
add_test(NAME cli.scene.error.speed COMMAND tsah info ${W}/scene_bad_speed.json)
set_tests_properties(cli.scene.error.speed PROPERTIES
  PASS_REGULAR_EXPRESSION "^tsah: [^\n]*scene_bad_speed.json: object 'back': negative speed[^\n]*\n$")
