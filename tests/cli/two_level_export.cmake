# tsah export of a two-level tree (docs/two-level.md#exported-buffers): the buffers read back and
# traced as a renderer would (tests/support/check_two_level_export.cpp) give TwoLevelRuntime's
# closest hits at the export time, in every layout; fed one file of an export at another time (the
# instance table, the TLAS, the poses' BLAS views) the same check fails; the header compiles as
# C11; bad inputs give one line. Uses two_level.cmake's trees of demo.json: every object instanced
# (--structure two-level, fixture tl_asked: the bursts' paths move their instances) and auto's
# (fixture tl_tree: the bursts flattened into one source).
set(W ${TSAH_CLI_WORK})
set(SCENE ${CMAKE_SOURCE_DIR}/samples/scenes/demo.json)

add_executable(check_two_level_export ${PROJECT_SOURCE_DIR}/tests/support/check_two_level_export.cpp)
target_link_libraries(check_two_level_export PRIVATE anim::anim tsah::core)
tsah_warnings(check_two_level_export)

# tle_export(NAME DIR TIME ARG...): exports ${W}/${TLE_FILE} (made by fixture TLE_FIXTURE) to
# ${W}/DIR (fixture tle_DIR); its summary line matches TLE_SUMMARY.
set(TLE_FILE tl_asked.tbvh)
set(TLE_FIXTURE tl_asked)
set(TLE_SUMMARY "3 BLAS in 4 views .*7 instances")
function(tle_export name dir)
  add_test(NAME cli.two_level.export.${name} COMMAND tsah export ${W}/${TLE_FILE} ${SCENE} -o ${W}/${dir} ${ARGN})
  set_tests_properties(cli.two_level.export.${name} PROPERTIES FIXTURES_REQUIRED ${TLE_FIXTURE} FIXTURES_SETUP tle_${dir}
    PASS_REGULAR_EXPRESSION "wrote [^\n]*${dir}: two-level scene at time [0-9.]+, ${TLE_SUMMARY}, TLAS [0-9]+ nodes")
endfunction()
# tle_check(NAME DIR TIME REGEX [FILE=OTHER_DIR ...]): the checker on ${W}/DIR at TIME.
function(tle_check name dir time regex)
  add_test(NAME cli.two_level.export.check.${name}
           COMMAND check_two_level_export ${SCENE} ${W}/${TLE_FILE} ${W}/${dir} ${time} ${ARGN})
  set_tests_properties(cli.two_level.export.check.${name} PROPERTIES FIXTURES_REQUIRED "${TLE_FIXTURE};tle_${dir}"
    PASS_REGULAR_EXPRESSION "${regex}")
endfunction()

foreach(layout bvh2 bvh4 bvh8)
  tle_export(${layout} tle_${layout} --time 0.37 --layout ${layout})
  tle_check(${layout} tle_${layout} 0.37 "rays, [0-9]+ hits, [0-9]+ differ: ok")
  add_test(NAME cli.two_level.export.${layout}.header_c11
           COMMAND ${CMAKE_C_COMPILER} -std=c11 -Wall -Werror -pedantic -fsyntax-only -x c ${W}/tle_${layout}/tsah_scene.h)
  set_tests_properties(cli.two_level.export.${layout}.header_c11 PROPERTIES FIXTURES_REQUIRED tle_tle_${layout})
endforeach()
# --frame F is the scene's frame F (demo.json: 10 fps from 0, so frame 17 is time 1.7).
tle_export(frame tle_frame17 --frame 17)
tle_check(frame tle_frame17 1.7 "rays, [0-9]+ hits, [0-9]+ differ: ok")
# A file of another time's export must fail the check (the regex matches only its failure line): the
# proof that it tests the transforms, the TLAS's time and the poses' views.
foreach(part "instances;instances.bin" "tlas;tlas_nodes.bin" "poses;blas_nodes.bin;blas_woop.bin;blas_vertices.bin")
  list(POP_FRONT part name)
  list(TRANSFORM part APPEND "=${W}/tle_frame17")
  tle_check(other_time.${name} tle_bvh2 0.37 "rays hit otherwise than the runtime" ${part})
  set_tests_properties(cli.two_level.export.check.other_time.${name} PROPERTIES
    FIXTURES_REQUIRED "tl_asked;tle_tle_bvh2;tle_tle_frame17")
endforeach()
# auto's tree: the bursts' merged source is one pose whose view holds world-space triangles.
set(TLE_FILE tl_auto.tbvh)
set(TLE_FIXTURE tl_tree)
set(TLE_SUMMARY "3 BLAS in 3 views .*6 instances")
tle_export(auto tle_auto --time 0.37)
tle_check(auto tle_auto 0.37 "rays, [0-9]+ hits, [0-9]+ differ: ok")

# TLAS trees per part of the time (fixture tl_parts: 4 parts, switching at 0.5, 1 and 1.5): the
# export holds the TLAS of the time's part, on a boundary the later one.
set(TLE_FILE tl_parts.tbvh)
set(TLE_FIXTURE tl_parts)
set(TLE_SUMMARY "3 BLAS in 4 views .*7 instances")
foreach(time 0.3 1.0 1.2)
  tle_export(parts_${time} tle_parts_${time} --time ${time})
  tle_check(parts_${time} tle_parts_${time} ${time} "rays, [0-9]+ hits, [0-9]+ differ: ok")
endforeach()
# The first part's TLAS (exported at 0.3, with its header) given for time 1.2 fails the check.
tle_check(parts_other_tlas tle_parts_1.2 1.2 "two-level export: ([0-9]+ of [0-9]+ rays hit otherwise than the runtime|the TLAS is not the runtime's at time 1.2)"
          tlas_nodes.bin=${W}/tle_parts_0.3 tlas_index.bin=${W}/tle_parts_0.3 tsah_scene.h=${W}/tle_parts_0.3)
set_tests_properties(cli.two_level.export.check.parts_other_tlas PROPERTIES
  FIXTURES_REQUIRED "tl_parts;tle_tle_parts_1.2;tle_tle_parts_0.3")

# Bad inputs: one line naming the file or option (tsah_expect_error: tests/cli/hardening.cmake).
function(tle_error name code regex)
  tsah_expect_error(cli.two_level.export.error.${name} ${code} "${regex}" ${ARGN})
  set_tests_properties(cli.two_level.export.error.${name} PROPERTIES FIXTURES_REQUIRED tl_tree)
endfunction()
set(E export ${W}/tl_auto.tbvh)
tle_error(wrong_scene 1 "[^\n]*tl_auto.tbvh was not built for [^\n]*tl_other_scene.json" ${E} ${W}/tl_other_scene.json -o ${W}/tle_bad)
tle_error(not_a_scene 2 "tl_auto.tbvh holds a two-level scene: export it with its scene file, not [^\n]*explode" ${E} ${CMAKE_SOURCE_DIR}/samples/explode -o ${W}/tle_bad)
tle_error(tree_second 2 "[^\n]*tl_auto.tbvh holds a two-level scene \\(.tbvh version 3\\): give the tree first, then its scene"
          export ${SCENE} ${W}/tl_auto.tbvh -o ${W}/tle_bad)
tle_error(layout 2 "--layout" ${E} ${SCENE} --layout cwbvh -o ${W}/tle_bad)
tle_error(frame 2 "--frame 21 is out of range: [^\n]*demo.json has 21 frames \\(0..20\\)" ${E} ${SCENE} --frame 21 -o ${W}/tle_bad)
tle_error(shutter 2 "tl_auto.tbvh holds a two-level scene[^\n]*--shutter applies to flat trees only"
          ${E} ${SCENE} --shutter 0.5 -o ${W}/tle_bad)
tle_error(boxes 2 "tl_auto.tbvh holds a two-level scene[^\n]*--boxes applies to flat trees only"
          ${E} ${SCENE} --boxes -o ${W}/tle_bad.ply)
# All files or none: instances.bin cannot be written (a folder), so no other file appears.
file(MAKE_DIRECTORY ${W}/tle_blocked/instances.bin)
tle_error(blocked 1 "tle_blocked/instances.bin: is a folder; expected a file name" ${E} ${SCENE} -o ${W}/tle_blocked)
add_test(NAME cli.two_level.export.error.blocked.nothing_written COMMAND sh -c "ls -A ${W}/tle_blocked")
set_tests_properties(cli.two_level.export.error.blocked.nothing_written PROPERTIES
  DEPENDS cli.two_level.export.error.blocked PASS_REGULAR_EXPRESSION "^instances.bin\n$")

# An instance flattened by its path (its x scale passes through 0 at t = 1) is exported invisible,
# with a zero inverse, next to an animated object, and the hits still agree. The animated source is
# BLAS 0 and its pose's view comes after the static view: the BLAS table stays in BLAS order.
set(TLE_FLAT ${W}/tle_flat_scene)
file(MAKE_DIRECTORY ${TLE_FLAT})
file(WRITE ${TLE_FLAT}/tri.obj "v 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n")
file(WRITE ${TLE_FLAT}/scene.json "{\"fps\": 2, \"time\": [0, 2], \"objects\": [
  {\"file\": \"${CMAKE_SOURCE_DIR}/samples/explode/explode_%04d.obj\", \"transform\": {\"translate\": [0, 0, -3]}},
  {\"file\": \"tri.obj\", \"path\": [{\"time\": 0}, {\"time\": 2, \"scale\": [-1, 1, 1]}]}]}\n")
add_test(NAME cli.two_level.export.flat.optimize
         COMMAND tsah optimize ${TLE_FLAT}/scene.json -o ${TLE_FLAT}/scene.tbvh --structure two-level --frames 2)
set_tests_properties(cli.two_level.export.flat.optimize PROPERTIES FIXTURES_SETUP tle_flat_tree)
add_test(NAME cli.two_level.export.flat COMMAND tsah export ${TLE_FLAT}/scene.tbvh ${TLE_FLAT}/scene.json --frame 2
                                                -o ${TLE_FLAT}/out)
set_tests_properties(cli.two_level.export.flat PROPERTIES FIXTURES_REQUIRED tle_flat_tree FIXTURES_SETUP tle_flat_out
  PASS_REGULAR_EXPRESSION "two-level scene at time 1, 2 BLAS in 2 views")
add_test(NAME cli.two_level.export.check.flattened
         COMMAND check_two_level_export ${TLE_FLAT}/scene.json ${TLE_FLAT}/scene.tbvh ${TLE_FLAT}/out 1)
set_tests_properties(cli.two_level.export.check.flattened PROPERTIES FIXTURES_REQUIRED "tle_flat_tree;tle_flat_out"
  PASS_REGULAR_EXPRESSION "2 instances\\): 4000 rays, [0-9]+ hits, [0-9]+ differ: ok")
